"""The S-shaped free-flying body (6 DoF): five square bars."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..geometry import lie
from ..geometry._se3_kernels import pose_integrate_compiled, pose_log_compiled
from ..geometry.collision import CollisionWorld
from . import _body_kernels
from ._shortcut_kernels import shortcut_path
from .base import Array, BodyParts, Bool, Robot
from .motion import FlatMotions, MotionCheck

#: centreline corners of the S-shape, body frame (from the paper's release)
S_CORNERS = np.array(
    [
        [-0.155, -0.082, 0.009],
        [0.009, -0.082, 0.009],
        [0.009, 0.082, 0.009],
        [0.009, 0.082, 0.173],
        [0.173, 0.082, 0.173],
        [0.173, 0.082, 0.009],
    ]
)
BAR_THICKNESS = 0.036
BAR_LENGTH = 0.2


def _flat_pair(a: Array, b: Array, da: int, db: int) -> tuple[tuple[int, ...], Array, Array]:
    """Broadcast ``a (..., da)`` and ``b (..., db)`` on their leading dimensions; returns the
    common batch shape and both as C-contiguous float64 ``(N, d)`` arrays (what the compiled
    kernels read: they index without bounds checks, so the last dimensions are checked)."""
    a = np.asarray(a, np.float64)
    b = np.asarray(b, np.float64)
    if a.shape[-1:] != (da,) or b.shape[-1:] != (db,):
        raise ValueError(f"expected shapes (..., {da}) and (..., {db}), got {a.shape} and {b.shape}")
    batch = np.broadcast_shapes(a.shape[:-1], b.shape[:-1])
    n = math.prod(batch)
    if a.shape[:-1] != batch:
        a = np.broadcast_to(a, batch + (da,))
    if b.shape[:-1] != batch:
        b = np.broadcast_to(b, batch + (db,))
    return batch, np.ascontiguousarray(a.reshape(n, da)), np.ascontiguousarray(b.reshape(n, db))


def _bars() -> BodyParts:
    centers, rots, halfs = [], [], []
    for a, b in zip(S_CORNERS[:-1], S_CORNERS[1:]):
        axis = int(np.argmax(np.abs(b - a)))
        centers.append((a + b) / 2)
        rots.append(np.eye(3))
        h = np.full(3, BAR_THICKNESS / 2)
        # each bar is 0.2 long: the centreline segment (0.164) plus half a thickness each end
        h[axis] = BAR_LENGTH / 2
        halfs.append(h)
    return BodyParts(
        sphere_centers=np.zeros((0, 3)),
        sphere_radii=np.zeros(0),
        box_centers=np.array(centers),
        box_rotations=np.array(rots),
        box_halfs=np.array(halfs),
    )


class SShape(Robot):
    """Configuration ``(x, y, z, qx, qy, qz, qw)``; twists ``(vx, vy, vz, wx, wy, wz)`` in the
    body frame, scaled by 0.07 per translation axis and 0.2 rad per rotation axis."""

    name = "sshape"
    #: the side of the cells a point cloud is sorted into for the compiled checks
    #: (:meth:`CollisionWorld.cloud_grid`): about the bars' thickness
    cloud_cell = BAR_THICKNESS
    dim = 3
    config_dim = 7
    twist_dim = 6

    def __init__(self, step: float = 0.07, rot_step: float = 0.2) -> None:
        self.action_scale = np.array([step] * 3 + [rot_step] * 3)
        self.parts = _bars()

    @staticmethod
    def to_matrix(q: Array) -> Array:
        """Homogeneous matrices ``(..., 4, 4)`` of configurations."""
        q = np.asarray(q, np.float64)
        out = np.zeros(q.shape[:-1] + (4, 4))
        out[..., :3, :3] = lie.quat_to_matrix(q[..., 3:])
        out[..., :3, 3] = q[..., :3]
        out[..., 3, 3] = 1.0
        return out

    @staticmethod
    def from_matrix(t: Array) -> Array:
        """Poses ``(..., 7)`` (position, quaternion) of homogeneous matrices ``t: (..., 4, 4)``."""
        t = np.asarray(t, np.float64)
        return np.concatenate([t[..., :3, 3], lie.matrix_to_quat(t[..., :3, :3])], -1)

    # integrate and log take the compiled quaternion kernels (10-40x faster for the 1 to
    # 256 configurations a planner passes per call); the numpy versions through 4x4
    # matrices are the reference (``NumpySShape`` uses them), for tests and benchmarks.
    def integrate(self, q: Array, v: Array) -> Array:
        batch, qf, vf = _flat_pair(q, v, 7, 6)
        return pose_integrate_compiled(qf, vf).reshape(batch + (7,))

    def log(self, q0: Array, q1: Array) -> Array:
        batch, af, bf = _flat_pair(q0, q1, 7, 7)
        return pose_log_compiled(af, bf).reshape(batch + (6,))

    @classmethod
    def _integrate_numpy(cls, q: Array, v: Array) -> Array:
        return cls.from_matrix(cls.to_matrix(q) @ lie.se3_exp(v))

    @classmethod
    def _log_numpy(cls, q0: Array, q1: Array) -> Array:
        return lie.relative_twist(cls.to_matrix(q0), cls.to_matrix(q1))

    def rotations(self, q: Array) -> Array:
        return lie.quat_to_matrix(np.asarray(q, np.float64)[..., 3:])

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
        """:meth:`Robot.check_motions`, compiled where every obstacle is a box, or in one
        scene of boxes and a point cloud (:func:`pointplan.robots._body_kernels.check_motions_boxes`,
        ``check_motions_cloud``: the same answers, counts and samples); otherwise the numpy
        check."""
        q0 = np.asarray(q0, np.float64)
        lead = q0.shape[:-1]
        stacked = world.batch_shape != ()
        obstacles = None if stacked else self._obstacles(world)
        if (not stacked and obstacles is None) or (stacked and (not world.boxes_only or lead != world.batch_shape)):
            return super().check_motions(world, q0, twist, n, low, high, fallback)
        fm = FlatMotions.of(q0, twist, n, low, high, fallback, 3, 6)
        body = self._body_arrays()
        if obstacles is not None and len(obstacles) == 4:
            _body_kernels.check_motions_cloud(
                fm.q0, fm.twist, fm.n, fm.fallback, fm.low, fm.high, body, obstacles, fm.configs, fm.out
            )
        else:
            boxes = [np.require(a, np.float64, ("C", "W")) for a in (world.box_c, world.box_r, world.box_h)]
            bc, br, bh = boxes if stacked else [b[None] for b in boxes]
            _body_kernels.check_motions_boxes(
                fm.q0, fm.twist, fm.n, fm.fallback, fm.low, fm.high, body, bc, br, bh, stacked, fm.configs, fm.out
            )
        return fm.result()

    def collides(self, world: CollisionWorld, q: Array, radii: Array | None = None, halfs: Array | None = None) -> Bool:
        """:meth:`Robot.collides`, compiled in one scene of boxes and a point cloud
        (:func:`pointplan.robots._body_kernels.bodies_hit`: the same answers)."""
        obstacles = None if world.boxes_only else self._obstacles(world)
        if obstacles is None or len(self.parts.sphere_radii):
            return super().collides(world, q, radii, halfs)
        q = np.asarray(q, np.float64)
        if q.shape[-1:] != (7,):
            raise ValueError(f"expected configurations (..., 7), got {q.shape}")
        lead = q.shape[:-1]
        pb = len(self.parts.box_halfs)
        hal = np.broadcast_to(self.parts.box_halfs if halfs is None else np.asarray(halfs, np.float64), lead + (pb, 3))
        m = math.prod(lead)
        f = np.ascontiguousarray
        out = np.empty(m, np.bool_)
        _body_kernels.bodies_hit(
            f(q.reshape(m, 7)), f(hal.reshape(m, pb, 3), np.float64), self._body_arrays(), obstacles, out
        )
        return out.reshape(lead)

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
        (single-scene) world is a box or a point cloud
        (:func:`pointplan.robots._shortcut_kernels.shortcut_path`: the same path and counts
        as the Python loop); ``None`` otherwise."""
        boxes = self._obstacles(world)
        if boxes is None:
            return None
        f = np.ascontiguousarray
        out, checks = shortcut_path(
            1, f(path, np.float64), f(twists, np.float64), f(u, np.float64), float(resolution),
            f(low, np.float64), f(high, np.float64), 0.0, self._body_arrays(), boxes, (),
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
        is a box or a point cloud (:func:`pointplan.robots._body_kernels.march_boxes`: the
        same nodes, answer and counts); ``None`` otherwise."""
        boxes = self._obstacles(world)
        if boxes is None:
            return None
        f = np.ascontiguousarray
        nodes, reached, checks = _body_kernels.march_boxes(
            f(q0, np.float64), f(q1, np.float64), f(v, np.float64), float(step), float(resolution),
            -1 if max_steps is None else int(max_steps), f(low, np.float64), f(high, np.float64),
            self._body_arrays(), boxes,
        )  # fmt: skip
        return nodes, bool(reached), int(checks)

    def nearest(self, nodes: Array, q: Array) -> tuple[int, Array]:
        """The node nearest to ``q`` and the twist from it (a compiled scan)."""
        i, v = _body_kernels.nearest_pose(np.ascontiguousarray(nodes, np.float64), np.ascontiguousarray(q, np.float64))
        return int(i), v

    def _obstacles(self, world: CollisionWorld) -> tuple[Any, ...] | None:
        """The obstacles of a single-scene world of boxes and point clouds as the compiled
        checks take them: the boxes ``(centres, rotations, half sides)``, and the cloud's
        grid (``world.cloud_grid``, cells of :attr:`cloud_cell`) where it has points;
        ``None`` for a stacked world or one with other shapes."""
        if world.batch_shape != () or not world.boxes_and_clouds_only:
            return None
        boxes = world.box_arrays()
        grid = None if world.boxes_only else world.cloud_grid(self.cloud_cell)
        return boxes if grid is None else (*boxes, grid)

    def _body_arrays(self) -> tuple[Array, Array, Array]:
        """The body's box centres, half sides and corner map as the compiled kernels take
        them (built once per body: ``padded`` copies get their own)."""
        cached = self.__dict__.get("_body_cache")
        if cached is None or cached[0] is not self.parts:
            f = np.ascontiguousarray
            p = self.parts
            if not np.array_equal(p.box_rotations, np.broadcast_to(np.eye(3), p.box_rotations.shape)):
                raise ValueError("the compiled checks take body boxes aligned with the body frame")
            arrays = (f(p.box_centers, np.float64), f(p.box_halfs, np.float64), f(self._corner_velocity))
            cached = self.__dict__["_body_cache"] = (p, arrays)
        return cached[1]

    def sample_orientation(self, rng: np.random.Generator, n: int) -> Array:
        return lie.matrix_to_quat(lie.random_rotations(rng, n))


class OrientedSShape(SShape):
    """The S-shape told its orientation, as an inertial sensor would: the same body, motion
    and observations, and a policy is also given the world's three axes in the body frame
    (the rows of the body-to-world rotation, 9 numbers) beside the goal vector. The
    observations are in the body frame, so a plain S-shape policy cannot tell which way the
    world's axes run where the scene looks the same in several orientations (Slot's square
    wall: which way its opening runs). Not the paper's observation; a variant to measure
    what that knowledge is worth. Demonstrations of ``sshape`` serve it unchanged (same
    body, :attr:`~pointplan.robots.base.Robot.body`)."""

    name = "sshape-oriented"
    body = "sshape"
    state_feature_dim = 9

    def state_features(self, q: Array, goal: Array) -> Array:
        """The world's x, y and z axes in the body frame, ``(..., 9)``."""
        rot = self.rotations(q)
        return rot.reshape(rot.shape[:-2] + (9,))


class NumpySShape(SShape):
    """The S-shape with ``integrate`` and ``log`` through 4x4 matrices and the motion
    checks in numpy: the reference the compiled kernels are tested and benchmarked
    against."""

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
        return Robot.check_motions(self, world, q0, twist, n, low, high, fallback)

    def collides(self, world: CollisionWorld, q: Array, radii: Array | None = None, halfs: Array | None = None) -> Bool:
        return Robot.collides(self, world, q, radii, halfs)

    def integrate(self, q: Array, v: Array) -> Array:
        return self._integrate_numpy(q, v)

    def log(self, q0: Array, q1: Array) -> Array:
        return self._log_numpy(q0, q1)
