"""Perturbed point observations: how robust is a policy to what it sees?

:class:`PerturbedPoints` wraps a point-set observer (``surface``, ``surface-normals``,
``interior``) and changes what it hands the policy:

- ``noise``: Gaussian noise of standard deviation ``noise`` (metres) on the positions of
  the observed points, fresh at every observation (normals are left as they are);
- ``drop``: that fraction of the scene's points removed (the same ones for the whole
  episode) before each observation's random subset is drawn;
- ``viewpoint``: only the points visible from one viewpoint: a fixed position, or
  ``"start"`` (where the robot is at its first observation of the scene). A point is
  visible when the segment from the viewpoint to it crosses no obstacle
  (:func:`visible_from`, batched over points and boxes);
- ``subset="fps"``: the observed subset by farthest-point sampling (from a random first
  point, so each observation still differs) instead of a uniform random subset.

The randomness (noise, dropped points) comes from generators seeded by ``seed`` and the
scene's name, not from the observation stream: with every perturbation off, the wrapped
observer returns exactly what the plain one does.

``PolicyPlanner(..., observer_wrapper=perturbation(noise=0.005))`` plans with it
(the batch-1 ``plan`` path; 2D and 3D point sets, static scenes).
"""

from __future__ import annotations

import zlib
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..geometry.shapes import Box
from ..scenes.scene import Scene
from .base import Array, Observer, PointSetObserver


def visible_from(scene: Scene, points: Array, viewpoint: Array, eps: float = 1e-7) -> NDArray[np.bool_]:
    """Which ``points (P, d)`` can be seen from ``viewpoint (d,)``: the open segment from
    the viewpoint to the point meets no box obstacle (each box shrunk by ``eps``, so a
    point on a face turned towards the viewpoint is seen and one on a face turned away is
    not). Slab test, batched over points and boxes."""
    points = np.asarray(points, np.float64)
    v = np.asarray(viewpoint, np.float64)
    boxes = [b for b in scene.obstacles if isinstance(b, Box)]
    if len(boxes) != len(scene.obstacles):
        raise ValueError("visible_from handles box obstacles only")
    if not boxes or len(points) == 0:
        return np.ones(len(points), bool)
    c = np.stack([b.center for b in boxes])  # (B, d)
    h = np.stack([b.half for b in boxes]) - eps
    r = np.stack([b.rotation for b in boxes])  # (B, d, d): box frame -> world
    # viewpoint and points in each box's frame
    v_loc = np.einsum("bji,bj->bi", r, v[None] - c)  # (B, d)
    p_loc = np.einsum("bji,pbj->pbi", r, points[:, None, :] - c[None])  # (P, B, d)
    d = p_loc - v_loc[None]
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (-h[None] - v_loc[None]) / d
        t2 = (h[None] - v_loc[None]) / d
    lo_t = np.minimum(t1, t2)
    hi_t = np.maximum(t1, t2)
    parallel = d == 0.0  # the segment runs along a slab: inside it or never
    inside = np.abs(v_loc)[None] < h[None]
    lo_t = np.where(parallel, np.where(inside, -np.inf, np.inf), lo_t)
    hi_t = np.where(parallel, np.where(inside, np.inf, -np.inf), hi_t)
    enter = lo_t.max(-1)
    leave = hi_t.min(-1)
    hit = (leave > np.maximum(enter, 0.0)) & (enter < 1.0)  # (P, B)
    return ~hit.any(-1)


def farthest_point_subset(points: Array, n: int, first: int) -> NDArray[np.int64]:
    """``n`` indices into ``points``: ``first``, then each time the point farthest from
    those chosen (all of them, then duplicates from the start, when there are fewer)."""
    count = len(points)
    if count <= n:
        return np.resize(np.arange(count), n) if count else np.zeros(n, np.int64)
    idx = np.empty(n, np.int64)
    idx[0] = first
    dist = np.sum((points - points[first]) ** 2, -1)
    for k in range(1, n):
        j = int(np.argmax(dist))
        idx[k] = j
        np.minimum(dist, np.sum((points - points[j]) ** 2, -1), out=dist)
    return idx


class PerturbedPoints(PointSetObserver):
    """A point-set observer whose observations are perturbed (see the module)."""

    compiled_points = False  # its own observe_one: not a plain subset of the points

    def __init__(
        self,
        base: PointSetObserver,
        noise: float = 0.0,
        drop: float = 0.0,
        viewpoint: str | Array | None = None,
        subset: str = "random",
        seed: int = 0,
    ) -> None:
        if not isinstance(base, PointSetObserver):
            raise TypeError("PerturbedPoints wraps a point-set observer")
        if not 0.0 <= drop < 1.0:
            raise ValueError("drop is a fraction in [0, 1)")
        if subset not in ("random", "fps"):
            raise ValueError("subset is 'random' or 'fps'")
        if isinstance(viewpoint, str) and viewpoint != "start":
            raise ValueError("viewpoint is a position or 'start'")
        super().__init__(base.robot, base.n_points, base.spacing)
        self.base = base
        self.name = base.name
        self.with_normals = base.with_normals
        self.noise = float(noise)
        self.drop = float(drop)
        self.viewpoint = (
            viewpoint if viewpoint is None or isinstance(viewpoint, str) else np.asarray(viewpoint, np.float64)
        )
        self.subset = subset
        self.seed = int(seed)
        self._noise_rng = np.random.default_rng(self.seed)
        self._pending_start = False

    def points_of(self, scene: Scene) -> tuple[Array, Array]:
        return self.base.points_of(scene)

    def _scene_seed(self, scene: Scene, stream: int) -> np.random.SeedSequence:
        return np.random.SeedSequence([self.seed, zlib.crc32(scene.name.encode()), stream])

    def set_scene(self, i: int, scene: Scene) -> None:
        Observer.set_scene(self, i, scene)
        self.base.set_scene(i, scene)  # the plain point set (cached on the scene)
        p, n = self.base._pts[i], self.base._nrm[i]
        keep = np.ones(len(p), bool)
        if self.drop > 0.0:
            gone = np.random.default_rng(self._scene_seed(scene, 1)).permutation(len(p))[
                : int(round(self.drop * len(p)))
            ]
            keep[gone] = False
        if self.viewpoint is not None and not isinstance(self.viewpoint, str):
            keep &= visible_from(scene, p, self.viewpoint)
        self._pending_start = isinstance(self.viewpoint, str)
        self._noise_rng = np.random.default_rng(self._scene_seed(scene, 2))
        self._stacked = None
        if i == len(self._pts):
            self._pts.append(p[keep])
            self._nrm.append(n[keep])
        else:
            self._pts[i], self._nrm[i] = p[keep], n[keep]

    def _see_from_start(self, q: Array) -> None:
        """Keep the points visible from the robot's first observed position."""
        self._pending_start = False
        pts = self._pts[0]
        keep = visible_from(self.scenes[0], pts, np.asarray(q, np.float64)[: self.robot.dim])
        self._pts[0], self._nrm[0] = pts[keep], self._nrm[0][keep]
        self._stacked = None

    def observe_one(
        self, q: Array, rng: np.random.Generator | None = None, u: Array | None = None
    ) -> NDArray[np.float32]:
        if self._pending_start:
            self._see_from_start(q)
        if self.subset == "fps" and len(self._pts[0]) > self.n_points:
            pts, nrm = self._pts[0], self._nrm[0]
            if u is None:
                assert rng is not None
                u = rng.random(len(pts) + self.n_points)
            idx = farthest_point_subset(pts, self.n_points, int(np.argmin(u[: len(pts)])))
            pb, nb = self.robot.to_body_frame(
                np.asarray(q, np.float64)[None], pts[idx][None], nrm[idx][None] if self.with_normals else None
            )
            obs = np.concatenate([pb[0], nb[0]], -1) if nb is not None else pb[0]
            obs = obs.astype(np.float32)
        else:
            obs = super().observe_one(q, rng, u)
        if self.noise > 0.0:  # isotropic: the same in the body frame as in the world frame
            d = self.robot.dim
            obs[:, :d] += (self._noise_rng.standard_normal((len(obs), d)) * self.noise).astype(np.float32)
        return obs

    def select(self, rng: np.random.Generator) -> tuple[Array, Array]:
        if self._pending_start or self.subset != "random":
            raise NotImplementedError(
                "viewpoint='start' and subset='fps' work with PolicyPlanner.plan (observe_one) only"
            )
        pw, nw = super().select(rng)
        if self.noise > 0.0:
            pw = pw + self._noise_rng.standard_normal(pw.shape) * self.noise
        return pw, nw


def perturbation(**kwargs: Any) -> Callable[[PointSetObserver], PerturbedPoints]:
    """An ``observer_wrapper`` for :class:`~pointplan.planners.policy.PolicyPlanner`:
    ``perturbation(noise=0.005, drop=0.25, viewpoint="start", subset="fps", seed=0)``."""

    def wrap(observer: PointSetObserver) -> PerturbedPoints:
        return PerturbedPoints(observer, **kwargs)

    return wrap


__all__ = ["PerturbedPoints", "farthest_point_subset", "perturbation", "visible_from"]
