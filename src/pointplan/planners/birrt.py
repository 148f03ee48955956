"""Bi-directional RRT: RRT-Connect (Kuffner & LaValle 2000) with path shortcutting.

Two trees grow from the start and the goal. Each iteration one tree *extends* one step
toward a uniform sample; the other tree then *connects*: it marches step by step toward the
new node until it reaches it (a path) or is blocked. The trees swap roles every iteration.

Every edge is at most ``step`` long in the robot's geodesic distance and is certified by
the robot's motion validator in sub-steps of at most ``resolution``
(:mod:`pointplan.robots.motion`: no configuration along it touches an obstacle). A connect
checks all its steps in one validator call. The solution is then shortcut: two points drawn uniformly by
arc length along the path are joined by a geodesic when that is free and shorter.

Only the :class:`~pointplan.robots.base.Robot` API is used, so any robot works.

The extend targets are uniform in the bounds unless a ``sampler`` is given: called once per
problem (``sampler(problem)``, inside the timed query), it returns ``draw(rng, n)`` giving
``n`` targets from the query's own generator (the learned sampler of
:mod:`pointplan.planners.learned_sampling` mixes a network's samples with uniform ones).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..robots.base import Robot
from ..robots.motion import segments_free
from ..scenes.scene import Problem
from .base import Array, PlanResult, check_free, march

_SAMPLE_BLOCK = 256

#: ``draw(rng, n) -> (n, config_dim)``: targets for the extend steps
DrawSamples = Callable[[np.random.Generator, int], Array]
#: ``sampler(problem) -> draw``, called once per query (it may prepare per-problem state)
SamplerFactory = Callable[[Problem], DrawSamples]


#: trees smaller than this find nearest nodes by a scan; larger ones index older nodes
_KD_MIN = 512
#: candidates taken from the index for robots with orientation (re-ranked exactly)
_KD_CANDIDATES = 16


def _embed(robot: Robot, q: Array) -> Array:
    """Points whose Euclidean distance stands in for the geodesic one: the position, and
    for oriented robots the unit quaternion (w >= 0) times 2 (its chord is about half the
    rotation angle)."""
    q = np.asarray(q, np.float64)
    if robot.euclidean:
        return q
    quat = q[..., robot.dim :]
    quat = np.where(quat[..., -1:] < 0, -quat, quat)
    return np.concatenate([q[..., : robot.dim], 2.0 * quat], -1)


class _Tree:
    """Nodes and parents in arrays that double when full, with a nearest-node index.

    Nearest nodes: for robots without orientation the geodesic distance is Euclidean, and a
    KD-tree over the older nodes plus a scan of the newest ones is exact. For oriented
    robots the KD-tree (over positions and quaternions) proposes candidates that are
    re-ranked by the true distance: nearly always the true nearest node, at a cost that
    grows like log(n) instead of n (a plain scan made 50,000-node searches quadratic)."""

    def __init__(self, root: Array, capacity: int = 256) -> None:
        self.nodes = np.empty((capacity, root.shape[0]))
        self.parent = np.empty(capacity, dtype=np.int64)
        self.nodes[0] = root
        self.parent[0] = -1
        self.n = 1
        self._kd = None
        self._kd_n = 0  # nodes [0, _kd_n) are in the index

    def add(self, configs: Array, first_parent: int) -> int:
        """Append a chain ``first_parent -> configs[0] -> configs[1] -> ...``; returns the
        index of the last added node."""
        k = len(configs)
        if self.n + k > len(self.nodes):
            cap = max(2 * len(self.nodes), self.n + k)
            nodes = np.empty((cap, self.nodes.shape[1]))
            nodes[: self.n] = self.nodes[: self.n]
            parent = np.empty(cap, dtype=np.int64)
            parent[: self.n] = self.parent[: self.n]
            self.nodes, self.parent = nodes, parent
        self.nodes[self.n : self.n + k] = configs
        self.parent[self.n] = first_parent
        self.parent[self.n + 1 : self.n + k] = np.arange(self.n, self.n + k - 1)
        self.n += k
        return self.n - 1

    def nearest(self, robot: Robot, q: Array) -> tuple[int, Array]:
        """Index of the node nearest to ``q`` and the twist from it to ``q``."""
        if self.n < _KD_MIN:
            return robot.nearest(self.nodes[: self.n], q)
        if self.n >= 2 * self._kd_n:  # rebuild when the tree has doubled
            from scipy.spatial import cKDTree

            self._kd = cKDTree(_embed(robot, self.nodes[: self.n]))
            self._kd_n = self.n
        exact = robot.euclidean
        assert self._kd is not None
        _, cand = self._kd.query(_embed(robot, q), k=1 if exact else _KD_CANDIDATES)
        idx = np.concatenate([np.atleast_1d(cand), np.arange(self._kd_n, self.n)])
        j, v = robot.nearest(self.nodes[idx], q)
        return int(idx[j]), v

    def branch(self, i: int) -> Array:
        """Configurations from the root to node ``i``."""
        idx = []
        while i >= 0:
            idx.append(i)
            i = int(self.parent[i])
        return self.nodes[idx[::-1]]

    def export(self) -> tuple[Array, NDArray[np.int64]]:
        return self.nodes[: self.n].copy(), self.parent[: self.n].copy()


def _probe_fractions(k: int) -> Array:
    """``k`` fractions spread inside (0, 1): where a shortcut's stretch is probed."""
    return np.arange(1, k + 1) / (k + 1)


class _Replay:
    """Uniform draws taken ahead (``uniform(low, high, 2)`` from them as a generator gives
    it), so that the Python shortcut loop and the compiled one read the same numbers."""

    def __init__(self, u: Array) -> None:
        self.u, self.k = u, 0

    def uniform(self, low: float, high: float, size: int) -> Array:
        out = low + (high - low) * self.u[self.k : self.k + size]
        self.k += size
        return out


class BiRRT:
    """RRT-Connect with shortcutting.

    ``max_nodes`` bounds the nodes of both trees together (the roots included); reaching it
    is a failure. ``time_limit`` bounds a query's search in seconds; ``max_nodes=None``
    leaves the time limit as the only bound (one of the two is required). ``goal_bias`` is the probability of steering the extending tree toward
    the other tree's root instead of a uniform sample (0 is plain RRT-Connect). Each
    ``plan`` call draws from ``default_rng((seed, call number))``: a fresh planner gives
    the same results on the same sequence of problems.

    ``sampler`` (optional) replaces the uniform targets: ``sampler(problem)`` returns
    ``draw(rng, n)``, called for blocks of targets with the query's generator in place of
    ``robot.sample_uniform(rng, n, low, high)``. Without it the planner is unchanged.
    """

    name = "birrt"

    def __init__(
        self,
        robot: Robot,
        max_nodes: int | None = 10000,
        step: float = 0.07,
        resolution: float = 0.01,
        shortcut_iters: int = 100,
        goal_bias: float = 0.0,
        seed: int = 0,
        sampler: SamplerFactory | None = None,
        time_limit: float | None = None,
        shortcut_probes: int = 4,
    ) -> None:
        if step <= 0 or resolution <= 0:
            raise ValueError("step and resolution must be positive")
        if time_limit is not None and not time_limit > 0:
            raise ValueError(f"time_limit must be positive seconds or None, not {time_limit}")
        if not 0.0 <= goal_bias <= 1.0:
            raise ValueError("goal_bias is a probability")
        if max_nodes is None and time_limit is None:
            raise ValueError("Bi-RRT needs a node budget (max_nodes) or a time limit (time_limit)")
        if max_nodes is not None and int(max_nodes) < 2:
            raise ValueError(f"max_nodes must be at least 2 (the two roots), not {max_nodes}")
        self.robot = robot
        self.max_nodes = None if max_nodes is None else int(max_nodes)
        self.step = float(step)
        self.resolution = float(resolution)
        self.shortcut_iters = int(shortcut_iters)
        self.goal_bias = float(goal_bias)
        self.seed = int(seed)
        self.sampler = sampler
        #: seconds a query may search (``None``: no limit; ``max_nodes`` bounds it too)
        self.time_limit = None if time_limit is None else float(time_limit)
        #: plain configurations tested on a shortcut's stretch before its certified check
        #: (where one collides the check would fail: the same paths, found sooner; 0: off)
        self.shortcut_probes = int(shortcut_probes)
        self.calls = 0

    def __repr__(self) -> str:
        return (
            f"BiRRT(max_nodes={self.max_nodes}, step={self.step}, resolution={self.resolution}, "
            f"shortcut_iters={self.shortcut_iters}, goal_bias={self.goal_bias}, seed={self.seed}, time_limit={self.time_limit})"
        )

    def reset(self, seed: int | None = None) -> None:
        """Restart the call counter (and optionally change the seed)."""
        if seed is not None:
            self.seed = int(seed)
        self.calls = 0

    # ------------------------------------------------------------------ planning
    def plan(self, problem: Problem) -> PlanResult:
        """Grow the two trees until they connect or a budget runs out, then shortcut the path."""
        t0 = time.perf_counter()
        rng = np.random.default_rng([self.seed, self.calls])
        self.calls += 1
        robot, scene = self.robot, problem.scene
        world, low, high = scene.world, scene.low, scene.high
        start, goal = problem.start, problem.goal
        cdim = robot.config_dim

        ends_free = check_free(robot, world, np.stack([start, goal]), low, high)
        checks = 2
        trees = [_Tree(start), _Tree(goal)]
        if not ends_free.all():
            return PlanResult.failure(cdim, 2, checks, time.perf_counter() - t0, trees=[t.export() for t in trees])

        draw = self.sampler(problem) if self.sampler is not None else None
        samples = np.empty((0, cdim))
        coins = np.empty(0)
        k = 0
        a = 0  # index of the tree that extends this iteration
        raw: Array | None = None
        deadline = t0 + self.time_limit if self.time_limit is not None else np.inf
        cap = self.max_nodes if self.max_nodes is not None else np.inf
        while trees[0].n + trees[1].n < cap and time.perf_counter() < deadline:
            if k == len(samples):
                samples = (
                    robot.sample_uniform(rng, _SAMPLE_BLOCK, low, high) if draw is None else draw(rng, _SAMPLE_BLOCK)
                )
                coins = rng.random(_SAMPLE_BLOCK)
                k = 0
            ta, tb = trees[a], trees[1 - a]
            target = tb.nodes[0] if coins[k] < self.goal_bias else samples[k]
            k += 1
            # EXTEND ta one step toward the sample
            near, v = ta.nearest(robot, target)
            ext = march(robot, world, ta.nodes[near], target, self.step, self.resolution, 1, low, high, v)
            checks += ext.checks
            if len(ext.nodes):
                new = ta.add(ext.nodes, near)
                q_new = ta.nodes[new]
                # CONNECT tb toward the new node, as far as it goes
                budget = None if self.max_nodes is None else self.max_nodes - trees[0].n - trees[1].n
                near_b, v = tb.nearest(robot, q_new)
                con = march(robot, world, tb.nodes[near_b], q_new, self.step, self.resolution, budget, low, high, v)
                checks += con.checks
                end_b = tb.add(con.nodes, near_b) if len(con.nodes) else near_b
                if con.reached:
                    # tb's last node is q_new itself: drop the duplicate
                    path = np.concatenate([ta.branch(new), tb.branch(end_b)[::-1][1:]])
                    raw = path if a == 0 else path[::-1]
                    break
            a = 1 - a

        nodes = trees[0].n + trees[1].n
        exported = [t.export() for t in trees]
        if raw is None:
            return PlanResult.failure(cdim, nodes, checks, time.perf_counter() - t0, trees=exported)
        path, sc_checks = self.shortcut(raw, problem, rng)
        return PlanResult(
            path=path,
            success=True,
            nodes=nodes,
            collision_checks=checks + sc_checks,
            time_s=time.perf_counter() - t0,
            trees=exported,
            raw_path=raw,
        )

    # ------------------------------------------------------------------ smoothing
    def shortcut(self, path: Array, problem: Problem, rng: Any) -> tuple[Array, int]:
        """``shortcut_iters`` random shortcuts between points anywhere on the path (by arc
        length). A shortcut replaces a stretch when it is shorter and its geodesic, together
        with the two partial segments that lead to it, is free and inside the bounds.
        Returns the new path and the number of configurations checked."""
        robot, scene = self.robot, problem.scene
        path = np.asarray(path, np.float64)
        checks = 0
        twists = robot.log(path[:-1], path[1:])  # segment e is path[e] exp(s twists[e])
        if len(path) >= 3 and self.shortcut_iters > 0:
            # the same draws as the loop below (rng.uniform(0, L, 2) is L times two of these)
            u = rng.random(2 * self.shortcut_iters)
            fast = robot.shortcut_compiled(scene.world, path, twists, u, self.resolution, scene.low, scene.high)
            if fast is not None:
                return fast
            rng = _Replay(u)
        for _ in range(self.shortcut_iters):
            if len(path) < 3:
                break
            seg = np.linalg.norm(twists, axis=-1)
            cum = np.concatenate([[0.0], np.cumsum(seg)])
            u, w = np.sort(rng.uniform(0.0, cum[-1], 2))
            i = min(int(np.searchsorted(cum, u, side="right")) - 1, len(seg) - 1)
            j = min(int(np.searchsorted(cum, w, side="right")) - 1, len(seg) - 1)
            if i == j:
                continue  # both on one segment: already a geodesic
            fa = (u - cum[i]) / seg[i] if seg[i] > 0 else 0.0
            fb = (w - cum[j]) / seg[j] if seg[j] > 0 else 1.0
            qa, qb = robot.integrate(path[[i, j]], twists[[i, j]] * np.array([[fa], [fb]]))
            if float(robot.distance(qa, qb)) >= w - u - 1e-12:
                continue
            # The new path's segments, certified by the motion validator (the pieces of
            # the old segments too: their sub-steps differ from the old segment's).
            verts = [path[i]]
            if (u - cum[i]) > 1e-9:
                verts.append(qa)
            if (cum[j + 1] - w) > 1e-9:
                verts.append(qb)
            verts.append(path[j + 1])
            va = np.stack(verts)
            if self.shortcut_probes:  # a few plain configurations on the new stretch first
                probe = robot.interpolate(va[:-1, None, :], va[1:, None, :], _probe_fractions(self.shortcut_probes))
                checks += probe.shape[0] * probe.shape[1]
                if robot.collides(scene.world, probe.reshape(-1, probe.shape[-1])).any():
                    continue  # (a certified stretch has no configuration that touches an obstacle)
            free, used = segments_free(robot, scene.world, va[:-1], va[1:], self.resolution, scene.low, scene.high)
            checks += int(used.sum())
            if not free.all():
                continue
            path = np.concatenate([path[:i], va, path[j + 2 :]])
            twists = np.concatenate([twists[:i], robot.log(va[:-1], va[1:]), twists[j + 1 :]])
        return path, checks


__all__ = ["BiRRT", "DrawSamples", "SamplerFactory"]
