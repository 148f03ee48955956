"""MPNet (Qureshi et al. 2019): neural planning with replanning (``mpnet-nr``) and its hybrid
with Bi-RRT (``mpnet-hr``).

The networks are in :mod:`pointplan.models.mpnet`: the scene's boundary points with normals
are encoded once, and the planning network proposes the next configuration from the
encoding, a configuration and a goal, with dropout on (so each call is a random draw).

A query runs:

1. **Bidirectional neural planning** between ``a`` and ``b`` (first the start and the goal):
   if the straight edge ``a -> b`` is free, that is the path. Otherwise two chains grow, one
   from each end: the network proposes the next configuration of one chain toward the end
   of the other (clipped into the workspace bounds), then the edge between the two chain
   ends is checked; the chains swap roles every step, for at most ``neural_steps`` (50)
   proposals. As in MPNet the proposals themselves are not checked (planning is lazy): the
   path is chain A followed by chain B reversed, joined by a free edge when they connected,
   by an unchecked one otherwise.
2. **Lazy state contraction** (:func:`contract`): from the first configuration, jump to the
   farthest later one joined to it by a free straight edge (farthest first, as MPNet's
   ``lvc``), and repeat from there. Edges are only ever replaced by free ones no longer
   than what they skip, so the path never gets longer and a free path stays free.
3. **Feasibility**: every edge of the path is checked. If all are free, done.
4. **Neural replanning** (at most ``replan_iters`` = 10 rounds): configurations in collision
   are dropped (not the start and the goal), then every edge that is not free is replaced by
   a bidirectional neural plan between its ends (``replan_steps`` = 50 proposals at most;
   a plan that did not connect is kept too, so the next round starts from it), then the
   path is contracted and checked again. ``mpnet-nr`` fails when the rounds run out.
5. **Hybrid** (``mpnet-hr`` only): after the rounds, colliding configurations are dropped
   and every edge that is still not free is planned by Bi-RRT (pointplan's
   :class:`~pointplan.planners.birrt.BiRRT`, shortcut as usual) between its ends; the
   pieces are spliced in and the path is contracted once more.

Every edge is checked by the certified motion validator Bi-RRT uses (the geodesic sampled
at ``resolution`` = 0.01, :func:`pointplan.robots.motion.segments_free`, the check of
:func:`~pointplan.planners.edges.edge_free`), and each edge only once per query (a cache).
``nodes`` = configurations the network proposed (all of them, including those later dropped
or contracted away) + Bi-RRT's nodes (both its trees, their roots included) for the hybrid.
``collision_checks`` = configurations checked by the validator (every sample of every edge
checked, counted as an edge-by-edge check would: contraction checks candidate edges in
batches but counts only those up to the first free one) + single configurations checked
when dropping colliding ones + Bi-RRT's checks.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..robots.base import Robot
from ..robots.motion import segments_free
from ..scenes.scene import Problem, Scene
from .base import Array, PlanResult, check_free
from .birrt import BiRRT

if TYPE_CHECKING:
    from ..models.mpnet import MPNet

#: candidate edges contraction checks in one validator call (farthest first)
_CONTRACT_BATCH = 16


def scene_points(robot: Robot, scene: Scene, observation: str | None = None, n_points: int = 0) -> tuple[Array, Array]:
    """The world points and outward normals MPNet's encoder reads for ``scene`` (cached on
    the scene, as the observers'). ``surface-normals`` (2D default): the observer's whole
    point set. ``global`` (3D default): the global observer's pool of ``n_points`` (default
    512) area-weighted surface points, drawn once per workspace (seeded by its name)."""
    from ..models.mpnet import N_POINTS_3D, OBSERVATION_3D, default_observation
    from ..observers import make_observer
    from ..observers.points import GlobalPoints

    observation = observation or default_observation(robot)
    if observation == OBSERVATION_3D:
        n = int(n_points) or N_POINTS_3D
        pts, nrm, _ = GlobalPoints(robot, n_points=n, pool_size=n).pool(scene)
        return pts, nrm
    observer = make_observer(observation, robot)
    observer.bind([scene])
    return observer.points_one()  # type: ignore[attr-defined,no-any-return]


class EdgeChecker:
    """Edges and configurations of one query checked by the certified validator, each once
    (a cache keyed by the exact configurations), with the number of configurations checked."""

    def __init__(self, robot: Robot, scene: Scene, resolution: float = 0.01) -> None:
        self.robot, self.scene, self.resolution = robot, scene, float(resolution)
        self.checks = 0
        self._edges: dict[bytes, bool] = {}
        self._states: dict[bytes, bool] = {}

    @staticmethod
    def _key(a: Array, b: Array) -> bytes:
        return np.ascontiguousarray(a, np.float64).tobytes() + np.ascontiguousarray(b, np.float64).tobytes()

    def known(self, a: Array, b: Array, free: bool) -> None:
        """Record an edge certified elsewhere (Bi-RRT's, by the same validator)."""
        self._edges[self._key(a, b)] = bool(free)

    def _run(self, a: Array, b: Array) -> tuple[np.ndarray, np.ndarray]:
        s = self.scene
        free, used = segments_free(
            self.robot, s.world, np.atleast_2d(a), np.atleast_2d(b), self.resolution, s.low, s.high
        )
        return np.asarray(free, bool), np.asarray(used, np.int64)

    def free(self, a: Array, b: Array) -> bool:
        """Is the geodesic ``a -> b`` certified free and inside the bounds?"""
        key = self._key(a, b)
        hit = self._edges.get(key)
        if hit is not None:
            return hit
        ok, used = self._run(a, b)
        self.checks += int(used[0])
        self._edges[key] = bool(ok[0])
        return bool(ok[0])

    def all_free(self, path: Array) -> np.ndarray:
        """Per edge of ``path``: free? (the edges not checked yet in one validator call)"""
        keys = [self._key(a, b) for a, b in zip(path[:-1], path[1:])]
        todo = [e for e, k in enumerate(keys) if k not in self._edges]
        if todo:
            idx = np.array(todo)
            ok, used = self._run(path[idx], path[idx + 1])
            self.checks += int(used.sum())
            for e, f in zip(todo, ok):
                self._edges[keys[e]] = bool(f)
        return np.array([self._edges[k] for k in keys], bool)

    def first_free(self, a: Array, bs: Array) -> int | None:
        """Index of the first ``b`` in ``bs`` with ``a -> b`` free, or None. Candidates are
        checked in batches, but only those up to the answer are counted and remembered (what
        one-by-one checks would do)."""
        for c0 in range(0, len(bs), _CONTRACT_BATCH):
            chunk = bs[c0 : c0 + _CONTRACT_BATCH]
            keys = [self._key(a, b) for b in chunk]
            todo = [e for e, k in enumerate(keys) if k not in self._edges]
            fresh: dict[int, tuple[bool, int]] = {}
            if todo:
                idx = np.array(todo)
                ok, used = self._run(np.broadcast_to(a, chunk[idx].shape), chunk[idx])
                fresh = {e: (bool(f), int(u)) for e, f, u in zip(todo, ok, used)}
            for e, k in enumerate(keys):
                if e in fresh:
                    f, u = fresh[e]
                    self.checks += u
                    self._edges[k] = f
                if self._edges[k]:
                    return c0 + e
        return None

    def states_free(self, qs: Array) -> np.ndarray:
        """Per configuration: collision-free and inside the bounds (one check each)."""
        qs = np.asarray(qs, np.float64).reshape(-1, self.robot.config_dim)
        keys = [q.tobytes() for q in qs]
        todo = [i for i, k in enumerate(keys) if k not in self._states]
        if todo:
            s = self.scene
            ok = check_free(self.robot, s.world, qs[todo], s.low, s.high)
            self.checks += len(todo)
            for i, f in zip(todo, ok):
                self._states[keys[i]] = bool(f)
        return np.array([self._states[k] for k in keys], bool)


def contract(robot: Robot, path: Array, edges: EdgeChecker) -> Array:
    """Lazy state contraction: from each kept configuration, jump to the farthest later one
    it reaches by a free edge no longer than the stretch of path it skips (farthest first;
    the next configuration when none does). Never lengthens the path; keeps a free path free."""
    path = np.asarray(path, np.float64)
    n = len(path)
    if n < 3:
        return path.copy()
    seg = robot.distance(path[:-1], path[1:])
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    keep = [0]
    i = 0
    while i < n - 1:
        js = np.arange(n - 1, i + 1, -1)  # farthest first, i + 1 excluded (already an edge)
        if len(js):
            shorter = robot.distance(np.broadcast_to(path[i], path[js].shape), path[js]) <= (cum[js] - cum[i]) + 1e-12
            js = js[shorter]
        found = edges.first_free(path[i], path[js]) if len(js) else None
        i = int(js[found]) if found is not None else i + 1
        keep.append(i)
    return path[keep]


class MPNetPlanner:
    """MPNet: neural planning, lazy state contraction and neural replanning; with
    ``hybrid``, Bi-RRT for the edges neural replanning could not repair (see the module).

    ``model``: a :class:`~pointplan.models.mpnet.MPNet` or a checkpoint path. Each ``plan``
    call draws the network's dropout from ``default_rng((seed, call number))`` and Bi-RRT
    has the same ``seed``: a fresh planner gives the same results on the same sequence of
    problems. ``max_nodes`` bounds each Bi-RRT call (hybrid)."""

    def __init__(
        self,
        model: str | Path | MPNet,
        robot: Robot | None = None,
        hybrid: bool = False,
        neural_steps: int = 50,
        replan_iters: int = 10,
        replan_steps: int = 50,
        resolution: float = 0.01,
        max_nodes: int = 20000,
        seed: int = 0,
        dropout: bool = True,
    ) -> None:
        from ..models.mpnet import MPNet, check_translating

        if isinstance(model, (str, Path)):
            model = MPNet.from_checkpoint(model)
        assert isinstance(model, MPNet)
        self.mpnet = model
        self.robot = robot or model.robot
        check_translating(self.robot)
        if self.robot.name != model.robot.name:
            raise ValueError(f"the MPNet was trained for robot {model.robot.name!r}, not {self.robot.name!r}")
        self.net = model.numpy()
        self.hybrid = bool(hybrid)
        self.name = "mpnet-hr" if self.hybrid else "mpnet-nr"
        self.neural_steps = int(neural_steps)
        self.replan_iters = int(replan_iters)
        self.replan_steps = int(replan_steps)
        self.resolution = float(resolution)
        self.seed = int(seed)
        self.dropout = bool(dropout)
        self.birrt = BiRRT(self.robot, max_nodes=max_nodes, resolution=resolution, seed=seed)
        self.calls = 0

    def __repr__(self) -> str:
        return (
            f"MPNetPlanner(hybrid={self.hybrid}, neural_steps={self.neural_steps}, replan_iters={self.replan_iters}, "
            f"replan_steps={self.replan_steps}, dropout={self.net.dropout if self.dropout else 0.0}, seed={self.seed})"
        )

    def reset(self, seed: int | None = None) -> None:
        """Restart the call counters (and optionally change the seed)."""
        if seed is not None:
            self.seed = int(seed)
        self.calls = 0
        self.birrt.reset(seed)

    def encode(self, scene: Scene) -> np.ndarray:
        """The encoder's feature of ``scene``."""
        from ..models.mpnet import encoder_input

        pts, nrm = scene_points(self.robot, scene, self.mpnet.observation, self.mpnet.n_points)
        return self.net.encode(encoder_input(pts, nrm, self.net.center, self.net.step))

    # ------------------------------------------------------------------ pieces
    def neural_plan(
        self, z: np.ndarray, a: Array, b: Array, steps: int, edges: EdgeChecker, rng: np.random.Generator | None
    ) -> tuple[Array, bool, int]:
        """Bidirectional neural planning from ``a`` to ``b``: ``(path, connected, proposals)``;
        the path runs from ``a`` to ``b`` (joined by an unchecked edge when not connected)."""
        scene = edges.scene
        if edges.free(a, b):
            return np.stack([a, b]), True, 0
        chains: list[list[Array]] = [[np.asarray(a, np.float64)], [np.asarray(b, np.float64)]]
        grow = 0
        connected = False
        n = 0
        for _ in range(steps):
            ta, tb = chains[grow], chains[1 - grow]
            x = self.net.next(z, ta[-1], tb[-1], rng)
            ta.append(self.robot.clip(x, scene.low, scene.high))
            n += 1
            if edges.free(chains[0][-1], chains[1][-1]):  # checked in path order
                connected = True
                break
            grow = 1 - grow
        return np.stack(chains[0] + chains[1][::-1]), connected, n

    def _drop_colliding(self, path: Array, edges: EdgeChecker) -> Array:
        if len(path) <= 2:
            return path
        ok = edges.states_free(path[1:-1])
        return np.concatenate([path[:1], path[1:-1][ok], path[-1:]])

    def _replan(
        self, z: np.ndarray, path: Array, edges: EdgeChecker, rng: np.random.Generator | None
    ) -> tuple[Array, int]:
        path = self._drop_colliding(path, edges)
        pieces = [path[:1]]
        nodes = 0
        for a, b in zip(path[:-1], path[1:]):
            if edges.free(a, b):
                pieces.append(b[None])
                continue
            sub, _, n = self.neural_plan(z, a, b, self.replan_steps, edges, rng)
            nodes += n
            pieces.append(sub[1:])
        return np.concatenate(pieces), nodes

    # ------------------------------------------------------------------ planning
    def plan(self, problem: Problem) -> PlanResult:
        t0 = time.perf_counter()
        rng = np.random.default_rng([self.seed, self.calls]) if self.dropout else None
        self.calls += 1
        robot, scene = self.robot, problem.scene
        cdim = robot.config_dim
        start, goal = np.asarray(problem.start, np.float64), np.asarray(problem.goal, np.float64)
        edges = EdgeChecker(robot, scene, self.resolution)
        info: dict[str, Any] = {"neural_nodes": 0, "birrt_nodes": 0, "replans": 0, "stage": ""}
        if not edges.states_free(np.stack([start, goal])).all():
            info["stage"] = "invalid"
            return PlanResult.failure(cdim, 0, edges.checks, time.perf_counter() - t0, info=info)
        z = self.encode(scene)

        raw, _, nodes = self.neural_plan(z, start, goal, self.neural_steps, edges, rng)
        path = contract(robot, raw, edges)
        birrt_nodes = birrt_checks = 0
        ok = bool(edges.all_free(path).all())
        stage = "neural"
        while not ok and info["replans"] < self.replan_iters:
            info["replans"] += 1
            path, n = self._replan(z, path, edges, rng)
            nodes += n
            path = contract(robot, path, edges)
            ok = bool(edges.all_free(path).all())
            stage = "replanned"
        if not ok and self.hybrid:
            stage = "birrt"
            path = self._drop_colliding(path, edges)
            free = edges.all_free(path)
            pieces = [path[:1]]
            for e, (a, b) in enumerate(zip(path[:-1], path[1:])):
                if free[e]:
                    pieces.append(b[None])
                    continue
                res = self.birrt.plan(Problem(scene, a, b, tag=f"{problem.tag}/birrt"))
                birrt_nodes += res.nodes
                birrt_checks += res.collision_checks
                if not res.success:
                    stage = "birrt-failed"
                    break
                for u, v in zip(res.path[:-1], res.path[1:]):
                    edges.known(u, v, True)  # certified by Bi-RRT with the same validator
                pieces.append(res.path[1:])
            else:
                path = contract(robot, np.concatenate(pieces), edges)
                ok = bool(edges.all_free(path).all())
        info.update(
            neural_nodes=nodes,
            birrt_nodes=birrt_nodes,
            stage=stage if ok else (stage if stage == "birrt-failed" else "failed"),
        )
        total_nodes = nodes + birrt_nodes
        checks = edges.checks + birrt_checks
        dt = time.perf_counter() - t0
        if not ok:
            return PlanResult.failure(cdim, total_nodes, checks, dt, raw_path=raw, info=info)
        return PlanResult(
            path=path, success=True, nodes=total_nodes, collision_checks=checks, time_s=dt, raw_path=raw, info=info
        )


__all__ = ["EdgeChecker", "MPNetPlanner", "contract", "scene_points"]
