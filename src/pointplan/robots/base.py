"""Rigid robots: body geometry plus configuration-space operations.

Configurations are float arrays with any leading batch shape. A configuration is the pose
of the body frame in the world: ``(x, y)`` for the disc, ``(x, y, z)`` for the sphere and
``(x, y, z, qx, qy, qz, qw)`` for free-flying bodies. Motions are *body twists*: the robot
moves from ``q`` to ``q * exp(v)``. The distance between two configurations is the norm of
the twist that joins them, ``||log(q0^-1 q1)||`` (metres and radians weighted one to one),
and every part of the package (env, planners, evaluator) uses this one distance.
"""

from __future__ import annotations

import copy
from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..geometry.collision import CollisionWorld
from .motion import MotionCheck, check_motions

Array = NDArray[np.float64]
Bool = NDArray[np.bool_]


@dataclass(frozen=True)
class BodyParts:
    """Body geometry in the body frame: spheres and oriented boxes (half sides)."""

    sphere_centers: Array  # (Ps, d)
    sphere_radii: Array  # (Ps,)
    box_centers: Array  # (Pb, d)
    box_rotations: Array  # (Pb, d, d)
    box_halfs: Array  # (Pb, d)


class Robot(ABC):
    """A rigid body that moves by body twists. Subclasses fill in the group operations."""

    #: short name used in files and on the command line
    name: str
    #: workspace dimension (2 or 3)
    dim: int
    #: length of a configuration vector
    config_dim: int
    #: length of a twist (= the action dimension)
    twist_dim: int
    #: action scale per twist axis: action in [-1, 1]^k times this is the twist
    action_scale: Array
    #: body geometry
    parts: BodyParts

    @property
    def body(self) -> str:
        """The body's name: robots with the same body and motion (an S-shape told its
        orientation and the plain one) share demonstrations and classical planners."""
        return self.name

    # -------------------------------------------------------------- group operations
    @abstractmethod
    def integrate(self, q: Array, v: Array) -> Array:
        """``q * exp(v)`` for body twists ``v: (..., twist_dim)``."""

    @abstractmethod
    def log(self, q0: Array, q1: Array) -> Array:
        """The body twist ``v`` with ``q0 * exp(v) = q1``."""

    @abstractmethod
    def rotations(self, q: Array) -> Array:
        """Body-to-world rotations ``(..., d, d)``."""

    def positions(self, q: Array) -> Array:
        """Positions of the body frame ``(..., d)``."""
        return np.asarray(q, np.float64)[..., : self.dim]

    @abstractmethod
    def sample_orientation(self, rng: np.random.Generator, n: int) -> Array:
        """``(n, config_dim - dim)`` orientation coordinates drawn uniformly."""

    def planner_defaults(self, planner: str) -> dict[str, float]:
        """Keyword defaults this robot gives a planner built by name (``make_planner``);
        rigid robots keep the planners' own."""
        return {}

    @property
    def euclidean(self) -> bool:
        """Whether configurations form a flat space: the distance is the Euclidean norm of
        their difference (positions only; an arm's joint space)."""
        return self.config_dim == self.dim

    # -------------------------------------------------------------- derived operations
    def distance(self, q0: Array, q1: Array) -> Array:
        """Geodesic distance ``||log(q0^-1 q1)||``."""
        return np.linalg.norm(self.log(q0, q1), axis=-1)

    def interpolate(self, q0: Array, q1: Array, s: Array | float) -> Array:
        """Points ``q0 * exp(s log(q0^-1 q1))`` on the geodesic; ``s`` broadcasts."""
        v = self.log(q0, q1)
        s = np.asarray(s, np.float64)
        return self.integrate(q0, v * s[..., None])

    def goal_vector(self, q: Array, goal: Array) -> Array:
        """The goal as seen from the robot: ``log(q^-1 goal)`` (body frame)."""
        return self.log(q, goal)

    #: width of :meth:`state_features` (0 for the rigid robots: their observation is in
    #: the body frame, so the goal vector and the points say where the robot is)
    state_feature_dim: int = 0

    def state_features(self, q: Array, goal: Array) -> Array:
        """What a policy is told about the robot beyond the goal vector, ``(..., state_feature_dim)``
        (an arm observes in its base frame and needs its own joint state)."""
        q = np.asarray(q, np.float64)
        return np.zeros(q.shape[:-1] + (0,))

    def clip(self, q: Array, low: Array, high: Array) -> Array:
        """Clip positions to the workspace bounds; orientation is free."""
        out = np.array(q, dtype=np.float64, copy=True)
        out[..., : self.dim] = np.clip(out[..., : self.dim], low, high)
        return out

    def sample_uniform(self, rng: np.random.Generator, n: int, low: Array, high: Array) -> Array:
        """``n`` configurations uniform in the bounds (collisions not checked)."""
        pos = rng.uniform(low, high, size=(n, self.dim))
        if self.config_dim == self.dim:
            return pos
        return np.concatenate([pos, self.sample_orientation(rng, n)], -1)

    def sample_free(
        self,
        world: CollisionWorld,
        rng: np.random.Generator,
        n: int,
        low: Array,
        high: Array,
        max_tries: int = 1000,
    ) -> Array:
        """``n`` collision-free configurations, drawn uniformly by rejection."""
        out = np.zeros((0, self.config_dim))
        for _ in range(max_tries):
            cand = self.sample_uniform(rng, max(2 * (n - len(out)), 16), low, high)
            free = cand[~self.collides(world, cand)]
            out = np.concatenate([out, free])[:n]
            if len(out) == n:
                return out
        raise RuntimeError("could not sample free configurations: is the workspace full?")

    def to_body_frame(self, q: Array, points: Array, normals: Array | None = None) -> tuple[Array, Array | None]:
        """Express world points ``(..., N, d)`` (and normals) in the frame of ``q: (..., cdim)``."""
        rot = self.rotations(q)
        p = np.einsum("...ji,...nj->...ni", rot, points - self.positions(q)[..., None, :])
        n = None if normals is None else np.einsum("...ji,...nj->...ni", rot, normals)
        return p, n

    # -------------------------------------------------------------- collision
    def world_parts(self, q: Array) -> tuple[Array, Array, Array, Array]:
        """World poses of the body parts: sphere centres ``(..., Ps, d)``, box centres
        ``(..., Pb, d)``, box rotations ``(..., Pb, d, d)``, box half sides ``(..., Pb, d)``."""
        rot = self.rotations(q)
        pos = self.positions(q)
        sc = np.einsum("...ij,pj->...pi", rot, self.parts.sphere_centers) + pos[..., None, :]
        bc = np.einsum("...ij,pj->...pi", rot, self.parts.box_centers) + pos[..., None, :]
        br = np.einsum("...ij,pjk->...pik", rot, self.parts.box_rotations)
        bh = np.broadcast_to(self.parts.box_halfs, bc.shape)
        return sc, bc, br, bh

    def collides(self, world: CollisionWorld, q: Array, radii: Array | None = None, halfs: Array | None = None) -> Bool:
        """Collision of configurations ``q: (*world.batch_shape, M, config_dim)`` or, for a
        single-scene world, any ``(..., config_dim)``. Returns the batch of booleans.

        ``radii: (..., Ps)`` and ``halfs: (..., Pb, d)`` (broadcasting against ``q``'s
        batch) replace the sizes of the sphere and box parts: grown bodies, see
        :meth:`grown_parts`."""
        q = np.asarray(q, np.float64)
        lead = q.shape[:-1]
        ps, pb = len(self.parts.sphere_radii), len(self.parts.box_halfs)
        rad = np.broadcast_to(self.parts.sphere_radii if radii is None else radii, lead + (ps,))
        hal = np.broadcast_to(self.parts.box_halfs if halfs is None else halfs, lead + (pb, self.dim))
        if world.batch_shape == ():
            q = q.reshape(-1, self.config_dim)
            rad, hal = rad.reshape(q.shape[0], ps), hal.reshape(q.shape[0], pb, self.dim)
        sc, bc, br, _ = self.world_parts(q)
        shape = q.shape[:-1]
        hit = np.zeros(shape, dtype=bool)
        if ps:
            flat = sc.reshape(shape[:-1] + (shape[-1] * ps, self.dim))
            hit |= world.spheres_collide(flat, rad.reshape(flat.shape[:-1])).reshape(shape + (ps,)).any(-1)
        if pb:
            d = self.dim
            hit |= (
                world.boxes_collide(
                    bc.reshape(shape[:-1] + (shape[-1] * pb, d)),
                    br.reshape(shape[:-1] + (shape[-1] * pb, d, d)),
                    hal.reshape(shape[:-1] + (shape[-1] * pb, d)),
                )
                .reshape(shape + (pb,))
                .any(-1)
            )
        return hit.reshape(lead) if world.batch_shape == () else hit

    def padded(self, margin: float) -> Robot:
        """A copy of this robot whose every part is grown by ``margin`` (sphere radii and box
        half sides): a path free for the copy keeps at least ``margin`` of clearance for this
        robot (used to plan demonstrations away from obstacles)."""
        if margin < 0:
            raise ValueError(f"margin must be >= 0, not {margin}")
        out = copy.copy(self)
        p = self.parts
        out.parts = BodyParts(
            p.sphere_centers, p.sphere_radii + margin, p.box_centers, p.box_rotations, p.box_halfs + margin
        )
        return out

    # -------------------------------------------------------------- certified motions
    def grown_parts(self, seg: Array, reach: float) -> tuple[Array, Array]:
        """Part sizes grown for motions by the body twist ``seg: (..., twist_dim)`` per
        sub-step: sphere radii ``(..., Ps)`` and box half sides ``(..., Pb, d)``.

        ``reach = 0.5``: the grown bodies at all the samples of a motion together contain
        everything the body sweeps (each body point lies within the growth of its own
        position at the nearest sample). ``reach = 1``: the grown body at sample 1 together
        with the plain body at sample 0 contain everything swept during the first
        sub-step. ``reach = 0``: the plain sizes. Proofs in ``docs/reference/design.md``.

        Robots that only translate: a sphere part of radius ``r`` moves on a straight line
        and becomes ``sqrt(r^2 + (reach |v|)^2)``; a box part grows along each of its axes
        by ``reach`` times the displacement's component along it. Free-flying 3D bodies
        (twists ``(v, w)``): a body point ``p`` moves at the constant body-frame speed
        ``|u(p)|``, ``u(p) = v + w x p``, its velocity direction turning at ``|w|``; within
        ``reach`` of a sample it stays within ``reach |u_i| + reach^2 / 2 |w| |u|`` along any
        unit axis ``i``, which is convex in ``p``, so the largest over a box is at a corner.
        """
        seg = np.asarray(seg, np.float64)
        parts = self.parts
        lead = seg.shape[:-1]
        if self.twist_dim == self.dim:  # translation only: straight lines
            v, w = seg, np.zeros(lead + (3,))
            radii = np.sqrt(parts.sphere_radii**2 + (reach * reach) * np.sum(v * v, axis=-1)[..., None])
        elif self.twist_dim == 6 and self.dim == 3:
            v, w = seg[..., :3], seg[..., 3:]
            radii = np.zeros(lead + (0,))
            if len(parts.sphere_radii):
                wn = np.linalg.norm(w, axis=-1)[..., None]
                u = v[..., None, :] + np.cross(w[..., None, :], parts.sphere_centers)  # (..., Ps, 3)
                radii = parts.sphere_radii + reach * (np.linalg.norm(u, axis=-1) + wn * parts.sphere_radii)
        else:
            raise NotImplementedError(f"no motion bound for {type(self).__name__}")
        if not len(parts.box_halfs):
            return radii, np.zeros(lead + (0, self.dim))
        pb, d = parts.box_halfs.shape
        local = (seg @ self._corner_velocity).reshape(lead + (pb, -1, d))  # u at the corners, part axes
        speed = np.sqrt(np.sum(local * local, axis=-1))  # (..., Pb, 2^d): |u|, rotation-invariant
        wn = np.sqrt(np.sum(w * w, axis=-1))[..., None, None]
        growth = reach * np.abs(local) + ((0.5 * reach * reach) * wn * speed)[..., None]
        return radii, parts.box_halfs + np.max(growth, axis=-2)

    @property
    def _corner_velocity(self) -> Array:
        """``(twist_dim, Pb * 2^d * d)``: the twist's linear map to the velocities ``v + w x
        p`` of the box parts' corners ``p``, in each part's own axes (computed once per
        body: a ``padded`` copy, which has other corners, computes its own)."""
        cached = self.__dict__.get("_corner_velocity_cache")
        if cached is None or cached[0] is not self.parts:
            p = self.parts
            signs = np.array(np.meshgrid(*[[-1.0, 1.0]] * self.dim, indexing="ij")).reshape(self.dim, -1).T
            corners = p.box_centers[:, None, :] + np.einsum(
                "pij,pkj->pki", p.box_rotations, signs * p.box_halfs[:, None, :]
            )
            basis = np.eye(self.twist_dim)
            rows = []
            for e in basis:  # the velocity of each corner for a unit twist along e
                if self.twist_dim == self.dim:
                    u = np.broadcast_to(e, corners.shape)
                else:
                    u = e[:3] + np.cross(e[3:], corners)
                rows.append(np.einsum("pij,pki->pkj", p.box_rotations, u).reshape(-1))
            cached = self.__dict__["_corner_velocity_cache"] = (p, np.array(rows))
        return cached[1]

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
        """Certify motions ``q0 exp(s twist)`` in ``n`` sub-steps each: see
        :func:`pointplan.robots.motion.check_motions`."""
        return check_motions(self, world, q0, twist, n, low, high, fallback)

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
        """``pointplan.planners.base.march`` in one compiled call, where a robot has one for
        this world: ``(nodes, reached, checks)``; ``None`` (the default): march in numpy."""
        return None

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
        """Bi-RRT's shortcutting in one compiled call, where a robot has one for this world
        (``u``: two uniform numbers per iteration): ``(path, checks)``; ``None`` (the
        default): shortcut in Python."""
        return None

    def nearest(self, nodes: Array, q: Array) -> tuple[int, Array]:
        """The index of the row of ``nodes (n, config_dim)`` nearest to ``q`` (geodesic
        distance; the first of equals) and the twist from it to ``q``."""
        v = self.log(nodes, np.asarray(q, np.float64)[None])
        i = int(np.argmin(np.einsum("ij,ij->i", v, v)))
        return i, v[i]

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"
