"""Point-set observers: boundary points, boundary points with normals, interior points."""

from __future__ import annotations

import numpy as np

from ..geometry.sampling import interior_points, surface_points
from ..scenes.scene import Scene
from .base import Array, PointSetObserver


class SurfacePoints(PointSetObserver):
    """Points on obstacle boundaries (2D: box edges; 3D: faces), thinned to ``spacing``."""

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
