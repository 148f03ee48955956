"""Obstacle shapes, in the world frame.

Sizes follow one convention everywhere: boxes take *full* side lengths, capsules and
cylinders a radius and a full length along their local z axis. 2D scenes use the same
classes with 2-vectors (boxes with a 2x2 rotation; spheres are discs).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]


def _vec(x: object, n: int | None = None) -> Array:
    a = np.asarray(x, dtype=np.float64).reshape(-1)
    if n is not None and a.shape != (n,):
        raise ValueError(f"expected {n} numbers, got {a.shape[0]}")
    return a


@dataclass(frozen=True)
class Box:
    """Oriented box: ``center: (d,)``, full side lengths ``size: (d,)``, ``rotation: (d, d)``."""

    center: Array
    size: Array
    rotation: Array = field(default=None)  # type: ignore[arg-type]  # (set in __post_init__)

    def __post_init__(self) -> None:
        c = _vec(self.center)
        object.__setattr__(self, "center", c)
        object.__setattr__(self, "size", _vec(self.size, c.shape[0]))
        rot = np.eye(c.shape[0]) if self.rotation is None else np.asarray(self.rotation, np.float64)
        object.__setattr__(self, "rotation", rot.reshape(c.shape[0], c.shape[0]))

    @property
    def dim(self) -> int:
        """2 or 3."""
        return int(self.center.shape[0])

    @property
    def half(self) -> Array:
        """The half side lengths."""
        return self.size / 2.0


@dataclass(frozen=True)
class Sphere:
    """Sphere (a disc in 2D)."""

    center: Array
    radius: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "center", _vec(self.center))
        object.__setattr__(self, "radius", float(self.radius))

    @property
    def dim(self) -> int:
        """2 or 3."""
        return int(self.center.shape[0])


@dataclass(frozen=True)
class Capsule:
    """All points within ``radius`` of the segment ``a -> b``."""

    a: Array
    b: Array
    radius: float

    def __post_init__(self) -> None:
        a = _vec(self.a)
        object.__setattr__(self, "a", a)
        object.__setattr__(self, "b", _vec(self.b, a.shape[0]))
        object.__setattr__(self, "radius", float(self.radius))

    @property
    def dim(self) -> int:
        """2 or 3."""
        return int(self.a.shape[0])


@dataclass(frozen=True)
class _AxialSolid:
    """A solid of revolution (3D only) about the local z axis of ``rotation``: centre,
    radius and full ``length`` along the axis (shared by :class:`Cylinder` and :class:`Cone`)."""

    center: Array
    radius: float
    length: float
    rotation: Array = field(default=None)  # type: ignore[arg-type]  # (set in __post_init__)

    def __post_init__(self) -> None:
        object.__setattr__(self, "center", _vec(self.center, 3))
        object.__setattr__(self, "radius", float(self.radius))
        object.__setattr__(self, "length", float(self.length))
        rot = np.eye(3) if self.rotation is None else np.asarray(self.rotation, np.float64)
        object.__setattr__(self, "rotation", rot.reshape(3, 3))

    @property
    def dim(self) -> int:
        """2 or 3."""
        return 3


@dataclass(frozen=True)
class Cylinder(_AxialSolid):
    """Solid cylinder (3D only) around the local z axis of ``rotation``, full ``length``."""


@dataclass(frozen=True)
class Cone(_AxialSolid):
    """Solid right circular cone (3D only) around the local z axis of ``rotation``: base disc
    of ``radius`` at ``z = -length/2``, apex at ``z = +length/2`` (coal's convention)."""


@dataclass(frozen=True)
class Mesh:
    """Triangle mesh in the world frame (3D only): ``vertices: (V, 3)``, ``faces: (F, 3)``."""

    vertices: Array
    faces: NDArray[np.int64]
    source: Path | None = None

    def __post_init__(self) -> None:
        v = np.asarray(self.vertices, np.float64).reshape(-1, 3)
        f = np.asarray(self.faces, np.int64).reshape(-1, 3)
        object.__setattr__(self, "vertices", v)
        object.__setattr__(self, "faces", f)

    @property
    def dim(self) -> int:
        """2 or 3."""
        return 3


#: a cloud point stands for a sphere this many median nearest-neighbour spacings wide
#: (:meth:`PointCloud.point_radius`): measured on 20,000 area-weighted random points on two
#: boxes, 2,000 rays (tests/test_raycast.py): at 1.5 spacings 2% of the rays slip through
#: the holes of a random sampling, at 2.5 none, with hit distances within 9 mm of the
#: boxes' and every normal the face's
SPLAT_FACTOR = 2.5


@dataclass(frozen=True)
class PointCloud:
    """Observed obstacle points with outward normals: ``points, normals: (P, d)``.

    A point cloud samples a surface: each point stands for a small sphere of radius
    :meth:`point_radius` (``radius`` when given, else :data:`SPLAT_FACTOR` times the
    median distance between nearest points), so that neither a ray nor the robot's body
    slips between the points of a sampled surface. The collision checks, the ray caster
    and the evaluator all use it.
    """

    points: Array
    normals: Array
    source: Path | None = None
    radius: float | None = None
    _auto_radius: float | None = field(default=None, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        p = np.asarray(self.points, np.float64)
        if p.ndim != 2:
            raise ValueError("points must be a (P, d) array")
        n = np.asarray(self.normals, np.float64).reshape(p.shape)
        norm = np.linalg.norm(n, axis=1, keepdims=True)
        n = np.where(norm > 0, n / np.where(norm > 0, norm, 1.0), 0.0)
        object.__setattr__(self, "points", p)
        object.__setattr__(self, "normals", n)
        if self.radius is not None and not (np.isfinite(self.radius) and self.radius >= 0):
            raise ValueError(f"a point cloud's radius must be a finite number >= 0, not {self.radius}")

    @property
    def dim(self) -> int:
        """2 or 3."""
        return int(self.points.shape[1])

    def point_radius(self) -> float:
        """The radius of the sphere each point stands for (computed once)."""
        if self.radius is not None:
            return float(self.radius)
        if self._auto_radius is None:
            if len(self.points) < 2:
                r = 0.0
            else:
                from scipy.spatial import cKDTree

                dist, _ = cKDTree(self.points).query(self.points, k=2)
                r = float(np.median(dist[:, 1])) * SPLAT_FACTOR
            object.__setattr__(self, "_auto_radius", r)
        return float(self._auto_radius)  # type: ignore[arg-type]


Shape = Box | Sphere | Capsule | Cylinder | Cone | Mesh | PointCloud
