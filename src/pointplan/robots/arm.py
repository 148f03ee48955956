"""Articulated arms loaded from a URDF: joint space, sphere bodies, certified motions.

A configuration is the vector of the arm's joint positions (radians for revolute joints,
metres for prismatic ones), in the URDF's order; motions are straight lines in joint space
(``q0 + s (q1 - q0)``, the convention of OMPL and MoveIt) and the distance is the Euclidean
norm of the joint difference. A :class:`~pointplan.scenes.scene.Problem` for an arm has a
:class:`JointSpaceScene`: its ``low``/``high`` are the joint limits (what the planners
sample in and the motion checks bound), its obstacles live in the 3D workspace.

The body is a set of spheres, each fixed to one joint's frame (a "spherized" URDF, whose
every collision element is a sphere; :func:`load_arm`). Collision: every sphere against
every obstacle (the scene's :class:`~pointplan.geometry.collision.CollisionWorld`: boxes,
spheres, capsules, cylinders, cones, meshes, point clouds), and against the spheres of the
links the SRDF does not exempt (self-collision). Spheres fixed to the same joint frame never
move relative to each other, and those on adjacent frames (one joint's frame and its
parent's: the links a joint connects, with everything rigidly attached to them) are
exempt as MoveIt exempts adjacent links; neither is tested.

Certified motions. When the joints move at rates ``dq``, the centre of sphere ``i`` moves
at most at ``sum_j W[i, j] |dq_j|`` (:attr:`ArmModel.speed_bound`): a revolute joint ``j``
turns the centre about an axis through the joint's origin, at a distance at most the length
of the kinematic chain from that origin to the centre (each rigid link adds the length of
its joint offset, whatever the configuration), and a prismatic joint moves it at ``|dq_j|``.
So along a joint-space segment of per-sub-step step ``seg`` every centre stays within
``reach * sum_j W[i, j] |seg_j|`` of its position at the nearest sample (``reach = 0.5``)
and :meth:`ArmRobot.grown_parts` grows each sphere by that much. For self-collision only
the joints that carry one sphere of a pair and not the other change the distance between
them (:attr:`ArmModel.pair_speed_bound`); each pair's required distance grows by that
bound, which is far smaller than the two spheres' own growth for neighbouring links. The
generic motion validator (:func:`pointplan.robots.motion.check_motions`) then certifies
joint-space segments exactly as it certifies rigid-body motions: an arm's collision sizes
are its sphere radii followed by its pairs' distances.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field, replace
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..geometry.collision import CollisionWorld
from .base import BodyParts, Robot
from .motion import BOUNDS_EPS, CONTACT_MARGIN, MotionCheck, check_motions

Array = NDArray[np.float64]
Bool = NDArray[np.bool_]
Int = NDArray[np.int64]


@dataclass(frozen=True)
class ArmModel:
    """The kinematic tree and sphere bodies of an arm, as arrays (no library needed to use it).

    Joint ``j`` (movable joints only, fixed ones folded into the placements) has the frame
    ``F_j = F_parent[j] * placement_j * motion_j(q_j)``, where ``placement_j`` is
    ``(rot0[j], pos0[j])`` and the motion turns about (revolute) or slides along (prismatic)
    ``axis[j]`` of the joint's own frame. ``parent[j] = -1``: the arm's base frame."""

    name: str
    joint_names: tuple[str, ...]
    parent: Int
    rot0: Array
    pos0: Array
    axis: Array
    prismatic: Bool
    lower: Array
    upper: Array
    #: per sphere: the joint frame it is fixed to (-1: the base) and its centre in that frame
    sphere_joint: Int
    sphere_center: Array
    sphere_radius: Array
    #: per sphere: the URDF link it belongs to
    sphere_link: tuple[str, ...]
    #: sphere index pairs tested for self-collision ``(K, 2)``
    self_pairs: Int
    #: the base frame in the world: rotation and position
    base_rot: Array = field(default_factory=lambda: np.eye(3))
    base_pos: Array = field(default_factory=lambda: np.zeros(3))

    @property
    def n_joints(self) -> int:
        return len(self.joint_names)

    @property
    def speed_bound(self) -> Array:
        """``W: (P, n)``: the speed of sphere ``i``'s centre is at most ``sum_j W[i, j] |dq_j|``
        (see the module's description); ``W[i, j] = 0`` for joints that do not carry it."""
        return self._bounds()[0]

    @property
    def pair_speed_bound(self) -> Array:
        """``(K, n)``: the distance between the centres of self-collision pair ``k`` changes
        at most at ``sum_j V[k, j] |dq_j|``. Joints that carry both spheres turn or slide
        them together and leave their distance alone, so only the joints that carry one of
        the two count, each with its own sphere's bound."""
        return self._bounds()[1]

    def _bounds(self) -> tuple[Array, Array]:
        cached = self.__dict__.get("_bounds_cache")
        if cached is not None:
            return cached  # type: ignore[no-any-return]
        n = self.n_joints
        # the longest |origin_k - origin_parent(k)| over the configurations
        link = np.linalg.norm(self.pos0, axis=1) + np.where(
            self.prismatic, np.maximum(np.abs(self.lower), np.abs(self.upper)), 0.0
        )
        w = np.zeros((len(self.sphere_radius), n))
        carried = np.zeros((len(self.sphere_radius), n), dtype=bool)
        for i, j0 in enumerate(self.sphere_joint):
            reach, j = float(np.linalg.norm(self.sphere_center[i])), int(j0)
            while j >= 0:  # walk up the chain: reach = longest distance from origin_j to the centre
                w[i, j] = 1.0 if self.prismatic[j] else reach
                carried[i, j] = True
                reach += float(link[j])
                j = int(self.parent[j])
        a, b = self.self_pairs[:, 0], self.self_pairs[:, 1]
        one = carried[a] ^ carried[b]
        v = np.where(one, w[a] + w[b], 0.0)
        object.__setattr__(self, "_bounds_cache", (w, v))
        return w, v

    def joint_frames(self, q: Array) -> tuple[Array, Array]:
        """World rotations ``(B, n, 3, 3)`` and origins ``(B, n, 3)`` of the joint frames at
        configurations ``q: (B, n)``."""
        q = np.asarray(q, np.float64)
        b, n = q.shape
        rot = np.empty((b, n, 3, 3))
        pos = np.empty((b, n, 3))
        for j in range(n):
            a = int(self.parent[j])
            rp, pp = (self.base_rot[None], self.base_pos[None]) if a < 0 else (rot[:, a], pos[:, a])
            r0 = rp @ self.rot0[j]
            p0 = pp + rp @ self.pos0[j]
            if self.prismatic[j]:
                rot[:, j] = r0
                pos[:, j] = p0 + (r0 @ self.axis[j])[None] * q[:, j, None]
            else:
                rot[:, j] = r0 @ axis_rotation(self.axis[j], q[:, j])
                pos[:, j] = p0
        return rot, pos

    def sphere_centers(self, q: Array) -> Array:
        """World centres ``(..., P, 3)`` of the body spheres at configurations ``(..., n)``."""
        q = np.asarray(q, np.float64)
        lead = q.shape[:-1]
        flat = q.reshape(-1, self.n_joints)
        rot, pos = self.joint_frames(flat)
        base = np.concatenate([rot, np.broadcast_to(self.base_rot, (len(flat), 1, 3, 3))], 1)  # index -1: the base
        org = np.concatenate([pos, np.broadcast_to(self.base_pos, (len(flat), 1, 3))], 1)
        j = self.sphere_joint
        c = np.einsum("bpij,pj->bpi", base[:, j], self.sphere_center) + org[:, j]
        return c.reshape(lead + (len(j), 3))


def axis_rotation(axis: Array, angle: Array) -> Array:
    """Rotations ``(B, 3, 3)`` by ``angle: (B,)`` about the unit ``axis`` (Rodrigues)."""
    k = np.asarray(axis, np.float64)
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    s, c = np.sin(angle)[:, None, None], np.cos(angle)[:, None, None]
    return np.eye(3)[None] + s * kx[None] + (1.0 - c) * (kx @ kx)[None]


class ArmRobot(Robot):
    """An articulated arm in joint space (see the module's description)."""

    dim = 3

    def __init__(self, model: ArmModel, step: float = 0.1) -> None:
        self.model = model
        self.name = model.name
        #: the URDF it was loaded from and its folder (empty when built from arrays)
        self.urdf = ""
        self.urdf_dir = ""
        self.config_dim = self.twist_dim = model.n_joints
        self.action_scale = np.full(model.n_joints, float(step))
        self.parts = BodyParts(
            model.sphere_center, model.sphere_radius, np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros((0, 3))
        )
        self._set_sizes()

    def _set_sizes(self) -> None:
        m = self.model
        self._pairs = (m.self_pairs[:, 0], m.self_pairs[:, 1])
        self._radius = m.sphere_radius.reshape(-1)
        #: the sizes the collision test takes (``radii`` of :meth:`collides`): the sphere
        #: radii, then per self-collision pair the least distance its centres must keep
        self._sizes = np.concatenate([self._radius, self._radius[self._pairs[0]] + self._radius[self._pairs[1]]])

    @property
    def euclidean(self) -> bool:
        """Joint space is flat: nearest neighbours and interpolation are Euclidean."""
        return True

    #: joint-space steps of the sampling planners (radians): an edge is certified by
    #: conservative advancement, so long edges cost little where the space is open
    STEP = 0.5
    RESOLUTION = 0.05

    def planner_defaults(self, planner: str) -> dict[str, float]:
        """Longer steps than the rigid robots' 0.07 (a joint-space radian moves the hand
        less than a metre): Bi-RRT's ``step`` and OMPL's ``range``."""
        if planner.startswith("ompl:") or planner == "hybrid-ompl":  # (OMPL's fallback)
            return {"range": self.STEP, "resolution": self.RESOLUTION}
        if planner == "birrt" or planner.startswith("hybrid"):
            return {"step": self.STEP, "resolution": self.RESOLUTION}
        if planner == "straight":
            return {"resolution": self.RESOLUTION}
        return {}

    # ------------------------------------------------------------------ joint space
    @property
    def lower(self) -> Array:
        """The lower joint limits."""
        return self.model.lower

    @property
    def upper(self) -> Array:
        """The upper joint limits."""
        return self.model.upper

    def integrate(self, q: Array, v: Array) -> Array:
        return np.asarray(q, np.float64) + np.asarray(v, np.float64)

    def log(self, q0: Array, q1: Array) -> Array:
        return np.asarray(q1, np.float64) - np.asarray(q0, np.float64)

    @property
    def state_feature_dim(self) -> int:  # type: ignore[override]
        return 7 * self.model.n_joints

    def state_features(self, q: Array, goal: Array) -> Array:
        """The joint state scaled to [-1, 1] by the limits, and the joint frames' origins
        at ``q`` and at ``goal`` (base frame, in units of one step like the observed
        points): a policy observing the obstacles in the base frame must know where its
        links are. ``(..., 7 n)``."""
        q, goal = np.asarray(q, np.float64), np.asarray(goal, np.float64)
        lead, n = q.shape[:-1], self.model.n_joints
        lo, hi = self.model.lower, self.model.upper
        unit = 2.0 * (q - lo) / (hi - lo) - 1.0
        both = np.stack(np.broadcast_arrays(q, goal), -2).reshape(-1, n)
        _, pos = self.model.joint_frames(both)
        pos = ((pos - self.model.base_pos) @ self.model.base_rot) / self.action_scale[0]
        return np.concatenate([unit, pos.reshape(lead + (6 * n,))], -1)

    def positions(self, q: Array) -> Array:
        """The joint positions: what the scene's bounds (the joint limits) bound."""
        return np.asarray(q, np.float64)

    def rotations(self, q: Array) -> Array:
        """The base frame's rotation (the frame the arm observes in), per configuration."""
        q = np.asarray(q, np.float64)
        return np.broadcast_to(self.model.base_rot, q.shape[:-1] + (3, 3)).copy()

    def sample_orientation(self, rng: np.random.Generator, n: int) -> Array:
        return np.zeros((n, 0))

    def sample_uniform(self, rng: np.random.Generator, n: int, low: Array, high: Array) -> Array:
        """``n`` configurations uniform in the joint box ``[low, high]``."""
        return rng.uniform(low, high, size=(n, self.config_dim))

    def clip(self, q: Array, low: Array, high: Array) -> Array:
        return np.clip(np.asarray(q, np.float64), low, high)

    def to_body_frame(self, q: Array, points: Array, normals: Array | None = None) -> tuple[Array, Array | None]:
        """World points (and normals) in the arm's base frame (the same for every ``q``)."""
        rot, pos = self.model.base_rot, self.model.base_pos
        p = (np.asarray(points, np.float64) - pos) @ rot
        return p, None if normals is None else np.asarray(normals, np.float64) @ rot

    # ------------------------------------------------------------------ collision
    def sphere_centers(self, q: Array) -> Array:
        """World centres ``(..., P, 3)`` of the body spheres."""
        return self.model.sphere_centers(q)

    def collides(self, world: CollisionWorld, q: Array, radii: Array | None = None, halfs: Array | None = None) -> Bool:
        """Collision with the world or with itself of configurations ``q`` (shapes as for
        :meth:`Robot.collides`). ``radii: (..., P + K)`` replace the collision sizes (grown
        bodies, :meth:`grown_parts`): ``P`` sphere radii, then ``K`` pair distances."""
        q = np.asarray(q, np.float64)
        lead = q.shape[:-1]
        p = len(self._radius)
        if world.batch_shape == () and _primitives_only(world):
            return self._collides_compiled(world, q, radii)
        size = np.broadcast_to(
            self._sizes if radii is None else np.asarray(radii, np.float64), lead + self._sizes.shape
        )
        rad = size[..., :p]
        c = self.model.sphere_centers(q)  # (..., P, 3)
        if world.batch_shape == ():
            hit = world.spheres_collide(c.reshape(-1, 3), rad.reshape(-1)).reshape(lead + (p,)).any(-1)
        else:
            e = world.batch_shape[0]
            hit = world.spheres_collide(c.reshape(e, -1, 3), rad.reshape(e, -1)).reshape(lead + (p,)).any(-1)
        return hit | self._pairs_within(c, size[..., p:])

    def _collides_compiled(self, world: CollisionWorld, q: Array, radii: Array | None) -> Bool:
        """The compiled test (:mod:`._arm_kernels`) for a scene of boxes, spheres and cylinders."""
        from ._arm_kernels import _arm_collides

        lead = q.shape[:-1]
        flat = np.ascontiguousarray(q.reshape(-1, self.config_dim))
        if radii is None:
            sizes = self._sizes[None]
        else:
            sizes = np.ascontiguousarray(
                np.broadcast_to(np.asarray(radii, np.float64), lead + self._sizes.shape).reshape(-1, len(self._sizes))
            )
        out = np.empty(len(flat), dtype=np.bool_)
        m = self.model
        w = world
        _arm_collides(
            flat, sizes, *self._packed, m.sphere_joint, m.sphere_center, m.self_pairs,
            w.box_c, w.box_r, w.box_h, w.sph_c, w.sph_r, w.cyl_c, w.cyl_r, w.cyl_rad, w.cyl_half, _cloud(w), out,
        )  # fmt: skip
        return out.reshape(lead)

    @property
    def _packed(self) -> tuple[Int, Array]:
        cached = self.__dict__.get("_packed_cache")
        if cached is None:
            from ._arm_kernels import pack_kinematics

            m = self.model
            cached = self.__dict__["_packed_cache"] = pack_kinematics(
                m.parent, m.prismatic, m.rot0, m.pos0, m.axis, m.base_rot, m.base_pos
            )
        return cached  # type: ignore[no-any-return]

    def _pairs_within(self, centers: Array, keep: Array) -> Bool:
        a, b = self._pairs
        d = centers[..., a, :] - centers[..., b, :]
        return np.any(np.einsum("...k,...k->...", d, d) <= keep * keep, axis=-1)  # type: ignore[no-any-return]

    def self_collides(self, centers: Array, radii: Array) -> Bool:
        """Do any two spheres of ``radii: (..., P)`` of links the SRDF does not exempt
        overlap, at ``centers: (..., P, 3)``? ``(...)``."""
        a, b = self._pairs
        return self._pairs_within(centers, radii[..., a] + radii[..., b])

    def grown_parts(self, seg: Array, reach: float) -> tuple[Array, Array]:
        """Collision sizes for a sub-step ``seg: (..., n)`` of a joint-space segment (see the
        module's description): each sphere radius grown by ``reach`` times the most its
        centre moves, each pair distance by ``reach`` times the most it changes."""
        seg = np.abs(np.asarray(seg, np.float64))
        radii = self._radius + reach * (seg @ self.model.speed_bound.T)
        pairs = self._sizes[len(self._radius) :] + reach * (seg @ self.model.pair_speed_bound.T)
        return np.concatenate([radii, pairs], -1), np.zeros(seg.shape[:-1] + (0, 3))

    def check_motions(
        self,
        world: CollisionWorld,
        q0: Array,
        twist: Array,
        n: Int,
        low: Array | None = None,
        high: Array | None = None,
        fallback: Bool | None = None,
    ) -> MotionCheck:
        """Certify the joint-space segments ``q0 + s twist``. Scenes of boxes, spheres and
        cylinders: by conservative advancement (:func:`advance`: steps as long as the
        clearance allows, so an open stretch costs a few configurations and a tight one
        many), reported on the grid of ``n`` sub-steps (``free = floor(certified * n)``).
        Other scenes: the generic grid of grown bodies (:func:`pointplan.robots.motion.check_motions`)."""
        if world.batch_shape != () or not _primitives_only(world):
            return check_motions(self, world, q0, twist, n, low, high, fallback)
        q0 = np.asarray(q0, np.float64)
        twist = np.asarray(twist, np.float64)
        lead = q0.shape[:-1]
        n = np.broadcast_to(np.maximum(np.asarray(n, np.int64), 1), lead)
        frac, checks = self.advance(world, q0.reshape(-1, self.config_dim), twist.reshape(-1, self.config_dim))
        frac, checks = frac.reshape(lead), checks.reshape(lead)
        inside = np.ones(lead)
        if low is not None and high is not None:
            inside = _fraction_inside(q0, twist, np.asarray(low, np.float64), np.asarray(high, np.float64))
        reach = np.minimum(frac, inside)
        free = np.where(reach >= 1.0, n, np.where(reach < 0, -1, np.floor(reach * n + 1e-12).astype(np.int64)))
        free = np.where((reach < 1.0) & (free >= n), n - 1, free)
        nmax = int(n.max()) if n.size else 1
        s = np.minimum(np.arange(nmax + 1) / n[..., None], 1.0)
        qs = q0[..., None, :] + twist[..., None, :] * s[..., None]
        return MotionCheck(
            free=free.astype(np.int64), collided=frac < np.minimum(inside, 1.0), checks=checks, configs=qs
        )

    #: conservative advancement evaluates at most this many configurations per radian of a
    #: segment (at least ``ADVANCE_MIN``): a segment that grazes an obstacle would otherwise
    #: take ever shorter steps; past the budget it counts as blocked where it got (measured
    #: on MotionBenchMaker: 3x faster Bi-RRT and RRTConnect than a budget of 5,000, no
    #: fewer problems solved)
    ADVANCE_PER_RADIAN = 400
    ADVANCE_MIN = 64

    #: before advancing, configurations this far apart (radians) along a segment are tested
    #: plainly; a segment is advanced only up to its first colliding one (a blocked
    #: shortcut or extension then costs a few tests instead of a long advance)
    PROBE_SPACING = 0.1

    def advance(self, world: CollisionWorld, q0: Array, twist: Array) -> tuple[Array, Int]:
        """Conservative advancement along segments ``q0[e] + s twist[e]`` (``(E, n)`` each)
        in a scene of boxes, spheres and cylinders: the fraction certified free (1: the whole
        segment; -1: not even its start) and the configurations evaluated, per segment."""
        q0, twist = np.ascontiguousarray(q0, np.float64), np.ascontiguousarray(twist, np.float64)
        length = np.linalg.norm(twist, axis=-1)
        probes = np.minimum(32, np.ceil(length / self.PROBE_SPACING)).astype(np.int64)  # (the end is probed too)
        k = int(probes.max(initial=0))
        reach = np.ones(len(q0))
        tested = np.zeros(len(q0), np.int64)
        if k:
            s = np.minimum(np.arange(1, k + 1)[None] / np.maximum(probes, 1)[:, None], 1.0)  # (E, k)
            hit = self.collides(world, q0[:, None] + s[..., None] * twist[:, None]) & (
                np.arange(k)[None] < probes[:, None]
            )
            first = np.where(hit.any(1), hit.argmax(1), -1)
            reach = np.where(first >= 0, s[np.arange(len(q0)), np.maximum(first, 0)], 1.0)
            tested = np.where(first >= 0, first + 1, probes)
        frac, n = self._advance(world, q0, twist * reach[:, None], length * reach)
        return np.where(frac > 0, frac * reach, frac), n + tested

    def _advance(self, world: CollisionWorld, q0: Array, twist: Array, length: Array) -> tuple[Array, Int]:
        from ._arm_kernels import _arm_advance

        max_iter = np.maximum(self.ADVANCE_MIN, np.ceil(self.ADVANCE_PER_RADIAN * length)).astype(np.int64)
        m, w = self.model, world
        out_s, out_n = np.empty(len(q0)), np.empty(len(q0), np.int64)
        p = len(self._radius)
        _arm_advance(
            q0, np.ascontiguousarray(twist), *self._packed, m.sphere_joint, m.sphere_center, m.self_pairs,
            self._sizes[:p], self._sizes[p:], m.speed_bound, m.pair_speed_bound,
            w.box_c, w.box_r, w.box_h, w.sph_c, w.sph_r, w.cyl_c, w.cyl_r, w.cyl_rad, w.cyl_half, _cloud(w),
            CONTACT_MARGIN, max_iter, out_s, out_n,
        )  # fmt: skip
        return out_s, out_n

    def padded(self, margin: float) -> ArmRobot:
        if margin < 0:
            raise ValueError(f"margin must be >= 0, not {margin}")
        out = copy.copy(self)
        out.model = replace(self.model, sphere_radius=self.model.sphere_radius + margin)
        out.parts = BodyParts(
            out.model.sphere_center,
            out.model.sphere_radius,
            self.parts.box_centers,
            self.parts.box_rotations,
            self.parts.box_halfs,
        )
        out._set_sizes()
        return out

    def __repr__(self) -> str:
        return f"ArmRobot({self.name!r}, joints={self.config_dim}, spheres={len(self._radius)})"


def _fraction_inside(q0: Array, twist: Array, low: Array, high: Array) -> Array:
    """How far along ``q0 + s twist`` the segment stays inside the box ``[low, high]``
    (1: all of it; -1: not even its start), per segment."""
    eps = BOUNDS_EPS
    start_in = np.all((q0 >= low - eps) & (q0 <= high + eps), axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        t_hi = np.where(twist > 0, (high + eps - q0) / twist, np.inf)
        t_lo = np.where(twist < 0, (low - eps - q0) / twist, np.inf)
    t = np.minimum(np.min(t_hi, axis=-1), np.min(t_lo, axis=-1))
    return np.where(start_in, np.minimum(t, 1.0), -1.0)


def _primitives_only(world: CollisionWorld) -> bool:
    """Whether a single-scene world holds only boxes, spheres, cylinders and point clouds
    (what the compiled arm test handles; capsules, cones and meshes take the numpy path)."""
    return (
        world.cap_a.shape[-2] == 0
        and world.con_c.shape[-2] == 0
        and (world.dim == 3 or all(t is None for t in world.cloud_trees))
        and not any(it[4] is not None for items in world.coal_items for it in items)
    )


def _cloud(world: CollisionWorld) -> tuple[Any, ...]:
    """The single scene's cloud as the compiled arm test takes it (an empty one without)."""
    from ._arm_kernels import pack_cloud

    return pack_cloud(world.sphere_grid(), world.cloud_point_radius())


# ---------------------------------------------------------------------- loading
#: pinocchio's joint models: short name -> (prismatic, axis; None: the model's own axis)
_JOINTS: dict[str, tuple[bool, tuple[float, float, float] | None]] = {
    "JointModelRX": (False, (1.0, 0.0, 0.0)),
    "JointModelRY": (False, (0.0, 1.0, 0.0)),
    "JointModelRZ": (False, (0.0, 0.0, 1.0)),
    "JointModelRevoluteUnaligned": (False, None),
    "JointModelPX": (True, (1.0, 0.0, 0.0)),
    "JointModelPY": (True, (0.0, 1.0, 0.0)),
    "JointModelPZ": (True, (0.0, 0.0, 1.0)),
    "JointModelPrismaticUnaligned": (True, None),
}


#: arms that ship with the package: name -> (URDF, SRDF) in ``data/robots/<name>/``
ARMS = {"panda": ("panda_spherized.urdf", "panda.srdf"), "ur5": ("ur5_spherized.urdf", "ur5.srdf")}


def arm_data(name: str) -> Any:
    """The package folder of a shipped arm's files."""
    from importlib import resources

    if name not in ARMS:
        raise ValueError(f"unknown arm {name!r}; shipped: {', '.join(ARMS)} (or load_arm(urdf, srdf) for your own)")
    return resources.files("pointplan") / "data" / "robots" / name


@cache
def make_arm(name: str, step: float = 0.1) -> ArmRobot:
    """A shipped arm (``panda``, ``ur5``) from its spherized URDF and SRDF."""
    from importlib import resources

    d = arm_data(name)
    urdf, srdf = ARMS[name]
    with resources.as_file(d / urdf) as u, resources.as_file(d / srdf) as s:
        return load_arm(u, s, name, step)


def disabled_pairs(srdf: str | Path) -> set[frozenset[str]]:
    """The link pairs an SRDF exempts from self-collision (``disable_collisions``)."""
    import xml.etree.ElementTree as ET

    try:
        root = ET.parse(srdf).getroot()
    except (OSError, ET.ParseError) as e:
        raise ValueError(f"{srdf}: not a readable SRDF ({e})") from None
    return {frozenset((el.get("link1", ""), el.get("link2", ""))) for el in root.iter("disable_collisions")}


def load_arm(urdf: str | Path, srdf: str | Path | None = None, name: str | None = None, step: float = 0.1) -> ArmRobot:
    """An :class:`ArmRobot` from a URDF whose collision elements are spheres (and an SRDF
    whose ``disable_collisions`` pairs skip self-collision tests; without one every pair of
    links that are not rigidly joined is tested). The URDF is read by pinocchio."""
    import pinocchio as pin

    urdf = Path(urdf)
    if not urdf.is_file():
        raise FileNotFoundError(f"{urdf}: no such URDF file")
    try:
        model = pin.buildModelFromUrdf(str(urdf))
        geom = pin.buildGeomFromUrdf(model, str(urdf), pin.GeometryType.COLLISION, package_dirs=[str(urdf.parent)])
    except Exception as e:  # pinocchio raises plain ValueError/RuntimeError with long messages
        raise ValueError(
            f"{urdf}: pinocchio could not read it ({str(e).splitlines()[0] if str(e) else type(e).__name__})"
        ) from None
    robot = ArmRobot(
        arm_model_from_pinocchio(model, geom, disabled_pairs(srdf) if srdf else set(), name or model.name), step
    )
    robot.urdf, robot.urdf_dir = str(urdf), str(urdf.parent)  # (what the evaluator rebuilds it from)
    return robot


def arm_model_from_pinocchio(model: object, geom: object, disabled: set[frozenset[str]], name: str) -> ArmModel:
    """The arrays of :class:`ArmModel` from a pinocchio model and its collision geometry."""
    import coal

    m, g = model, geom
    n = m.njoints - 1  # type: ignore[attr-defined]
    kinds = [m.joints[j].shortname() for j in range(1, n + 1)]  # type: ignore[attr-defined]
    bad = [(m.names[j + 1], k) for j, k in enumerate(kinds) if k not in _JOINTS]  # type: ignore[attr-defined]
    if bad:
        raise ValueError(
            f"{name}: joint {bad[0][0]} is a {bad[0][1]}: only revolute and prismatic joints are supported"
        )
    axis = []
    for j, k in enumerate(kinds):
        fixed = _JOINTS[k][1]
        axis.append(np.asarray(fixed if fixed is not None else m.joints[j + 1].extract().axis, np.float64))  # type: ignore[attr-defined]
    pl = [m.jointPlacements[j] for j in range(1, n + 1)]  # type: ignore[attr-defined]
    centers, radii, joints, links = [], [], [], []
    for o in g.geometryObjects:  # type: ignore[attr-defined]
        if not isinstance(o.geometry, coal.Sphere):
            link = m.frames[o.parentFrame].name  # type: ignore[attr-defined]
            raise ValueError(
                f"{name}: link {link} has a {type(o.geometry).__name__} collision element; use a URDF whose collision elements are spheres"
            )
        centers.append(np.asarray(o.placement.translation, np.float64))
        radii.append(float(o.geometry.radius))
        joints.append(int(o.parentJoint) - 1)
        links.append(m.frames[o.parentFrame].name)  # type: ignore[attr-defined]
    sj = np.asarray(joints, np.int64)
    parent = [m.parents[j] - 1 for j in range(1, n + 1)]  # type: ignore[attr-defined]

    def tested(a: int, b: int) -> bool:
        ja, jb = int(sj[a]), int(sj[b])
        rigid_or_adjacent = ja == jb or (jb >= 0 and parent[jb] == ja) or (ja >= 0 and parent[ja] == jb)
        return not rigid_or_adjacent and links[a] != links[b] and frozenset((links[a], links[b])) not in disabled

    pairs = [(a, b) for a in range(len(radii)) for b in range(a + 1, len(radii)) if tested(a, b)]
    lower = np.asarray(m.lowerPositionLimit, np.float64)  # type: ignore[attr-defined]
    upper = np.asarray(m.upperPositionLimit, np.float64)  # type: ignore[attr-defined]
    if not (np.all(np.isfinite(lower)) and np.all(np.isfinite(upper)) and np.all(upper > lower)):
        raise ValueError(f"{name}: every joint needs finite limits with lower < upper")
    return ArmModel(
        name=name,
        joint_names=tuple(m.names[j] for j in range(1, n + 1)),  # type: ignore[attr-defined]
        parent=np.array(parent, np.int64),
        rot0=np.array([np.asarray(p.rotation) for p in pl]),
        pos0=np.array([np.asarray(p.translation) for p in pl]),
        axis=np.array(axis),
        prismatic=np.array([_JOINTS[k][0] for k in kinds]),
        lower=lower,
        upper=upper,
        sphere_joint=sj,
        sphere_center=np.array(centers).reshape(-1, 3),
        sphere_radius=np.array(radii),
        sphere_link=tuple(links),
        self_pairs=np.array(pairs, np.int64).reshape(-1, 2),
    )
