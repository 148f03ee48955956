"""Scenes (obstacles + workspace bounds) and planning problems."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from numpy.typing import NDArray

from ..geometry.collision import CollisionWorld
from ..geometry.shapes import Box, Shape

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
        """2 or 3: the workspace's dimension."""
        return int(self.low.shape[0])

    @cached_property
    def world(self) -> CollisionWorld:
        """The packed obstacles, built once."""
        return CollisionWorld.from_shapes(self.obstacles, self.dim)

    #: whether obstacles move with time (see :class:`DynamicScene`)
    dynamic = False

    def obstacles_at(self, t: int) -> list[Shape]:
        """The obstacles at time step ``t`` (a static scene: always the same)."""
        return list(self.obstacles)

    def world_at(self, t: int) -> CollisionWorld:
        """The packed obstacles at time step ``t``."""
        return self.world

    def predicted_world(self, now: int, t: int) -> CollisionWorld:
        """The obstacles at time step ``t`` as foreseen at step ``now`` (a static scene:
        as they are)."""
        return self.world


class DynamicScene(Scene):
    """Boxes that move: box ``k`` goes from its placement in ``obstacles`` (time 0) to its
    placement in ``targets`` (time ``period / 2``) and back, ``s(t) = (1 - cos(2 pi t /
    period)) / 2`` of the way, centres linearly and rotations along the geodesic (slerp).

    Time is the environment's step counter: a move from step ``t`` to ``t + 1`` is checked
    against the obstacles at ``t + 1``, and the observation at step ``t`` shows them at ``t``.
    ``world`` (used by planners that ignore time) is the scene at time 0.
    """

    dynamic = True

    def __init__(
        self,
        obstacles: Sequence[Box],
        targets: Sequence[Box],
        low: Array,
        high: Array,
        period: int = 80,
        name: str = "",
    ) -> None:
        super().__init__(obstacles, low, high, name)
        self.targets = list(targets)
        self.boxes = [b for b in self.obstacles if isinstance(b, Box)]
        if (
            len(self.targets) != len(self.obstacles)
            or len(self.boxes) != len(self.obstacles)
            or not all(isinstance(b, Box) for b in self.targets)
        ):
            raise ValueError("a dynamic scene needs one target box per obstacle box")
        self.period = int(period)
        self._worlds: dict[int, CollisionWorld] = {}
        # relative rotations as rotation vectors, for the geodesic interpolation
        from ..geometry import lie

        rel = (
            np.stack([a.rotation.T @ b.rotation for a, b in zip(self.boxes, self.targets)])
            if self.targets
            else np.zeros((0, 3, 3))
        )
        self._rel_rotvec = lie.so3_log(rel) if len(rel) else np.zeros((0, 3))

    def fraction(self, t: int | Array) -> Array:
        """How far along from the first placement to the second, at time ``t``."""
        return (1.0 - np.cos(2.0 * np.pi * np.asarray(t, np.float64) / self.period)) / 2.0

    def poses_at(self, t: int) -> tuple[Array, Array]:
        """Box centres ``(K, 3)`` and rotations ``(K, 3, 3)`` at time ``t``."""
        from ..geometry import lie

        s = float(self.fraction(t))
        c0 = np.stack([b.center for b in self.boxes])
        c1 = np.stack([b.center for b in self.targets])
        r0 = np.stack([b.rotation for b in self.boxes])
        return c0 + s * (c1 - c0), r0 @ lie.so3_exp(s * self._rel_rotvec)

    def obstacles_at(self, t: int) -> list[Shape]:
        if not self.obstacles:
            return []
        c, r = self.poses_at(t)
        return [Box(ci, b.size, ri) for ci, ri, b in zip(c, r, self.obstacles)]  # type: ignore[union-attr]

    def predicted_world(self, now: int, t: int) -> CollisionWorld:
        """The boxes at time step ``t`` as foreseen at step ``now`` from what was seen up to
        then: their motion from ``now - 1`` to ``now`` carried on at the same speed (centres
        along a line, rotations at a constant angular velocity); at step 0, where they are.
        Not cached: each ``now`` foresees its own."""
        if not self.boxes:
            return self.world
        c, r = self.predicted_poses(now, t)
        return CollisionWorld.from_shapes([Box(ci, b.size, ri) for ci, ri, b in zip(c, r, self.boxes)], self.dim)

    def predicted_poses(self, now: int, t: int) -> tuple[Array, Array]:
        """Box centres ``(K, 3)`` and rotations ``(K, 3, 3)`` of :meth:`predicted_world`."""
        from ..geometry import lie

        c1, r1 = self.poses_at(now)
        c0, r0 = self.poses_at(now - 1) if now > 0 else (c1, r1)
        k = float(t - now)
        spin = lie.so3_log(np.swapaxes(r0, -1, -2) @ r1)  # the last step's turn, in each box's frame
        return c1 + k * (c1 - c0), r1 @ lie.so3_exp(k * spin)

    def world_at(self, t: int) -> CollisionWorld:
        t = int(t) % self.period
        w = self._worlds.get(t)
        if w is None:
            w = self._worlds[t] = CollisionWorld.from_shapes(self.obstacles_at(t), self.dim)
        return w


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
