"""The dodge among moving obstacles: the boxes' foreseen poses (checked against a closed
form) and a robot that steps out of a moving box's way (its path checked against the box's
closed-form motion, independently of the collision code)."""

from __future__ import annotations

import numpy as np
import pytest

from pointplan.envs.core import EnvConfig
from pointplan.geometry.shapes import Box
from pointplan.planners.rollout import DODGE_OFF, ESCAPE_OFF, Dodge, RolloutEngine, RolloutOptions
from pointplan.robots.point import Sphere3D
from pointplan.scenes.scene import DynamicScene, Problem, Scene

LOW, HIGH = np.full(3, -0.6), np.full(3, 0.6)


def rz(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def eased(t: float, period: int) -> float:
    return (1.0 - np.cos(2.0 * np.pi * t / period)) / 2.0


def test_predicted_poses_carry_the_last_step_on() -> None:
    """A box sliding along x and turning about z: foreseen k steps after ``now`` at its
    position plus k times its last step, its angle plus k times its last turn."""
    period, turn = 40, 1.2
    a = Box(center=[-0.3, 0.1, 0.0], size=[0.1, 0.2, 0.05], rotation=np.eye(3))
    b = Box(center=[0.3, 0.1, 0.2], size=[0.1, 0.2, 0.05], rotation=rz(turn))
    scene = DynamicScene([a], [b], LOW, HIGH, period=period)
    for now in (3, 11, 27):
        for k in (1, 2, 5):
            s1, s0 = eased(now, period), eased(now - 1, period)
            c = a.center + (s1 + k * (s1 - s0)) * (b.center - a.center)
            r = rz(turn * (s1 + k * (s1 - s0)))
            pc, pr = scene.predicted_poses(now, now + k)
            np.testing.assert_allclose(pc[0], c, atol=1e-12)
            np.testing.assert_allclose(pr[0], r, atol=1e-12)
    c0, r0 = scene.predicted_poses(0, 4)  # nothing seen moving yet: where it is
    np.testing.assert_allclose(c0[0], a.center, atol=1e-12)
    np.testing.assert_allclose(r0[0], np.eye(3), atol=1e-12)


def test_predicted_world_holds_the_foreseen_box() -> None:
    robot = Sphere3D()
    a = Box(center=[-0.4, 0.0, 0.0], size=[0.1, 0.1, 0.1])
    b = Box(center=[0.4, 0.0, 0.0], size=[0.1, 0.1, 0.1])
    scene = DynamicScene([a], [b], LOW, HIGH, period=40)
    c, _ = scene.predicted_poses(8, 12)
    here = c[0][None]
    assert robot.collides(scene.predicted_world(8, 12), here)[0]
    assert not robot.collides(scene.world_at(8), here)[0]
    static = Scene([a], LOW, HIGH)
    assert static.predicted_world(3, 9) is static.world


def stand_still(obs: np.ndarray, q: np.ndarray, goal: np.ndarray, noise: np.ndarray | None = None) -> np.ndarray:
    """A policy whose mean action is to stay (its spread: a unit normal)."""
    return np.zeros_like(q) if noise is None else np.tanh(noise)


def gap_to_box(p: np.ndarray, center: np.ndarray, half: np.ndarray) -> float:
    """Distance from point ``p`` to an axis-aligned box (closed form)."""
    return float(np.linalg.norm(np.maximum(np.abs(p - center) - half, 0.0)))


@pytest.mark.parametrize("dodge", [DODGE_OFF, Dodge()])
def test_a_robot_that_stands_still_is_hit_unless_it_dodges(dodge: Dodge) -> None:
    """A box sweeps along x through the robot's start. Without the dodge the robot stays
    and is hit; with it the robot steps aside and is never touched: every pose of its
    path, and points between them, clear of the box at the move's end (exact distance)."""
    robot = Sphere3D()
    period, half = 80, np.full(3, 0.05)
    a = Box(center=[0.4, 0.0, 0.0], size=2 * half)
    b = Box(center=[-0.4, 0.0, 0.0], size=2 * half)
    scene = DynamicScene([a], [b], LOW, HIGH, period=period)
    problem = Problem(scene, np.zeros(3), np.array([0.0, 0.0, 0.5]))
    opts = RolloutOptions(horizon=30, escape=ESCAPE_OFF, dodge=dodge, greedy_goal=False, connect_goal=False)
    res = RolloutEngine(stand_still, robot, EnvConfig(observation="global", n_points=16), opts).plan(problem)
    if not dodge.on:
        assert res.info["end"] == "crushed" and len(res.path) < 31
        return
    assert res.info.get("end") != "crushed" and len(res.path) == 31
    assert np.linalg.norm(res.path[-1]) > 0.05  # it moved
    for t in range(30):  # move t -> t + 1 against the box at t + 1
        center = a.center + eased(t + 1, period) * (b.center - a.center)
        for s in np.linspace(0.0, 1.0, 21):
            p = (1 - s) * res.path[t] + s * res.path[t + 1]
            assert gap_to_box(p, center, half) > robot.radius


def toward_goal(obs: np.ndarray, q: np.ndarray, goal: np.ndarray, noise: np.ndarray | None = None) -> np.ndarray:
    a = np.clip((goal - q) / 0.07, -1.0, 1.0)
    return a if noise is None else np.tanh(np.arctanh(np.clip(a, -0.999, 0.999)) + noise)


def test_the_dodge_leaves_static_scenes_alone() -> None:
    """In a static scene the rollout with the dodge is the rollout without it."""
    robot = Sphere3D()
    scene = Scene([Box(center=[0.0, 0.0, 0.25], size=[0.3, 0.3, 0.05])], LOW, HIGH)
    problem = Problem(scene, np.array([0.05, 0.0, 0.0]), np.array([0.0, 0.0, 0.5]))
    paths = []
    for dodge in (DODGE_OFF, Dodge()):
        opts = RolloutOptions(horizon=20, dodge=dodge, greedy_goal=False)
        engine = RolloutEngine(toward_goal, robot, EnvConfig(observation="global", n_points=16), opts)
        paths.append(engine.run([problem])[0].path)
    np.testing.assert_array_equal(paths[0], paths[1])
    assert len(paths[0]) > 3  # it moved, up to the plate
