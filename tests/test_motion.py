"""Certified motion checks (robots/motion.py) and the evaluator's certificate."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pointplan.envs.core import q_free
from pointplan.evaluation import check_path
from pointplan.evaluation.clearance import Clearance
from pointplan.geometry import lie
from pointplan.geometry.collision import CollisionWorld
from pointplan.geometry.shapes import Box
from pointplan.planners import BiRRT, march
from pointplan.robots import Disc2D, Sphere3D, SShape
from pointplan.robots.motion import CONTACT_MARGIN, intervals, segments_free
from pointplan.scenes import Problem, Scene
from pointplan.scenes.scenarios import make_scenario
from pointplan.scenes.scene import DynamicScene

ROBOTS = {"disc2d": Disc2D(), "sphere3d": Sphere3D(), "sshape": SShape()}


def _random_boxes(rng: np.random.Generator, dim: int, around: np.ndarray, spread: float, k: int) -> list[Box]:
    boxes = []
    for _ in range(k):
        rot = lie.so2_exp(rng.uniform(-np.pi, np.pi)) if dim == 2 else lie.random_rotations(rng, 1)[0]
        boxes.append(
            Box(center=around + rng.uniform(-spread, spread, dim), size=rng.uniform(0.02, 0.2, dim), rotation=rot)
        )
    return boxes


def _random_config(robot, rng: np.random.Generator, center: np.ndarray, spread: float) -> np.ndarray:  # type: ignore[no-untyped-def]
    pos = center + rng.uniform(-spread, spread, robot.dim)
    if robot.config_dim == robot.dim:
        return pos
    return np.concatenate([pos, robot.sample_orientation(rng, 1)[0]])


@given(name=st.sampled_from(sorted(ROBOTS)), seed=st.integers(0, 2**32 - 1), resolution=st.sampled_from([0.01, 0.03]))
@settings(max_examples=120, deadline=None)
def test_no_accepted_segment_has_an_interior_collision(name: str, seed: int, resolution: float) -> None:
    """Whenever the validator accepts a segment among random boxes placed around it, exact
    (coal) distances at 400 configurations along it and at its ends are all positive."""
    robot = ROBOTS[name]
    rng = np.random.default_rng(seed)
    center = np.full(robot.dim, 0.5)
    a = _random_config(robot, rng, center, 0.1)
    b = robot.integrate(a, rng.uniform(-1, 1, robot.twist_dim) * robot.action_scale * rng.uniform(0.1, 1.5))
    mid = robot.positions(robot.interpolate(a, b, 0.5))
    reach = 0.3 if name == "sshape" else 0.12
    boxes = _random_boxes(rng, robot.dim, mid, reach, int(rng.integers(1, 5)))
    world = CollisionWorld.from_shapes(boxes, robot.dim)
    free, checks = segments_free(robot, world, a[None], b[None], resolution)
    assert checks[0] >= intervals(robot.distance(a, b), resolution) + 1
    if not free[0]:
        return
    clearance = Clearance(robot, boxes)
    qs = robot.interpolate(a, b, np.linspace(0.0, 1.0, 401))
    d = np.array([clearance(q) for q in qs])
    assert d.min() > CONTACT_MARGIN * 0.99, d.min()


def _corner_graze() -> tuple[Scene, np.ndarray, np.ndarray]:
    """A disc segment passing 9.5 mm from a box corner (radius 10 mm): its samples 0.01
    apart (at 5 mm each side of the closest point) are all 10.7 mm from the corner."""
    scene = Scene([Box(center=[0.5, 0.5], size=[0.2, 0.2])], low=np.zeros(2), high=np.ones(2))
    corner = np.array([0.6, 0.6])
    normal = np.array([1.0, 1.0]) / np.sqrt(2)
    tangent = np.array([1.0, -1.0]) / np.sqrt(2)
    return scene, corner + 0.0095 * normal - 0.035 * tangent, corner + 0.0095 * normal + 0.035 * tangent


def test_corner_graze_between_two_samples_is_rejected() -> None:
    robot = Disc2D()
    scene, a, b = _corner_graze()
    samples = robot.interpolate(a, b, np.linspace(0, 1, 8))  # the old 0.01 grid
    assert not robot.collides(scene.world, samples).any()
    assert Clearance(robot, scene.obstacles)(robot.interpolate(a, b, 0.5)) < 0  # but it cuts in
    free, _ = segments_free(robot, scene.world, a[None], b[None], 0.01, scene.low, scene.high)
    assert not free[0]
    # the environment stops the move before the corner, as a collision
    new_q, collided, _ = q_free(robot, scene.world, a[None], (b - a)[None], scene.low[None], scene.high[None])
    assert collided[0] and np.linalg.norm(new_q[0] - a) < 0.035
    assert Clearance(robot, scene.obstacles)(new_q[0]) > 0
    # Bi-RRT's march does not cross it either, and the evaluator rejects the segment
    assert not march(robot, scene, a, b, 0.07, 0.01).reached
    assert not check_path(robot, Problem(scene, a, b), np.stack([a, b]))
    # 2.5 mm further out it passes
    out = np.array([1.0, 1.0]) / np.sqrt(2) * 0.0025
    assert segments_free(robot, scene.world, (a + out)[None], (b + out)[None], 0.01)[0][0]
    assert check_path(robot, Problem(scene, a + out, b + out), np.stack([a + out, b + out]))


def test_start_closer_than_the_growth_can_still_move_away() -> None:
    """A start 0.1 mm from a wall: its grown check fails, the fallback certifies moves away."""
    robot = Disc2D()
    scene = Scene([Box(center=[0.5, 0.25], size=[1.0, 0.5])], low=np.zeros(2), high=np.ones(2))
    start = np.array([0.5, 0.5 + robot.radius + 1e-4])
    away = np.array([[0.0, 0.05], [0.03, 0.05]])
    new_q, collided, checks = q_free(
        robot, scene.world, np.stack([start, start]), away, np.zeros((2, 2)), np.ones((2, 2))
    )
    assert not collided.any() and np.all(checks == intervals(np.linalg.norm(away, axis=1), 0.01) + 3)
    np.testing.assert_allclose(new_q, start + away)
    # into the wall: stopped at once
    new_q, collided, _ = q_free(
        robot, scene.world, start[None], np.array([[0.0, -0.05]]), np.zeros((1, 2)), np.ones((1, 2))
    )
    assert collided[0] and np.array_equal(new_q[0], start)


def test_a_move_slid_along_the_border_is_never_longer_than_one_action() -> None:
    """The S-shape pushed against the workspace's border: aimed at its clipped end pose,
    the move's SE(3) log can exceed one action in a translation coordinate (22 of these
    4,000 draws); it is shortened to one action, so that executed in time (the
    evaluator's clock, ``timed_path``) it still takes one step, and it ends inside the
    bounds on the same geodesic."""
    from pointplan.evaluation.evaluate import timed_path

    robot = SShape()
    low, high = np.full(3, -0.6), np.full(3, 0.6)
    rng = np.random.default_rng(0)
    n = 4000
    world = Scene([], low, high).world
    q = robot.sample_free(world, rng, n, low, high)
    q[:, :3] = np.clip(q[:, :3], -0.56, 0.56)  # near the border
    q[:, :3] = np.where(np.abs(q[:, :3]) > 0.5, np.sign(q[:, :3]) * 0.56, q[:, :3])
    action = rng.uniform(-1, 1, (n, 6))
    action[np.arange(n), rng.integers(0, 6, n)] = rng.choice([-1.0, 1.0], n)  # at the limit on one axis
    twist = action * robot.action_scale
    target = robot.integrate(q, twist)
    aimed = robot.log(q, robot.clip(target, low, high))
    longer = np.max(np.abs(aimed) / robot.action_scale, axis=-1) > 1 + 1e-9
    assert longer.sum() >= 10  # the case arises
    new_q, _, _ = q_free(robot, world, q, twist, np.tile(low, (n, 1)), np.tile(high, (n, 1)))
    done = robot.log(q, new_q)
    assert np.all(np.max(np.abs(done) / robot.action_scale, axis=-1) <= 1 + 1e-9)
    assert all(len(timed_path(robot, np.stack([a, b]))) == 2 for a, b in zip(q[longer], new_q[longer]))
    assert np.all(robot.positions(new_q) >= low - 1e-9) and np.all(robot.positions(new_q) <= high + 1e-9)
    # the shortened move lies along the aimed one: the same direction in the twist space
    cos = np.sum(done[longer] * aimed[longer], -1) / (
        np.linalg.norm(done[longer], axis=-1) * np.linalg.norm(aimed[longer], axis=-1) + 1e-300
    )
    moved = np.linalg.norm(done[longer], axis=-1) > 1e-9
    np.testing.assert_allclose(cos[moved], 1.0, atol=1e-9)


def test_moving_box_onto_the_start_is_a_collision() -> None:
    """The issue's case: free at t = 4, inside a box at t = 5; the move escapes the box."""
    sc = make_scenario("dynamic3d", robot="sphere3d")
    scene = sc.scene("train", 550119390)
    robot = sc.robot
    q0 = np.array([0.12734918763867942, -0.014354039086789679, -0.026917729678806963])
    action = np.array([-0.8166237462886241, -0.3180702132443198, -0.4323194439040873])
    assert not robot.collides(scene.world_at(4), q0) and robot.collides(scene.world_at(5), q0)
    world = scene.world_at(5)
    end = q0 + action * robot.action_scale
    assert not robot.collides(world, end)
    new_q, collided, _ = q_free(
        robot, world, q0[None], (action * robot.action_scale)[None], scene.low[None], scene.high[None]
    )
    assert collided[0]
    np.testing.assert_array_equal(new_q[0], q0)  # it cannot leave through the box


def test_evaluator_checks_the_start_pose_against_the_moved_obstacles() -> None:
    """A plate that lands on the start at t = 1: the first move leaves it within one
    sub-step, so only the start pose touches it."""
    robot = Sphere3D()
    start = np.array([0.0, 0.0, 0.0])
    far = Box(center=[0.4, 0.4, 0.4], size=[0.002, 0.1, 0.1])
    onto = Box(center=[-0.029, 0.0, 0.0], size=[0.002, 0.1, 0.1])
    scene = DynamicScene([far], [onto], low=np.full(3, -0.6), high=np.full(3, 0.6), period=2)
    path = np.array([start, [0.07, 0.0, 0.0], [0.14, 0.0, 0.0]])
    assert robot.collides(scene.world_at(1), start)
    assert not robot.collides(scene.world_at(1), np.array([0.01, 0.0, 0.0]))
    verdict = check_path(robot, Problem(scene, start, path[-1]), path)
    assert not verdict and "move 0" in verdict.reason
    # the same path in a static scene with the box far away is fine
    assert check_path(robot, Problem(Scene([far], scene.low, scene.high), start, path[-1]), path)


def test_sshape_growth_covers_rotation() -> None:
    """Turning in place: the grown bars at the samples contain every corner's arc."""
    robot = SShape()
    q0 = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0])
    twist = np.array([0.01, -0.004, 0.0, 0.0, 0.0, 0.2])
    n = 20
    radii, halfs = robot.grown_parts(twist / n, 0.5)
    signs = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], float)
    corners = robot.parts.box_centers[:, None] + signs * robot.parts.box_halfs[:, None]  # (5, 8, 3), bars unrotated
    for s in np.linspace(0, 1, 201):
        k = round(s * n)  # nearest sample
        qs, qk = robot.integrate(q0, twist * s), robot.integrate(q0, twist * k / n)
        world = corners @ robot.rotations(qs).T + qs[:3]
        # in each bar's frame at sample k, the corner stays within the grown half sides
        local = np.einsum("ij,pkj->pki", robot.rotations(qk).T, world - qk[:3]) - robot.parts.box_centers[:, None]
        assert np.all(np.abs(local) <= halfs[:, None, :] + 1e-12)


@pytest.mark.slow  # certification of planned paths
@pytest.mark.parametrize("name", ["disc2d", "sshape"])
def test_birrt_paths_pass_the_evaluator(name: str) -> None:
    sc = make_scenario("narrow2d" if name == "disc2d" else "qureshi3d", robot=None if name == "disc2d" else name)
    planner = BiRRT(sc.robot, seed=0, max_nodes=20000)
    for p in sc.problems("test", 4):
        res = planner.plan(p)
        assert res.success and check_path(sc.robot, p, res.path), p.tag


# ---------------------------------------------------------------------------- bad input
def test_check_path_explains_bad_input() -> None:
    robot = Disc2D()
    scene = Scene([], low=np.zeros(2), high=np.ones(2))
    problem = Problem(scene, start=[0.2, 0.2], goal=[0.6, 0.6])
    good = np.array([[0.2, 0.2], [0.4, 0.4], [0.6, 0.6]])
    assert check_path(robot, problem, good)
    nan = good.copy()
    nan[1, 0] = np.nan
    verdict = check_path(robot, problem, nan)
    assert not verdict and "NaN" in verdict.reason and "[1]" in verdict.reason
    verdict = check_path(robot, problem, good[1:])
    assert not verdict and "start" in verdict.reason
    verdict = check_path(robot, problem, np.concatenate([good, np.zeros((3, 1))], 1))
    assert not verdict and "(K, 2)" in verdict.reason and "(3, 3)" in verdict.reason
    verdict = check_path(robot, problem, good[0])
    assert not verdict and "shape (2,)" in verdict.reason
    verdict = check_path(robot, problem, np.zeros((0, 2)))
    assert not verdict and "empty" in verdict.reason
    verdict = check_path(robot, problem, good[:2])
    assert not verdict and "goal" in verdict.reason
