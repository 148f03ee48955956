"""The hybrid planner: the policy, repaired by Bi-RRT where it fails."""

from __future__ import annotations

import numpy as np
import pytest

from pointplan.evaluation import check_path
from pointplan.planners import make_planner
from pointplan.planners.hybrid import HybridPlanner
from pointplan.scenes.scenarios import Narrow2DScenario


@pytest.fixture(scope="module")
def hybrid() -> HybridPlanner:
    planner = make_planner("hybrid", Narrow2DScenario().robot, seed=0)
    assert isinstance(planner, HybridPlanner)
    return planner


@pytest.mark.parametrize("index", [1, 165])
def test_hybrid_solves_what_the_policy_fails(hybrid: HybridPlanner, index: int) -> None:
    scenario = Narrow2DScenario()
    robot = scenario.robot
    problem = scenario.problem("test", index, seed=0)  # problems 1 and 165 of the 400 test problems
    alone = make_planner("policy", robot).plan(problem)
    assert not alone.success and not check_path(robot, problem, alone.path)
    res = hybrid.plan(problem)
    assert res.success and res.info["repaired"]
    assert check_path(robot, problem, res.path)
    assert np.array_equal(res.path[0], problem.start) and np.array_equal(res.path[-1], problem.goal)
    assert res.nodes == res.info["policy_steps"] + res.info["birrt_nodes"]
    # the policy dithers in place on both: stopped early, so fewer steps than alone
    assert res.info["policy_end"] == "stalled"
    assert res.info["policy_steps"] < alone.nodes


def test_hybrid_keeps_the_policy_path_when_it_reaches_the_goal(hybrid: HybridPlanner) -> None:
    scenario = Narrow2DScenario()
    robot = scenario.robot
    for i in (0, 2, 3):
        p = scenario.problem("test", i, seed=0)
        res = hybrid.plan(p)
        assert check_path(robot, p, res.path)
        if not res.info["repaired"]:
            assert res.info["policy_end"] == "goal" and res.nodes == res.info["policy_steps"]
            assert res.info["birrt_nodes"] == 0


def test_hybrid_from_the_cli(capsys: pytest.CaptureFixture[str]) -> None:
    from pointplan import cli

    assert cli.main(["eval", "--planner", "hybrid", "--episodes", "3", "--quiet"]) == 0
    assert "hybrid" in capsys.readouterr().out


def test_hybrid_with_ompl_fallback_and_a_time_budget() -> None:
    """``hybrid-ompl``: the policy, then OMPL's RRTConnect with pointplan's certified edges;
    a policy that cannot move hands every problem to the fallback, whose paths the
    evaluator accepts; the query's budget reaches the fallback."""
    pytest.importorskip("ompl")
    sc = Narrow2DScenario()
    planner = make_planner("hybrid-ompl", sc.robot, time_limit=3.0)
    assert planner.name == "hybrid-ompl" and planner.fallback.name == "ompl:RRTConnect"
    planner.policy.engine.horizon = 1  # (one step: the fallback does the rest)
    solved = 0
    for p in sc.problems("test", 4, seed=0):
        res = planner.plan(p)
        solved += bool(res.success and check_path(sc.robot, p, res.path))
        assert res.info.get("fallback") in (None, "ompl:RRTConnect")
        assert planner.fallback.time_limit <= 3.0
    assert solved == 4


def test_the_hybrid_is_bounded_by_time_not_nodes() -> None:
    """The hybrid's limit is a time budget for the whole query (10 s by default), its
    Bi-RRT without a node budget; Bi-RRT needs one of the two and stops at its time limit."""
    import time

    from pointplan.planners import make_planner
    from pointplan.planners.birrt import BiRRT
    from pointplan.robots.sshape import SShape
    from pointplan.scenes.scenarios import make_scenario

    hyb = make_planner("hybrid", SShape(), observation="local")
    assert hyb.time_limit == 10.0 and hyb.fallback.max_nodes is None  # type: ignore[attr-defined]
    with pytest.raises(ValueError, match="node budget"):
        BiRRT(SShape(), max_nodes=None)
    p = make_scenario("slot", robot="sshape").problems("test", 1, seed=0)[0]  # hard for a plain Bi-RRT
    t = time.perf_counter()
    res = BiRRT(SShape(), max_nodes=None, time_limit=0.3).plan(p)
    assert time.perf_counter() - t < 2.0
    assert res.success or res.nodes > 2
