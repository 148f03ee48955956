"""The independent path check, the evaluator and its table."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pointplan.evaluation import EvalReport, check_path, densify, evaluate, format_table
from pointplan.geometry.shapes import Box
from pointplan.planners import BiRRT, PlanResult, StraightLine
from pointplan.robots import Disc2D, SShape
from pointplan.scenes import Problem, Scene
from pointplan.scenes.scenarios import Narrow2DScenario

METRIC_KEYS = {
    "success_rate",
    "episodes",
    "nodes_mean",
    "nodes_median",
    "nodes_mean_solved",
    "collision_checks_mean",
    "collision_checks_median",
    "path_length_mean",
    "path_length_median",
    "time_mean_s",
    "time_median_s",
    "planner_claims_disagree",
    "invalid_problems",
}


@pytest.fixture
def robot() -> Disc2D:
    return Disc2D()


@pytest.fixture
def wall_problem() -> Problem:
    """A thin vertical wall (x in [0.49, 0.51]) with a gap at the top (y > 0.8)."""
    scene = Scene([Box(center=[0.5, 0.4], size=[0.02, 0.8])], low=np.zeros(2), high=np.ones(2))
    return Problem(scene, start=[0.2, 0.3], goal=[0.8, 0.3], tag="wall")


GOOD = [[0.2, 0.3], [0.5, 0.9], [0.8, 0.3]]


def test_accepts_a_valid_path(robot: Disc2D, wall_problem: Problem) -> None:
    assert check_path(robot, wall_problem, np.array(GOOD))
    # ending within the tolerance of the goal is enough
    assert check_path(robot, wall_problem, np.array(GOOD[:-1] + [[0.78, 0.32]]))


def test_rejects_a_path_through_a_wall(robot: Disc2D, wall_problem: Problem) -> None:
    # both vertices are free; only the segment between them crosses the thin wall
    path = np.array([[0.2, 0.3], [0.8, 0.3]])
    assert not robot.collides(wall_problem.scene.world, path).any()
    verdict = check_path(robot, wall_problem, path)
    assert not verdict and "segment 0 touches" in verdict.reason
    # the certificate does not sample at ``resolution`` (that only spaces the bounds
    # check): even a coarse resolution does not let the segment through
    assert not check_path(robot, wall_problem, path, resolution=1.0)


def test_rejects_a_path_not_reaching_the_goal(robot: Disc2D, wall_problem: Problem) -> None:
    assert not check_path(robot, wall_problem, np.array(GOOD[:-1] + [[0.8, 0.4]]))
    assert not check_path(robot, wall_problem, np.array(GOOD[:-1] + [[0.8, 0.37]]), tolerance=0.07)
    assert check_path(robot, wall_problem, np.array(GOOD[:-1] + [[0.8, 0.37]]), tolerance=0.08)


def test_rejects_a_path_leaving_the_bounds(robot: Disc2D, wall_problem: Problem) -> None:
    # around the wall through its gap... and out of the square on the way
    path = np.array([[0.2, 0.3], [0.45, 1.03], [0.55, 1.03], [0.8, 0.3]])
    assert not robot.collides(wall_problem.scene.world, densify(robot, path, 0.01)).any()
    assert not check_path(robot, wall_problem, path)


def test_rejects_a_wrong_start_and_malformed_paths(robot: Disc2D, wall_problem: Problem) -> None:
    assert not check_path(robot, wall_problem, np.array([[0.21, 0.3]] + GOOD[1:]))
    assert not check_path(robot, wall_problem, np.zeros((0, 2)))
    assert not check_path(robot, wall_problem, np.array(GOOD)[:, :1])
    bad = np.array(GOOD)
    bad[1, 0] = np.nan
    assert not check_path(robot, wall_problem, bad)


def test_single_configuration_path(robot: Disc2D) -> None:
    scene = Scene([], low=np.zeros(2), high=np.ones(2))
    problem = Problem(scene, start=[0.5, 0.5], goal=[0.52, 0.5])
    assert check_path(robot, problem, np.array([[0.5, 0.5]]))


def test_densify_spacing_and_ends(robot: Disc2D) -> None:
    path = np.array([[0.0, 0.0], [0.07, 0.0], [0.07, 0.035], [0.07, 0.035]])
    qs = densify(robot, path, 0.01)
    # 0.07 is 7 intervals despite round-off, 0.035 is 4, a zero-length segment 1
    assert len(qs) == 8 + 5 + 2
    step = np.linalg.norm(np.diff(qs, axis=0), axis=-1)
    assert step.max() <= 0.01 + 1e-12
    np.testing.assert_array_equal(qs[0], path[0])
    np.testing.assert_allclose(qs[-1], path[-1])


def test_check_path_sshape_bounds() -> None:
    robot = SShape()
    scene = Scene([], low=np.zeros(3), high=np.ones(3))
    q0 = np.array([0.5, 0.5, 0.5, 0, 0, 0, 1.0])
    q1 = np.array([0.6, 0.5, 0.5, 0, 0, 0, 1.0])
    problem = Problem(scene, q0, q1)
    assert check_path(robot, problem, np.stack([q0, q1]))
    out = np.array([1.2, 0.5, 0.5, 0, 0, 0, 1.0])
    assert not check_path(robot, problem, np.stack([q0, out, q1]))


# ---------------------------------------------------------------------------- evaluate
class LiarPlanner:
    """Claims success with a straight segment through the wall; fails honestly elsewhere."""

    name = "liar"

    def plan(self, problem: Problem) -> PlanResult:
        if problem.tag == "honest-fail":
            return PlanResult.failure(2, nodes=3, collision_checks=10, time_s=0.0)
        path = np.stack([problem.start, problem.goal])
        return PlanResult(path, True, nodes=1, collision_checks=5, time_s=0.0)


def test_evaluate_decides_success_itself(robot: Disc2D, wall_problem: Problem) -> None:
    free = Problem(Scene([], low=np.zeros(2), high=np.ones(2)), start=[0.1, 0.1], goal=[0.4, 0.5], tag="free")
    honest = Problem(wall_problem.scene, wall_problem.start, wall_problem.goal, tag="honest-fail")
    report = evaluate(LiarPlanner(), [wall_problem, free, honest], robot, progress=False)
    assert isinstance(report, EvalReport) and report.planner == "liar"
    assert [r.success for r in report.records] == [False, True, False]
    assert [r.claimed_success for r in report.records] == [True, True, False]
    m = report.metrics()
    assert set(m) == METRIC_KEYS
    assert m["episodes"] == 3
    assert m["success_rate"] == pytest.approx(1 / 3)
    assert m["planner_claims_disagree"] == 1
    assert m["nodes_mean"] == pytest.approx(5 / 3) and m["nodes_median"] == 1
    assert m["nodes_mean_solved"] == report.records[1].nodes  # the one solved problem
    assert m["collision_checks_mean"] == pytest.approx(20 / 3)
    # path length over the successful problem only
    assert m["path_length_mean"] == pytest.approx(0.5) and m["path_length_median"] == pytest.approx(0.5)
    assert m["time_mean_s"] >= 0


def test_evaluate_real_planners_with_progress_bar(robot: Disc2D) -> None:
    problems = Narrow2DScenario().problems("test", 6, seed=1)
    metrics = {}
    for planner in (BiRRT(robot, seed=0), StraightLine(robot)):
        report = evaluate(planner, problems, robot, progress=True)
        assert len(report.records) == 6
        metrics[planner.name] = report.metrics()
        assert metrics[planner.name]["planner_claims_disagree"] == 0
    assert metrics["birrt"]["success_rate"] == 1.0
    assert metrics["straight"]["success_rate"] < 1.0
    table = format_table(metrics)
    lines = table.splitlines()
    assert "birrt" in lines[0] and "straight" in lines[0]
    assert len({len(line) for line in lines}) == 1  # aligned
    assert any(line.startswith("success") and "100.0%" in line for line in lines)


def test_metrics_of_an_all_failure_report(robot: Disc2D, wall_problem: Problem) -> None:
    report = evaluate(StraightLine(robot), [wall_problem], robot, progress=False)
    m = report.metrics()
    assert m["success_rate"] == 0.0 and math.isnan(m["path_length_mean"])
    assert "-" in format_table({"straight": m})
