"""Robots without orientation: the 2D disc and the 3D sphere."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..geometry.collision import CollisionWorld
from . import _ball_kernels
from ._shortcut_kernels import shortcut_path
from .base import Array, BodyParts, Bool, Robot
from .motion import FlatMotions, MotionCheck

#: the body arrays the compiled shortcut takes for a robot without box parts (unused)
_NO_BODY = (np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((6, 0)))


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

    def check_motions(
        self,
        world: CollisionWorld,
        q0: Array,
        twist: Array,
        n: NDArray[np.int64],
        low: Array | None = None,
        high: Array | None = None,
        fallback: Bool | None = None,
    ) -> MotionCheck:
        """:meth:`Robot.check_motions`, compiled where every obstacle is a box, sphere,
        capsule, cylinder or cone (stacked scenes: boxes only)
        (:func:`pointplan.robots._ball_kernels.check_motions_balls`: the same answers,
        counts and samples); otherwise the numpy check."""
        q0 = np.asarray(q0, np.float64)
        lead = q0.shape[:-1]
        stacked = world.batch_shape != ()
        if not (world.boxes_only or (not stacked and world.primitives_only)) or (stacked and lead != world.batch_shape):
            return super().check_motions(world, q0, twist, n, low, high, fallback)
        fm = FlatMotions.of(q0, twist, n, low, high, fallback, self.dim, self.dim)
        bc, br, bh = (np.require(a, np.float64, ("C", "W")) for a in (world.box_c, world.box_r, world.box_h))
        if not stacked:
            bc, br, bh = bc[None], br[None], bh[None]
        prims = () if stacked else world.ball_prims()
        _ball_kernels.check_motions_balls(
            fm.q0, fm.twist, fm.n, fm.fallback, fm.low, fm.high, self.radius, bc, br, bh, prims, stacked, fm.configs,
            fm.out,
        )  # fmt: skip
        return fm.result()

    def shortcut_compiled(
        self,
        world: CollisionWorld,
        path: Array,
        twists: Array,
        u: Array,
        resolution: float,
        low: Array,
        high: Array,
    ) -> tuple[Array, int] | None:
        """Bi-RRT's shortcutting in one compiled call where every obstacle of the
        (single-scene) world is a box, sphere, capsule, cylinder or cone
        (:func:`pointplan.robots._shortcut_kernels.shortcut_path`: the same path and counts
        as the Python loop); ``None`` otherwise."""
        if world.batch_shape != () or not world.primitives_only:
            return None
        f = np.ascontiguousarray
        boxes = world.box_arrays()
        out, checks = shortcut_path(
            0, f(path, np.float64), f(twists, np.float64), f(u, np.float64), float(resolution),
            f(low, np.float64), f(high, np.float64), self.radius, _NO_BODY, boxes, world.ball_prims(),
        )  # fmt: skip
        return out, int(checks)

    def march_compiled(
        self,
        world: CollisionWorld,
        q0: Array,
        q1: Array,
        v: Array,
        step: float,
        resolution: float,
        max_steps: int | None,
        low: Array,
        high: Array,
    ) -> tuple[Array, bool, int] | None:
        """``march`` in one compiled call where every obstacle of the (single-scene) world
        is a box, sphere, capsule, cylinder or cone
        (:func:`pointplan.robots._ball_kernels.march_balls`); ``None`` otherwise."""
        if world.batch_shape != () or not world.primitives_only:
            return None
        f = np.ascontiguousarray
        nodes, reached, checks = _ball_kernels.march_balls(
            f(q0, np.float64), f(q1, np.float64), f(v, np.float64), float(step), float(resolution),
            -1 if max_steps is None else int(max_steps), f(low, np.float64), f(high, np.float64), self.radius,
            *world.box_arrays(), world.ball_prims(),
        )  # fmt: skip
        return nodes, bool(reached), int(checks)

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
