"""The 2D scenarios of the disc: 2D-Narrow and the empty square."""

from __future__ import annotations

import numpy as np

from ..robots import Disc2D
from ..robots.base import Robot
from . import narrow2d
from .base import Scenario
from .scene import Problem, Scene


class Narrow2DScenario(Scenario):
    """2D-Narrow with the 2D disc; horizon 50."""

    name = "narrow2d"
    horizon = 50

    def __init__(self, robot: Robot | None = None, config: narrow2d.Narrow2DConfig | None = None) -> None:
        self.robot = robot or Disc2D()
        self.config = config or narrow2d.Narrow2DConfig()

    def scene(self, split: str, index: int) -> Scene:
        return narrow2d.workspace(split, index, self.config, radius=float(self.robot.parts.sphere_radii.max()))

    def problem(self, split: str, index: int, seed: int = 0) -> Problem:
        return narrow2d.problem(split, index, seed, self.robot)

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros(2), np.ones(2)


class Empty2DScenario(Scenario):
    """The unit square with no obstacles, for the 2D disc: a sanity check for learning."""

    name = "empty2d"
    horizon = 50

    def __init__(self, robot: Robot | None = None) -> None:
        self.robot = robot or Disc2D()
        self._scene = Scene([], low=np.zeros(2), high=np.ones(2), name="empty2d")

    def scene(self, split: str, index: int) -> Scene:
        return self._scene

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return self._scene.low.copy(), self._scene.high.copy()
