"""OMPL's planners in the harness (skipped without the optional ``ompl`` package)."""

from __future__ import annotations

import builtins
import sys
from collections.abc import Callable

import numpy as np
import pytest

from pointplan.evaluation import check_path, evaluate
from pointplan.planners import make_planner
from pointplan.robots import Sphere3D, SShape
from pointplan.scenes.scenarios import Narrow2DScenario
from pointplan.scenes.scene import Problem, Scene


@pytest.fixture(scope="module")
def narrow(narrow2d_test_problems: Callable[[int], list[Problem]]) -> list[Problem]:
    return narrow2d_test_problems(6)


def test_missing_ompl_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    real_import = builtins.__import__

    def no_ompl(
        name: str, globals: object = None, locals: object = None, fromlist: object = (), level: int = 0
    ) -> object:
        if level == 0 and (name == "ompl" or name.startswith("ompl.")):
            raise ImportError("No module named 'ompl'")
        return real_import(name, globals, locals, fromlist, level)  # type: ignore[arg-type]

    for mod in [m for m in sys.modules if m == "ompl" or m.startswith("ompl.")]:
        monkeypatch.delitem(sys.modules, mod)
    monkeypatch.setattr(builtins, "__import__", no_ompl)
    with pytest.raises(ImportError, match=r"pip install 'pointplan\[ompl\]'"):
        make_planner("ompl:RRTConnect", Narrow2DScenario().robot)


def test_cli_without_ompl_says_what_to_install(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from pointplan import cli
    from pointplan.planners import ompl as ompl_mod

    def missing() -> None:
        raise ImportError(ompl_mod.OMPL_MISSING)

    monkeypatch.setattr(ompl_mod, "_ompl", missing)
    code = cli.main(["eval", "--planner", "ompl:RRTConnect", "--episodes", "1", "--quiet"])
    assert code == 2
    assert "pip install 'pointplan[ompl]'" in capsys.readouterr().err


ompl = pytest.importorskip("ompl")


@pytest.mark.parametrize("name", ["ompl:RRTConnect", "ompl:rrtconnect"])
def test_rrtconnect_solves_narrow_problems(narrow: list[Problem], name: str) -> None:
    robot = Narrow2DScenario().robot
    planner = make_planner(name, robot, time_limit=30.0)  # stops when solved; a loaded CI machine needs headroom
    assert planner.name == "ompl:RRTConnect"
    for p in narrow:
        res = planner.plan(p)
        assert res.success, res.info
        assert check_path(robot, p, res.path)
        assert np.array_equal(res.path[0], p.start) and np.array_equal(res.path[-1], p.goal)
        assert res.nodes >= 2 and res.collision_checks > res.nodes
        # every edge no longer than the range (plus round-off)
        assert np.all(robot.distance(res.path[:-1], res.path[1:]) <= 0.07 + 1e-9)


def test_evaluator_agrees_and_other_planners_run(narrow: list[Problem]) -> None:
    robot = Narrow2DScenario().robot
    report = evaluate(make_planner("ompl:RRTConnect", robot, time_limit=30.0), narrow, robot, progress=False)
    m = report.metrics()
    assert m["success_rate"] == 1.0 and m["planner_claims_disagree"] == 0
    for name in ("ompl:RRT", "ompl:PRM", "ompl:KPIECE1"):
        res = make_planner(name, robot, time_limit=0.5).plan(narrow[0])
        if res.success:
            assert check_path(robot, narrow[0], res.path), name


def test_unknown_planner_name_is_a_clear_error() -> None:
    robot = Narrow2DScenario().robot
    with pytest.raises(ValueError, match=r"unknown OMPL planner 'NoSuchPlanner'.*RRTConnect"):
        make_planner("ompl:NoSuchPlanner", robot)
    with pytest.raises(ValueError, match=r"unknown planner 'nosuch'.*ompl:NAME"):
        make_planner("nosuch", robot)


def test_cli_eval_with_ompl(capsys: pytest.CaptureFixture[str]) -> None:
    from pointplan import cli

    assert (
        cli.main(["eval", "--planner", "ompl:RRTConnect,birrt", "--episodes", "3", "--quiet", "--time-limit", "2"]) == 0
    )
    out = capsys.readouterr().out
    assert "ompl:RRTConnect" in out and "100.0%" in out
    assert cli.main(["eval", "--planner", "ompl:Nope", "--episodes", "1", "--quiet"]) == 2


def _box_scene_3d() -> Scene:
    from pointplan.geometry.shapes import Box

    wall = Box(center=np.array([0.5, 0.5, 0.25]), size=np.array([0.1, 1.0, 0.5]))
    return Scene(obstacles=[wall], low=np.zeros(3), high=np.ones(3), name="wall3d")


def test_sphere_and_sshape_spaces() -> None:
    scene = _box_scene_3d()
    sphere = Sphere3D()
    p = Problem(scene, np.array([0.2, 0.5, 0.3]), np.array([0.8, 0.5, 0.3]))
    res = make_planner("ompl:RRTConnect", sphere, time_limit=5.0).plan(p)
    assert res.success and check_path(sphere, p, res.path)
    ss = SShape()
    q0 = np.array([0.25, 0.5, 0.7, 0.0, 0.0, 0.0, 1.0])
    q1 = np.array([0.75, 0.5, 0.7, 0.0, 0.0, np.sin(0.4), np.cos(0.4)])
    p3 = Problem(scene, q0, q1)
    res = make_planner("ompl:RRTConnect", ss, time_limit=10.0).plan(p3)
    assert res.success, res.info
    assert res.path.shape[1] == 7
    assert check_path(ss, p3, res.path)


def test_first_query_checks_before_the_budget_and_does_not_count_it(
    narrow: list[Problem], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A planner's first query on a kind of world makes one state check and one short edge
    toward the goal before OMPL's clock starts (compiling the kernels is not planning
    time); the query's ``collision_checks`` counts only OMPL's own checks, and later
    queries on the same kind of world make none."""
    from pointplan.planners import ompl as ompl_mod

    calls: list[tuple[str, int]] = []
    edges: list[tuple[np.ndarray, np.ndarray]] = []
    real_free, real_edge = ompl_mod.check_free, ompl_mod.edge_free

    def counted_free(robot, world, q, low, high):  # type: ignore[no-untyped-def]
        calls.append(("state", len(q)))
        return real_free(robot, world, q, low, high)

    def counted_edge(robot, world, q0, q1, resolution, low, high):  # type: ignore[no-untyped-def]
        ok, n = real_edge(robot, world, q0, q1, resolution, low, high)
        calls.append(("edge", n))
        edges.append((np.array(q0), np.array(q1)))
        return ok, n

    monkeypatch.setattr(ompl_mod, "check_free", counted_free)
    monkeypatch.setattr(ompl_mod, "edge_free", counted_edge)
    robot = Narrow2DScenario().robot
    planner = make_planner("ompl:RRTConnect", robot, time_limit=2.0, seed=3)
    problem = narrow[0]

    low, high = np.asarray(problem.scene.low, np.float64), np.asarray(problem.scene.high, np.float64)
    planner._warm_up(problem, low, high)
    assert [c[0] for c in calls] == ["state", "edge"]
    q0, q1 = edges[0]
    assert np.allclose(q0, problem.start)
    step = q1 - q0
    toward = np.asarray(problem.goal) - np.asarray(problem.start)
    assert np.isclose(np.linalg.norm(step), 2 * planner.resolution)
    assert np.isclose(step @ toward, np.linalg.norm(step) * np.linalg.norm(toward))  # toward the goal
    calls.clear()
    planner._warm_up(problem, low, high)  # the same kind of world: nothing more
    assert calls == []

    fresh = make_planner("ompl:RRTConnect", robot, time_limit=2.0, seed=3)
    result = fresh.plan(problem)
    assert result.success
    made = sum(n for _, n in calls)
    warm = calls[0][1] + calls[1][1]  # the first state check and the first edge
    assert [c[0] for c in calls[:2]] == ["state", "edge"]
    assert result.collision_checks == made - warm
    calls.clear()
    again = fresh.plan(problem)
    assert again.collision_checks == sum(n for _, n in calls)
