"""Robots without orientation: the 2D disc and the 3D sphere."""

from __future__ import annotations

import numpy as np

from .base import Array, BodyParts, Robot


class _Ball(Robot):
    """A ball of ``radius`` that translates; twists are plain displacements."""

    def __init__(self, dim: int, radius: float, step: float = 0.07) -> None:
        self.dim = dim
        self.config_dim = dim
        self.twist_dim = dim
        self.radius = float(radius)
        self.action_scale = np.full(dim, float(step))
        self.parts = BodyParts(
            sphere_centers=np.zeros((1, dim)),
            sphere_radii=np.array([self.radius]),
            box_centers=np.zeros((0, dim)),
            box_rotations=np.zeros((0, dim, dim)),
            box_halfs=np.zeros((0, dim)),
        )

    def integrate(self, q: Array, v: Array) -> Array:
        return np.asarray(q, np.float64) + np.asarray(v, np.float64)

    def log(self, q0: Array, q1: Array) -> Array:
        return np.asarray(q1, np.float64) - np.asarray(q0, np.float64)

    def interpolate(self, q0: Array, q1: Array, s: Array | float) -> Array:
        q0 = np.asarray(q0, np.float64)
        s = np.asarray(s, np.float64)[..., None]
        return q0 + s * (np.asarray(q1, np.float64) - q0)

    def rotations(self, q: Array) -> Array:
        q = np.asarray(q)
        return np.broadcast_to(np.eye(self.dim), q.shape[:-1] + (self.dim, self.dim))

    def sample_orientation(self, rng: np.random.Generator, n: int) -> Array:
        return np.zeros((n, 0))

    def to_body_frame(self, q: Array, points: Array, normals: Array | None = None) -> tuple[Array, Array | None]:
        # No rotation: a translation suffices.
        return points - np.asarray(q, np.float64)[..., None, :], normals

    def grown_parts(self, seg: Array, reach: float) -> tuple[Array, Array]:
        # the base class's formula for a translating sphere, without the box-part work
        seg = np.asarray(seg, np.float64)
        r2 = self.radius * self.radius + (reach * reach) * np.einsum("...i,...i->...", seg, seg)
        return np.sqrt(r2)[..., None], np.zeros(seg.shape[:-1] + (0, self.dim))

    def padded(self, margin: float) -> Robot:
        out = super().padded(margin)
        out.radius = self.radius + float(margin)  # type: ignore[attr-defined]
        return out

    def collides(self, world, q, radii=None, halfs=None):  # type: ignore[no-untyped-def]
        q = np.asarray(q, np.float64)
        r = self.radius if radii is None else np.asarray(radii, np.float64)[..., 0]
        if world.batch_shape == ():  # any leading shape, as in Robot.collides
            r = r if np.ndim(r) == 0 else np.broadcast_to(r, q.shape[:-1]).reshape(-1)
            return world.spheres_collide(q.reshape(-1, self.dim), r).reshape(q.shape[:-1])
        return world.spheres_collide(q, r)

    def __repr__(self) -> str:
        return f"{type(self).__name__}(radius={self.radius})"


class Disc2D(_Ball):
    """A disc of radius 0.01 in the plane (2 DoF)."""

    name = "disc2d"

    def __init__(self, radius: float = 0.01, step: float = 0.07) -> None:
        super().__init__(2, radius, step)


class Sphere3D(_Ball):
    """A sphere of radius 0.03 in space (3 DoF)."""

    name = "sphere3d"

    def __init__(self, radius: float = 0.03, step: float = 0.07) -> None:
        super().__init__(3, radius, step)
