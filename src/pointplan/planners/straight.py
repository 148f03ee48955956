"""The straight-line baseline: follow the geodesic from start to goal."""

from __future__ import annotations

import time

import numpy as np

from ..robots.base import Robot
from ..scenes.scene import Problem
from .base import PlanResult, check_free, march


class StraightLine:
    """Walk the geodesic start -> goal in steps of ``step``, each checked every
    ``resolution``; succeed iff the whole geodesic is collision-free and inside the bounds.

    ``nodes`` is the number of steps, ``ceil(length / step)``; ``collision_checks`` counts
    the configurations checked up to the first blocked step. The path is the start followed
    by the end of every step. Deterministic: ``seed`` is accepted and ignored.
    """

    name = "straight"

    def __init__(self, robot: Robot, step: float = 0.07, resolution: float = 0.01, seed: int | None = None) -> None:
        if step <= 0 or resolution <= 0:
            raise ValueError("step and resolution must be positive")
        self.robot = robot
        self.step = float(step)
        self.resolution = float(resolution)

    def __repr__(self) -> str:
        return f"StraightLine(step={self.step}, resolution={self.resolution})"

    def plan(self, problem: Problem) -> PlanResult:
        """The straight edge from start to goal, a success only where it is free."""
        t0 = time.perf_counter()
        robot, scene = self.robot, problem.scene
        length = float(robot.distance(problem.start, problem.goal))
        if length <= 1e-12:
            # nothing to walk: the start is the path if it is free
            ok = bool(check_free(robot, scene.world, problem.start[None], scene.low, scene.high)[0])
            path = problem.start[None].copy() if ok else np.zeros((0, robot.config_dim))
            return PlanResult(path, ok, 0, 1, time.perf_counter() - t0)
        nodes = int(np.ceil(length / self.step - 1e-9))
        m = march(robot, scene, problem.start, problem.goal, self.step, self.resolution)
        if not m.reached:
            return PlanResult.failure(robot.config_dim, nodes, m.checks, time.perf_counter() - t0)
        path = np.concatenate([problem.start[None], m.nodes])
        return PlanResult(path, True, nodes, m.checks, time.perf_counter() - t0)
