"""Observers: what the robot sees of the obstacles, in its own frame.

An observer is bound to the ``E`` scenes of a (vector) environment; ``set_scene`` swaps one
slot when that environment resets, and ``observe`` answers for all ``E`` configurations at
once.
"""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

from ..robots.base import Robot
from ..scenes.scene import Scene

Array = NDArray[np.float64]


class Observer(ABC):
    """Base class. Subclasses define ``name``, ``space`` and ``observe``.

    Capabilities the rollout engine (:mod:`pointplan.planners.rollout`) chooses its
    stepper by: ``one_robot``, the observer has ``observe_one(q, u=...)`` and
    ``draws_one()``, which give the observation ``observe`` would draw for one robot in
    its one bound static scene from a block of uniform numbers; ``compiled_points``, that
    observation is a uniform subset of ``points_one()`` in the robot's frame, drawn as
    :class:`PointSetObserver` draws it (the compiled rollout reproduces it).

    ``storage_dtype``: the dtype that holds many observations without loss (replay
    buffers, demonstrations); ``observe`` itself always returns float32.

    ``stochastic``: ``observe`` draws from its generator (a random subset of points, random
    rays), so observing again gives a fresh sample; ``False`` where the same
    configurations in the same scenes always give the same observations and the generator
    is left untouched (the occupancy image), so many observations need computing once."""

    name: str
    one_robot: bool = False
    compiled_points: bool = False
    storage_dtype: type = np.float32
    stochastic: bool = True

    def __init__(self, robot: Robot) -> None:
        self.robot = robot
        self.scenes: list[Scene] = []

    def bind(self, scenes: list[Scene]) -> None:
        """Prepare for a batch of scenes (one per environment)."""
        self.scenes = list(scenes)
        for i, s in enumerate(scenes):
            self.set_scene(i, s)

    def set_scene(self, i: int, scene: Scene) -> None:
        """Replace the scene of environment ``i``."""
        if i == len(self.scenes):
            self.scenes.append(scene)
        self.scenes[i] = scene

    @property
    @abstractmethod
    def space(self) -> spaces.Box:
        """The observation space of one environment."""

    @abstractmethod
    def observe(self, q: Array, rng: np.random.Generator, t: NDArray[np.int64] | None = None) -> NDArray[np.float32]:
        """Observations of configurations ``q: (E, config_dim)``, one per bound scene, at
        time steps ``t: (E,)`` (only moving obstacles care; ``None`` means time 0)."""


def random_subsets(counts: NDArray[np.int64], pmax: int, n: int, rng: np.random.Generator) -> NDArray[np.int64]:
    """Indices ``(E, n)`` into sets of ``counts`` valid items (of ``pmax`` slots): a random
    subset without replacement, padded with random duplicates where a set has fewer than
    ``n`` items (index 0 where a set is empty)."""
    e = len(counts)
    keys = rng.random((e, pmax))
    keys[np.arange(pmax)[None, :] >= counts[:, None]] = np.inf  # invalid slots sort last
    idx = np.argsort(keys, axis=1)[:, :n]
    if idx.shape[1] < n:
        idx = np.concatenate([idx, np.zeros((e, n - idx.shape[1]), dtype=idx.dtype)], 1)
    short = np.arange(n)[None, :] >= counts[:, None]
    dup = (rng.random((e, n)) * np.maximum(counts, 1)[:, None]).astype(np.int64)
    return np.where(short, dup, idx)


class PointSetObserver(Observer):
    """Shared machinery: a fixed point set per scene, resized to ``n_points`` each call by a
    random subset (or padded by duplicates), expressed in the robot frame."""

    with_normals: bool = False
    one_robot = True
    compiled_points = True

    def __init__(self, robot: Robot, n_points: int = 64, spacing: float = 0.015) -> None:
        super().__init__(robot)
        if n_points < 1:
            raise ValueError("n_points must be at least 1")
        self.n_points = int(n_points)
        self.spacing = float(spacing)
        self._pts: list[Array] = []
        self._nrm: list[Array] = []
        self._stacked: tuple[Array, Array, NDArray[np.int64]] | None = None

    def move(self, pw: Array, nw: Array, t: NDArray[np.int64] | None) -> tuple[Array, Array]:
        """Hook for moving obstacles: selected world points at time ``t`` (static: as is)."""
        return pw, nw

    @abstractmethod
    def points_of(self, scene: Scene) -> tuple[Array, Array]:
        """World points ``(P, d)`` and normals ``(P, d)`` for a scene."""

    def set_scene(self, i: int, scene: Scene) -> None:
        super().set_scene(i, scene)
        cache = scene.__dict__.setdefault("_observer_cache", {})
        key = (type(self).__name__, self.spacing)
        if key not in cache:
            cache[key] = self.points_of(scene)
        p, n = cache[key]
        self._stacked = None
        if i == len(self._pts):
            self._pts.append(p)
            self._nrm.append(n)
        else:
            self._pts[i], self._nrm[i] = p, n

    @property
    def features(self) -> int:
        return self.robot.dim * (2 if self.with_normals else 1)

    @property
    def space(self) -> spaces.Box:
        return spaces.Box(-np.inf, np.inf, shape=(self.n_points, self.features), dtype=np.float32)

    def select(self, rng: np.random.Generator) -> tuple[Array, Array]:
        """World points and normals ``(E, N, d)``: a random subset of each scene's set."""
        e, n, d = len(self._pts), self.n_points, self.robot.dim
        if self._stacked is None:
            counts = np.array([len(p) for p in self._pts], dtype=np.int64)
            pmax = max(int(counts.max()) if e else 1, 1)
            sp = np.zeros((e, pmax, d))
            sn = np.zeros((e, pmax, d))
            for i in range(e):  # once per scene change, not per step
                sp[i, : counts[i]] = self._pts[i]
                sn[i, : counts[i]] = self._nrm[i]
            self._stacked = (sp, sn, counts)
        sp, sn, counts = self._stacked
        idx = random_subsets(counts, sp.shape[1], n, rng)
        self._last_idx = idx
        return (
            np.take_along_axis(sp, idx[..., None], axis=1),
            np.take_along_axis(sn, idx[..., None], axis=1),
        )

    def points_one(self) -> tuple[Array, Array]:
        """World points and normals of the single bound scene (what :meth:`observe_one`
        draws its subset from)."""
        return self._pts[0], self._nrm[0]

    def draws_one(self) -> int:
        """How many uniform numbers one observation of the single bound scene draws
        (:meth:`observe_one` takes them as ``u``)."""
        return max(len(self._pts[0]), 1) + self.n_points

    def observe_one(
        self, q: Array, rng: np.random.Generator | None = None, u: Array | None = None
    ) -> NDArray[np.float32]:
        """``observe(q[None], rng)[0]`` for an observer bound to one static scene, without
        the batch machinery (a planner's batch-1 rollout calls this every step): the same
        random draws, the same values. ``u`` may pass the ``draws_one()`` uniform numbers
        instead of ``rng`` (drawn ahead in one block: the same stream)."""
        pts, nrm = self._pts[0], self._nrm[0]
        count, n = len(pts), self.n_points
        m = max(count, 1)
        if u is None:
            assert rng is not None
            u = rng.random(m + n)  # random_subsets' draws: keys for one set, then duplicates
        if count == 0:
            return np.zeros((n, self.features), np.float32)
        idx = np.argsort(u[:m])[:n]
        if count < n:
            idx = np.concatenate([idx, (u[m + count : m + n] * count).astype(np.int64)])
        q = np.asarray(q, np.float64)
        p, nb = self.robot.to_body_frame(q[None], pts[idx][None], nrm[idx][None] if self.with_normals else None)
        if self.with_normals:
            assert nb is not None
            return np.concatenate([p[0], nb[0]], -1).astype(np.float32)
        return p[0].astype(np.float32)

    def observe(self, q: Array, rng: np.random.Generator, t: NDArray[np.int64] | None = None) -> NDArray[np.float32]:
        pw, nw = self.select(rng)
        pw, nw = self.move(pw, nw, t)
        p, n = self.robot.to_body_frame(q, pw, nw)
        assert self._stacked is not None
        empty = self._stacked[2] == 0
        if empty.any():  # a scene with nothing to see: all-zero features
            p[empty] = 0.0
            if n is not None:
                n[empty] = 0.0
        if self.with_normals:
            assert n is not None
            return np.concatenate([p, n], -1).astype(np.float32)
        return p.astype(np.float32)
