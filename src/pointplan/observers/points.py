"""Point-set observers: boundary points, boundary points with normals, interior points."""

from __future__ import annotations

import zlib

import numpy as np
from numpy.typing import NDArray

from ..geometry.sampling import area_weighted_points, interior_points, surface_points
from ..robots.base import Robot
from ..scenes.scene import Scene
from .base import Array, Observer, PointSetObserver


class SurfacePoints(PointSetObserver):
    """Points on obstacle boundaries (2D: the outlines of boxes, discs and capsules; 3D:
    their surfaces), about ``spacing`` apart."""

    name = "surface"
    with_normals = False

    def points_of(self, scene: Scene) -> tuple[Array, Array]:
        return surface_points(scene.obstacles, self.spacing, scene.low, scene.high)


class SurfaceNormals(SurfacePoints):
    """Boundary points with outward normals: features ``(x, n)`` per point."""

    name = "surface-normals"
    with_normals = True


class InteriorPoints(PointSetObserver):
    """Points on a grid inside the obstacles."""

    name = "interior"
    with_normals = False

    def points_of(self, scene: Scene) -> tuple[Array, Array]:
        p = interior_points(scene.obstacles, self.spacing, scene.low, scene.high)
        return p, np.zeros_like(p)


class GlobalPoints(PointSetObserver):
    """3D "global" observation: points drawn uniformly on the obstacles' surfaces (each
    obstacle in proportion to its area) with outward normals, in the robot frame.

    Each workspace gets a pool of ``pool_size`` surface points once (points hidden inside
    another obstacle are dropped); every observation is a fresh random subset of
    ``n_points`` (default 256) of the pool. Moving obstacles carry their points along."""

    name = "global"
    with_normals = True

    def __init__(self, robot: Robot, n_points: int = 256, pool_size: int = 4096) -> None:
        if robot.dim != 3:
            raise ValueError("the global observation samples 3D surfaces; in 2D use 'surface-normals'")
        super().__init__(robot, n_points, spacing=0.0)
        self.pool_size = int(max(pool_size, n_points))
        self._owner: list[NDArray[np.int64]] = []
        self._owner_stacked: NDArray[np.int64] | None = None

    def pool(self, scene: Scene) -> tuple[Array, Array, NDArray[np.int64]]:
        """The workspace's surface pool: points, normals and the obstacle each lies on
        (cached on the scene, per pool size)."""
        cache = scene.__dict__.setdefault("_observer_cache", {})
        key = ("GlobalPoints", self.pool_size)
        if key not in cache:
            rng = np.random.default_rng(zlib.crc32(scene.name.encode()))
            cache[key] = area_weighted_points(scene.obstacles, self.pool_size, rng)
        return cache[key]

    def points_of(self, scene: Scene) -> tuple[Array, Array]:
        p, n, _ = self.pool(scene)
        return p, n

    def set_scene(self, i: int, scene: Scene) -> None:
        Observer.set_scene(self, i, scene)
        p, n, owner = self.pool(scene)
        self._stacked = None
        self._owner_stacked = None
        if i == len(self._pts):
            self._pts.append(p)
            self._nrm.append(n)
            self._owner.append(owner)
        else:
            self._pts[i], self._nrm[i], self._owner[i] = p, n, owner

    def move(self, pw: Array, nw: Array, t: NDArray[np.int64] | None) -> tuple[Array, Array]:
        dyn = [i for i, s in enumerate(self.scenes) if s.dynamic]
        if not dyn or t is None:
            return pw, nw
        if self._owner_stacked is None:
            pmax = max(len(o) for o in self._owner)
            self._owner_stacked = np.zeros((len(self._owner), max(pmax, 1)), np.int64)
            for i, o in enumerate(self._owner):
                self._owner_stacked[i, : len(o)] = o
        own = np.take_along_axis(self._owner_stacked, self._last_idx, axis=1)
        pw, nw = pw.copy(), nw.copy()
        for i in dyn:
            scene = self.scenes[i]
            c0, r0 = scene.poses_at(0)  # type: ignore[attr-defined]
            ct, rt = scene.poses_at(int(t[i]))  # type: ignore[attr-defined]
            rel = rt @ np.transpose(r0, (0, 2, 1))  # (K, 3, 3)
            k = own[i]
            pw[i] = np.einsum("nij,nj->ni", rel[k], pw[i] - c0[k]) + ct[k]
            nw[i] = np.einsum("nij,nj->ni", rel[k], nw[i])
        return pw, nw
