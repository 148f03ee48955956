"""Scenarios: a robot, a family of workspaces, and how problems are drawn in them.

An environment id names a scenario; the environment asks it for workspaces of the train or
test split and for start/goal pairs. The scenarios by name are in :mod:`.registry`.
"""

from __future__ import annotations

import zlib
from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence

import numpy as np

from ..robots.base import Robot
from .scene import Problem, Scene


class Scenario(ABC):
    """A family of planning problems for one robot."""

    name: str
    robot: Robot
    horizon: int
    #: the name the random streams of workspaces and problems are drawn from, when it is
    #: not ``name`` (a scenario renamed keeps its problems)
    stream: str | None = None

    @property
    def stream_name(self) -> str:
        """The name seeding this scenario's random streams (``stream``, else ``name``)."""
        return self.stream or self.name

    @abstractmethod
    def scene(self, split: str, index: int) -> Scene:
        """Workspace ``index`` of ``split`` (``train`` or ``test``); splits are disjoint."""

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """The workspace bounds ``(low, high)`` shared by every scene of the scenario
        (subclasses answer without building a scene)."""
        ref = self.scene("test", 0)
        return ref.low.copy(), ref.high.copy()

    def sample_problem(self, scene: Scene, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """A collision-free start and goal drawn uniformly in ``scene``."""
        q = self.robot.sample_free(scene.world, rng, 2, scene.low, scene.high)
        return q[0], q[1]

    @staticmethod
    def first_blocked_pair(
        draw: Callable[[], tuple[np.ndarray, np.ndarray] | None],
        straight_free: Callable[[np.ndarray, np.ndarray], bool],
        tries: int,
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """Of ``tries`` pairs from ``draw`` (``None``: a draw that failed), the first whose
        straight line is not free, else the first pair drawn, else ``None``."""
        first: tuple[np.ndarray, np.ndarray] | None = None
        for _ in range(tries):
            pair = draw()
            if pair is None:
                continue
            if not straight_free(*pair):
                return pair
            first = first or pair
        return first

    def problem(self, split: str, index: int, seed: int = 0) -> Problem:
        """Problem ``index`` of ``split``: workspace ``index``, start and goal drawn from
        ``(split, index, seed)``."""
        scene = self.scene(split, index)
        rng = np.random.default_rng(
            np.random.SeedSequence([zlib.crc32(self.stream_name.encode()), zlib.crc32(split.encode()), index, seed])
        )
        start, goal = self.sample_problem(scene, rng)
        return Problem(scene, start, goal, tag=f"{self.name}/{split}/{index}/seed{seed}")

    def problems(self, split: str, n: int, seed: int = 0) -> list[Problem]:
        """``n`` fixed problems, one per workspace ``0..n-1`` of ``split``."""
        return [self.problem(split, i, seed) for i in range(n)]


class FixedScenario(Scenario):
    """One scene (e.g. loaded from a file) for every split, with optional fixed problems."""

    def __init__(self, scene: Scene, robot: Robot, horizon: int = 50, fixed: Sequence[Problem] = ()) -> None:
        self.name = scene.name or "scene"
        self._scene = scene
        self.robot = robot
        self.horizon = horizon
        self.fixed = list(fixed)

    def scene(self, split: str, index: int) -> Scene:
        return self._scene

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return self._scene.low.copy(), self._scene.high.copy()

    def problem(self, split: str, index: int, seed: int = 0) -> Problem:
        if self.fixed:
            return self.fixed[index % len(self.fixed)]
        return super().problem(split, index, seed)

    def problems(self, split: str, n: int, seed: int = 0) -> list[Problem]:
        if self.fixed:
            return self.fixed[:n]
        return super().problems(split, n, seed)
