"""The "local" observation: a panoramic depth camera simulated by ray casting."""

from __future__ import annotations

import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

from ..geometry.collision import CollisionWorld
from ..geometry.sampling import fibonacci_sphere
from ..geometry.shapes import Box, Shape
from ..robots.base import Robot
from ..scenes.scene import Scene
from .base import Array, Observer, random_subsets

#: thickness of the wall slabs that close the workspace for ray casting
WALL_THICKNESS = 0.05


def wall_slabs(low: Array, high: Array, thickness: float = WALL_THICKNESS) -> list[Box]:
    """Six slabs just outside the bounds, so that every ray leaving the workspace hits."""
    low, high = np.asarray(low, np.float64), np.asarray(high, np.float64)
    mid, ext = (low + high) / 2, high - low + 2 * thickness
    out = []
    for axis in range(3):
        for side, face in ((-1, low[axis]), (1, high[axis])):
            c = mid.copy()
            c[axis] = face + side * thickness / 2
            size = ext.copy()
            size[axis] = thickness
            out.append(Box(c, size))
    return out


def ray_origins(robot: Robot) -> Array:
    """Body-frame points the rays start from: the centre for balls, the centreline corners
    of the S-shape (6 points along its body)."""
    if robot.body == "sshape":
        from ..robots.sshape import S_CORNERS

        return S_CORNERS.copy()
    return np.zeros((1, robot.dim))


def _rotate(rot: Array, v: Array) -> Array:
    """``rot (E, 3, 3)`` applied to ``v (R, 3)``: ``(E, R, 3)``, summed in a fixed order
    (``einsum`` sums in an order of its own), the order of the compiled rollout's ray
    casting (``planners/_rigid_kernels.py``): the same rays to the last bit, so both thin
    the same hits (a wall lies on a cell boundary of the thinning grid, where the last bit
    of a hit decides its cell)."""
    r = rot[:, None, :, :]
    return r[..., 0] * v[None, :, 0, None] + r[..., 1] * v[None, :, 1, None] + r[..., 2] * v[None, :, 2, None]


def thin_grid(points: Array, normals: Array, valid: NDArray[np.bool_], spacing: float) -> NDArray[np.bool_]:
    """Keep one point per cell of a grid of ``spacing`` over (point, normal) space (cells
    centred on multiples of ``spacing``), per environment: ``points, normals (E, R, 3)``, ``valid (E, R)`` -> kept ``(E, R)``."""
    if spacing < 0.01:
        raise ValueError("thinning spacing below 0.01 is not supported (cell keys are 8-bit)")
    e, r, _ = points.shape
    # cells centred on multiples of the spacing: the walls (at multiples of it in the
    # project's scenes) and the zero components of axis-aligned normals then lie at a
    # cell's centre, not on a boundary where the last bit of a hit decides its cell
    cells = np.floor(np.concatenate([points, normals], -1) / spacing + 0.5).astype(np.int64)
    # one int64 key per (environment, cell): 6 cell coordinates of 8 bits each, env above
    cells = np.clip(cells + 128, 0, 255)
    key = np.repeat(np.arange(e, dtype=np.int64)[:, None], r, 1) << np.int64(48)
    for k in range(6):
        key |= cells[..., k] << np.int64(8 * k)
    idx = np.flatnonzero(valid.reshape(-1))
    kept = np.zeros(e * r, dtype=bool)
    if len(idx):
        _, first = np.unique(key.reshape(-1)[idx], return_index=True)
        kept[idx[first]] = True
    return kept.reshape(e, r)


class LocalRays(Observer):
    """What a panoramic depth camera on the robot sees: rays in ``n_rays`` directions on a
    Fibonacci sphere (split evenly among the origins: the sphere's centre, or six points
    along the S-shape), first hits within ``max_range``, thinned on a ``spacing`` grid over
    (point, normal), resized to ``n_points`` (random subset, or duplicates), points and
    normals in the robot frame. Wall slabs just outside the workspace close it, so every
    ray has something to hit. Hits are not occluded by the robot's own body; rays from body
    points outside the workspace are dropped."""

    name = "local"
    with_normals = True
    #: keep the ``n_points`` hits nearest to the body instead of a random subset
    nearest = False
    one_robot = True

    def __init__(
        self, robot: Robot, n_points: int = 64, n_rays: int = 256, max_range: float = 0.7, spacing: float = 0.06
    ) -> None:
        if robot.dim != 3:
            raise ValueError("the ray-cast observation is implemented for 3D robots")
        super().__init__(robot)
        self.n_points = int(n_points)
        self.max_range = float(max_range)
        self.spacing = float(spacing)
        self.origins = ray_origins(robot)
        per = max(1, n_rays // len(self.origins))
        dirs = fibonacci_sphere(per)
        self.body_origins = np.repeat(self.origins, per, 0)  # (R, 3)
        self.body_dirs = np.tile(dirs, (len(self.origins), 1))  # (R, 3)
        self._world: CollisionWorld | None = None
        self._static_worlds: dict[int, CollisionWorld] = {}

    @property
    def features(self) -> int:
        return 6

    @property
    def space(self) -> spaces.Box:
        return spaces.Box(-np.inf, np.inf, shape=(self.n_points, 6), dtype=np.float32)

    def set_scene(self, i: int, scene: Scene) -> None:
        super().set_scene(i, scene)
        self._world = None

    def ray_world(self, scene: Scene, t: int = 0) -> CollisionWorld:
        """The scene's obstacles at time ``t`` plus the wall slabs."""
        cache = scene.__dict__.setdefault("_ray_worlds", {})
        key = int(t) % getattr(scene, "period", 1) if scene.dynamic else 0
        w = cache.get(key)
        if w is None:
            obstacles: list[Shape] = list(scene.obstacles_at(key)) + list(wall_slabs(scene.low, scene.high))
            w = cache[key] = CollisionWorld.from_shapes(obstacles, 3)
        return w

    def stacked_world(self, t: NDArray[np.int64] | None) -> CollisionWorld:
        if not any(s.dynamic for s in self.scenes) or t is None:
            if self._world is None:
                self._world = CollisionWorld.stack([self.ray_world(s) for s in self.scenes])
            return self._world
        return CollisionWorld.stack([self.ray_world(s, int(ti)) for s, ti in zip(self.scenes, t)])

    def cast(self, q: Array, t: NDArray[np.int64] | None = None) -> tuple[Array, Array, NDArray[np.bool_]]:
        """World hit points and normals ``(E, R, 3)`` and which rays hit within range."""
        from ..geometry.raycast import cast_rays

        rot = self.robot.rotations(q)
        pos = self.robot.positions(q)
        origins = _rotate(rot, self.body_origins) + pos[:, None, :]
        dirs = _rotate(rot, self.body_dirs)
        self._origins_world = origins
        hits = cast_rays(self.stacked_world(t), origins, dirs, self.max_range)
        ok = hits.hit & (hits.distance <= self.max_range)
        # a ray whose origin (a point of the body) pokes out of the workspace sees nothing:
        # it would start inside a wall slab
        low = np.stack([s.low for s in self.scenes])[:, None]
        high = np.stack([s.high for s in self.scenes])[:, None]
        ok &= np.all((origins > low) & (origins < high), axis=-1)
        return np.where(ok[..., None], hits.points, 0.0), np.where(ok[..., None], hits.normals, 0.0), ok

    def draws_one(self) -> int:
        """How many uniform numbers one observation of the single bound static scene draws
        (the subset's keys, one per ray, then the duplicates' draws)."""
        return len(self.body_origins) + self.n_points

    def observe_one(
        self, q: Array, rng: np.random.Generator | None = None, u: Array | None = None
    ) -> NDArray[np.float32]:
        """``observe(q[None], rng)[0]`` for an observer bound to one static scene, from the
        ``draws_one()`` uniform numbers ``u`` (or drawn from ``rng``): the same rays, the
        same subset, the same values."""
        n_rays, n = len(self.body_origins), self.n_points
        if u is None:
            assert rng is not None
            u = rng.random(n_rays + n)
        q = np.asarray(q, np.float64)[None]
        pw, nw, ok = self.cast(q)
        kept = np.flatnonzero(thin_grid(pw, nw, ok, self.spacing)[0])  # in ray order
        count = len(kept)
        if count == 0:
            return np.zeros((n, 6), np.float32)
        pos = np.argsort(u[:count])[:n]
        if count < n:
            pos = np.concatenate([pos, (u[n_rays + count : n_rays + n] * count).astype(np.int64)])
        sel = kept[pos]
        pb, nb = self.robot.to_body_frame(q, pw[:, sel], nw[:, sel])
        assert nb is not None
        return np.concatenate([pb[0], nb[0]], -1).astype(np.float32)

    def observe(self, q: Array, rng: np.random.Generator, t: NDArray[np.int64] | None = None) -> NDArray[np.float32]:
        q = np.asarray(q, np.float64)
        pw, nw, ok = self.cast(q, t)
        kept = thin_grid(pw, nw, ok, self.spacing)
        counts = kept.sum(1)
        if self.nearest:
            # the kept rays ordered by how far from the body they hit, the nearest first
            d = np.linalg.norm(pw - self._origins_world, axis=-1)
            order = np.argsort(np.where(kept, d, np.inf), axis=1, kind="stable")
            idx = np.take_along_axis(order, nearest_subsets(counts, self.n_points, rng), axis=1)
        else:
            # move the kept rays to the front, then draw N of them
            order = np.argsort(~kept, axis=1, kind="stable")
            idx = np.take_along_axis(order, random_subsets(counts, kept.shape[1], self.n_points, rng), axis=1)
        p = np.take_along_axis(pw, idx[..., None], axis=1)
        n = np.take_along_axis(nw, idx[..., None], axis=1)
        pb, nb = self.robot.to_body_frame(q, p, n)
        assert nb is not None
        out = np.concatenate([pb, nb], -1)
        out[counts == 0] = 0.0
        return out.astype(np.float32)


def nearest_subsets(counts: NDArray[np.int64], n: int, rng: np.random.Generator) -> NDArray[np.int64]:
    """Indices ``(E, n)`` into sets sorted nearest first: the first ``n`` of each, padded with
    random duplicates of its items where a set has fewer than ``n`` (index 0 if empty)."""
    e = len(counts)
    idx = np.broadcast_to(np.arange(n), (e, n))
    dup = (rng.random((e, n)) * np.maximum(counts, 1)[:, None]).astype(np.int64)
    return np.where(idx >= counts[:, None], dup, idx)


class NearestRays(LocalRays):
    """:class:`LocalRays` keeping the ``n_points`` hits nearest to the robot's body (by ray
    length) instead of a random subset, so that an obstacle the robot touches is always in
    the observation (a deviation from the paper; ``docs/notebook/sshape.md``)."""

    name = "local-near"
    nearest = True
    one_robot = False  # (its subset draws differ; it steps in lockstep)


class WideRays(LocalRays):
    """:class:`LocalRays` with four times the rays (1,024), a range of 2.0 (across the
    whole workspace, so a ray through an opening hits what lies behind it) and 128 points.
    Made for Slot: with the paper's ``local`` settings 2.8 of its 252 rays cross the
    opening on average from in front of the wall, none for 26% of those poses, and a probe
    locates the opening from them barely better than with the opening closed; with these,
    13 rays cross it and the probe gains as much from the opening as from ``global``'s
    points (a deviation from the
    paper; ``docs/results/slot.md``, "Can the observations show the opening?")."""

    name = "local-wide"

    def __init__(
        self, robot: Robot, n_points: int = 128, n_rays: int = 1024, max_range: float = 2.0, spacing: float = 0.06
    ) -> None:
        super().__init__(robot, n_points=n_points, n_rays=n_rays, max_range=max_range, spacing=spacing)
