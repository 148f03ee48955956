"""Scenes (obstacles + workspace bounds) and planning problems."""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import Sequence

import numpy as np
from numpy.typing import NDArray

from ..geometry.collision import CollisionWorld
from ..geometry.shapes import Shape

Array = NDArray[np.float64]


@dataclass(eq=False)
class Scene:
    """A static workspace: obstacles in the world frame and axis-aligned bounds."""

    obstacles: Sequence[Shape]
    low: Array
    high: Array
    name: str = ""

    def __post_init__(self) -> None:
        self.low = np.asarray(self.low, np.float64)
        self.high = np.asarray(self.high, np.float64)
        if self.low.shape != self.high.shape or np.any(self.high <= self.low):
            raise ValueError("scene bounds need low < high in every axis")
        self.obstacles = list(self.obstacles)

    @property
    def dim(self) -> int:
        return int(self.low.shape[0])

    @cached_property
    def world(self) -> CollisionWorld:
        """The packed obstacles, built once."""
        return CollisionWorld.from_shapes(self.obstacles, self.dim)


@dataclass(eq=False)
class Problem:
    """A start and a goal configuration in a scene."""

    scene: Scene
    start: Array
    goal: Array
    #: where it came from, e.g. ``narrow2d/test/17``
    tag: str = ""
    extra: dict[str, object] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.start = np.asarray(self.start, np.float64)
        self.goal = np.asarray(self.goal, np.float64)
