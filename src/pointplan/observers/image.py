"""Occupancy image in the robot frame."""

from __future__ import annotations

import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

from ..robots.base import Robot
from .base import Array, Observer


class OccupancyImage(Observer):
    """A ``size x size`` image centred on the robot, covering ``[-extent, extent]^2`` around
    it. A cell is 1 where the robot placed at the cell centre would collide, or where the
    cell lies outside the workspace, else 0. Shape ``(1, size, size)``, rows along x,
    columns along y."""

    name = "image"

    def __init__(self, robot: Robot, size: int = 64, extent: float = 1.0) -> None:
        super().__init__(robot)
        if robot.dim != 2 or robot.config_dim != 2:
            raise ValueError("the occupancy image observer is for the 2D disc")
        self.size = int(size)
        self.extent = float(extent)
        u = (np.arange(self.size) + 0.5) / self.size * 2 * self.extent - self.extent
        self._offsets = np.stack(np.meshgrid(u, u, indexing="ij"), -1).reshape(-1, 2)
        self._world = None

    def set_scene(self, i: int, scene) -> None:  # type: ignore[no-untyped-def]
        super().set_scene(i, scene)
        self._world = None

    @property
    def space(self) -> spaces.Box:
        return spaces.Box(0.0, 1.0, shape=(1, self.size, self.size), dtype=np.float32)

    def observe(self, q: Array, rng: np.random.Generator) -> NDArray[np.float32]:
        from ..geometry.collision import CollisionWorld

        if self._world is None:
            self._world = CollisionWorld.stack([s.world for s in self.scenes])
        cells = np.asarray(q, np.float64)[:, None, :] + self._offsets[None]  # (E, S*S, 2)
        occ = self.robot.collides(self._world, cells)
        low = np.stack([s.low for s in self.scenes])[:, None, :]
        high = np.stack([s.high for s in self.scenes])[:, None, :]
        occ |= np.any((cells < low) | (cells > high), -1)
        return occ.reshape(-1, 1, self.size, self.size).astype(np.float32)
