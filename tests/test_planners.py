"""Bi-RRT and the straight line: correctness, budgets, reproducibility, other robots."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest

from pointplan.evaluation import check_path, densify
from pointplan.geometry.shapes import Box
from pointplan.planners import (
    PLANNERS,
    BiRRT,
    Planner,
    PlanResult,
    StraightLine,
    make_planner,
    path_length,
)
from pointplan.robots import Disc2D, Sphere3D, SShape
from pointplan.scenes import Problem, Scene

N_NARROW = 20


@pytest.fixture(scope="module")
def narrow(narrow2d_test_problems: Callable[[int], list[Problem]]) -> list[Problem]:
    return narrow2d_test_problems(N_NARROW)


@pytest.fixture(scope="module")
def narrow_results(narrow: list[Problem]) -> list[PlanResult]:
    planner = BiRRT(Disc2D(), seed=0)
    return [planner.plan(p) for p in narrow]


def wall_scene() -> Scene:
    """The unit square cut by a vertical wall with one gap near the top."""
    return Scene(
        [Box(center=[0.5, 0.4], size=[0.1, 0.8])],
        low=np.zeros(2),
        high=np.ones(2),
        name="wall",
    )


def corridor_scene() -> Scene:
    """A hard 2D problem: an S-shaped corridor between four walls."""
    walls = [
        Box(center=[0.2, 0.45], size=[0.04, 0.9]),
        Box(center=[0.4, 0.55], size=[0.04, 0.9]),
        Box(center=[0.6, 0.45], size=[0.04, 0.9]),
        Box(center=[0.8, 0.55], size=[0.04, 0.9]),
    ]
    return Scene(walls, low=np.zeros(2), high=np.ones(2), name="corridor")


# ---------------------------------------------------------------------------- Bi-RRT, 2D
def test_birrt_solves_every_narrow_problem(narrow: list[Problem], narrow_results: list[PlanResult]) -> None:
    robot = Disc2D()
    for problem, res in zip(narrow, narrow_results):
        assert res.success, problem.tag
        assert check_path(robot, problem, res.path), problem.tag


def test_birrt_paths_start_end_and_are_free(narrow: list[Problem], narrow_results: list[PlanResult]) -> None:
    robot = Disc2D()
    for problem, res in zip(narrow, narrow_results):
        path = res.path
        assert path.ndim == 2 and path.shape[1] == 2 and len(path) >= 2
        np.testing.assert_allclose(path[0], problem.start, atol=1e-12)
        np.testing.assert_allclose(path[-1], problem.goal, atol=1e-12)
        qs = densify(robot, path, 0.01)
        assert not robot.collides(problem.scene.world, qs).any()
        assert np.all((qs >= 0.0) & (qs <= 1.0))
        # the raw path is valid too, and made of steps no longer than ``step``
        assert check_path(robot, problem, res.raw_path)
        assert np.all(robot.distance(res.raw_path[:-1], res.raw_path[1:]) <= 0.07 + 1e-9)


def test_shortcutting_does_not_lengthen(narrow_results: list[PlanResult]) -> None:
    robot = Disc2D()
    shorter = 0
    for res in narrow_results:
        raw, final = path_length(robot, res.raw_path), path_length(robot, res.path)
        assert final <= raw + 1e-9
        shorter += final < raw - 1e-6
    assert shorter > N_NARROW // 2  # and it usually helps


def test_birrt_counts_and_trees(narrow_results: list[PlanResult]) -> None:
    robot = Disc2D()
    for res in narrow_results:
        assert len(res.trees) == 2
        assert res.nodes == sum(len(nodes) for nodes, _ in res.trees)
        assert res.collision_checks >= res.nodes
        assert res.time_s > 0
        for nodes, parent in res.trees:
            assert parent[0] == -1 and np.all(parent[1:] >= 0) and np.all(parent[1:] < np.arange(1, len(parent)))
            if len(nodes) > 1:
                edge = robot.distance(nodes[parent[1:]], nodes[1:])
                assert np.all(edge <= 0.07 + 1e-9)


def test_birrt_is_reproducible(narrow: list[Problem]) -> None:
    robot = Disc2D()
    a = [BiRRT(robot, seed=3).plan(p) for p in narrow[:4]]
    b = [BiRRT(robot, seed=3).plan(p) for p in narrow[:4]]
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x.path, y.path)
        assert (x.nodes, x.collision_checks) == (y.nodes, y.collision_checks)
    # a fresh planner repeats; successive calls of one planner draw new numbers
    p = BiRRT(robot, seed=3)
    first, second = p.plan(narrow[0]), p.plan(narrow[0])
    np.testing.assert_array_equal(first.path, a[0].path)
    assert first.nodes != second.nodes or not np.array_equal(first.path, second.path)
    p.reset()
    np.testing.assert_array_equal(p.plan(narrow[0]).path, a[0].path)


def test_birrt_fails_with_a_tiny_budget() -> None:
    robot = Disc2D()
    problem = Problem(corridor_scene(), start=[0.1, 0.1], goal=[0.9, 0.9])
    res = BiRRT(robot, max_nodes=20, seed=0).plan(problem)
    assert not res.success
    assert res.path.shape == (0, 2)
    assert res.raw_path is None
    assert res.nodes <= 20
    # with a real budget it is solvable
    ok = BiRRT(robot, max_nodes=20000, seed=0).plan(problem)
    assert ok.success and check_path(robot, problem, ok.path)


def test_birrt_start_in_collision_fails() -> None:
    problem = Problem(wall_scene(), start=[0.5, 0.3], goal=[0.9, 0.1])
    res = BiRRT(Disc2D()).plan(problem)
    assert not res.success and res.path.shape == (0, 2)


# ---------------------------------------------------------------------------- straight line
def test_straight_line_free_scene() -> None:
    robot = Disc2D()
    scene = Scene([], low=np.zeros(2), high=np.ones(2))
    problem = Problem(scene, start=[0.1, 0.2], goal=[0.8, 0.7])
    res = StraightLine(robot).plan(problem)
    length = math.hypot(0.7, 0.5)
    assert res.success and check_path(robot, problem, res.path)
    assert res.nodes == math.ceil(length / 0.07)
    np.testing.assert_allclose(res.path[0], problem.start)
    np.testing.assert_allclose(res.path[-1], problem.goal)
    # every step checked: 7 intervals + both ends for full steps
    assert res.collision_checks >= math.ceil(length / 0.01)
    assert path_length(robot, res.path) == pytest.approx(length)


def test_straight_line_blocked_by_wall() -> None:
    robot = Disc2D()
    problem = Problem(wall_scene(), start=[0.1, 0.3], goal=[0.9, 0.3])
    res = StraightLine(robot).plan(problem)
    assert not res.success
    assert res.path.shape == (0, 2)
    assert res.nodes == math.ceil(0.8 / 0.07)
    # stops at the first blocked step: the disc touches the wall at x = 0.44
    assert 0 < res.collision_checks < 0.8 / 0.01
    # while Bi-RRT goes through the gap
    birrt = BiRRT(robot, seed=0).plan(problem)
    assert birrt.success and check_path(robot, problem, birrt.path)


# ---------------------------------------------------------------------------- 3D robots
def test_birrt_sshape_small_3d_scene() -> None:
    robot = SShape()
    scene = Scene(
        [Box(center=[0.75, 0.75, 0.75], size=[0.06, 0.06, 1.5]), Box(center=[0.75, 0.75, 0.05], size=[1.5, 1.5, 0.1])],
        low=np.zeros(3),
        high=np.full(3, 1.5),
    )
    # quarter turn about z between start and goal; the pole blocks the straight line
    goal_q = [0.0, 0.0, math.sin(math.pi / 8), math.cos(math.pi / 8)]
    problem = Problem(scene, start=[0.35, 0.75, 0.75, 0, 0, 0, 1], goal=[1.15, 0.75, 0.75, *goal_q])
    assert not robot.collides(scene.world, np.stack([problem.start, problem.goal])).any()
    assert not StraightLine(robot).plan(problem).success
    res = BiRRT(robot, seed=2).plan(problem)
    assert res.success and res.path.shape[1] == 7
    assert check_path(robot, problem, res.path)
    assert path_length(robot, res.path) <= path_length(robot, res.raw_path) + 1e-9


def test_birrt_sphere3d() -> None:
    robot = Sphere3D()
    scene = Scene(
        [Box(center=[0.5, 0.5, 0.4], size=[0.1, 1.0, 0.8]), Box(center=[0.5, 0.2, 0.9], size=[0.1, 0.4, 0.2])],
        low=np.zeros(3),
        high=np.ones(3),
    )
    problem = Problem(scene, start=[0.2, 0.5, 0.3], goal=[0.8, 0.5, 0.3])
    assert not StraightLine(robot).plan(problem).success
    res = BiRRT(robot, seed=0).plan(problem)
    assert res.success and check_path(robot, problem, res.path)
    # it had to climb over the wall (top at z = 0.8) through the gap at y > 0.4
    assert res.path[:, 2].max() > 0.8


# ---------------------------------------------------------------------------- registry
def test_make_planner_and_protocol() -> None:
    robot = Disc2D()
    b = make_planner("birrt", robot, max_nodes=123, seed=4)
    s = make_planner("straight", robot)
    assert isinstance(b, BiRRT) and b.max_nodes == 123 and b.seed == 4
    assert isinstance(s, StraightLine)
    assert isinstance(b, Planner) and isinstance(s, Planner)
    assert b.name == "birrt" and s.name == "straight"
    assert {"birrt", "straight"} <= set(PLANNERS)
    with pytest.raises(ValueError, match="magic.*birrt.*straight"):
        make_planner("magic", robot)


def test_nearest_node_index_matches_a_scan() -> None:
    """Large trees answer nearest-node queries from a KD-tree: exactly for the sphere (the
    geodesic distance is Euclidean), nearly always exactly for the S-shape (candidates are
    re-ranked by the true distance)."""
    from pointplan.planners.birrt import _Tree
    from pointplan.robots import make_robot

    rng = np.random.default_rng(0)
    for name, need in (("sphere3d", 1.0), ("sshape", 0.95)):
        robot = make_robot(name)
        lo, hi = np.full(3, -0.6), np.full(3, 0.6)
        nodes = robot.sample_uniform(rng, 3000, lo, hi)
        tree = _Tree(nodes[0])
        tree.add(nodes[1:2000], 0)
        tree.nearest(robot, nodes[0])  # builds the index over 2,000 nodes
        tree.add(nodes[2000:], 0)  # 1,000 more, not indexed yet: scanned
        queries = robot.sample_uniform(rng, 200, lo, hi)
        same = 0
        for q in queries:
            i, v = tree.nearest(robot, q)
            d = np.linalg.norm(robot.log(tree.nodes[: tree.n], q[None]), axis=1)
            np.testing.assert_allclose(np.linalg.norm(v), d[i], atol=1e-12)
            same += bool(d[i] <= d.min() + 1e-12)
        assert same / len(queries) >= need, (name, same)
