"""The shipped 2D policy against OMPL's RRTConnect and our Bi-RRT, one problem at a time.

As a user calls a planner: ``planner.plan(problem)`` on 2D-Narrow test problems, batch 1,
one core. The planners take turns on each problem (so a change in machine load hits all
of them alike) and every path is re-checked by ``check_path``.

    OMP_NUM_THREADS=1 python benchmarks/bench_vs_ompl.py --problems 400

Planners (``--planners``, comma separated):

- ``policy``: ``make_planner("policy", robot).plan`` (the batch-1 path: for the disc among
  boxes one compiled call per problem (network, motion checks, the greedy goal test); paths
  end at the goal as soon as the certified straight edge to it is free).
- ``policy-python``: the same rollout without the compiled kernel (``compiled=False``:
  numpy network, one batched ``q_free`` call per run ahead).
- ``policy-nogreedy``: ``greedy_goal=False``: the rollout to the goal tolerance, then the
  last edge (the planner before the greedy goal test).
- ``policy-before``: the per-problem path as it was before: ``rollout_batch`` with one
  problem, the network in PyTorch with its default thread count (``--torch-threads``
  changes that), no connection to the goal.
- ``ompl``: ``make_planner("ompl:RRTConnect", robot)``: OMPL's C++ search with pointplan's
  validity checker and pointplan's edge check as motion validator (what ``pointplan eval``
  runs); range 0.07.
- ``ompl-ref``: RRTConnect driven the way one usually drives OMPL from Python: a Python
  validity checker (a hand-written disc-against-boxes test on plain floats, no numpy) and
  OMPL's own C++ ``DiscreteMotionValidator`` checking states 0.01 apart; range 0.07. This
  is the setup of the issue's report (its OMPL times).
- ``ompl-simplify``: ``ompl`` followed by OMPL's path simplifier (``simplifySolution``:
  shortcuts and smoothing, its motions checked by pointplan's edge check too).
- ``birrt``: our Bi-RRT (RRT-Connect + 100 shortcuts).
- ``hybrid``: ``make_planner("hybrid", robot)``: the policy, then Bi-RRT where it fails.

Printed: time per problem (median / mean, ms) as wall time and as the thread's CPU time
(on a shared machine the wall time of a 2 ms call swings by 2-3x between runs, the CPU time
much less), success by ``check_path``, nodes and collision checks (mean), the policy's
per-step latency split (observation, network, motion check), and the ratios policy / OMPL.
"""

from __future__ import annotations

import argparse
import gc
import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from pointplan.evaluation import check_path
from pointplan.planners import make_planner
from pointplan.planners.base import PlanResult, path_length
from pointplan.planners.policy import rollout_batch
from pointplan.scenes.scenarios import Narrow2DScenario
from pointplan.scenes.scene import Problem


class OMPLReference:
    """RRTConnect with a plain-Python disc-vs-boxes validity checker and OMPL's own
    motion validator (states ``resolution`` apart): the usual Python setup."""

    name = "ompl-ref"

    def __init__(self, robot: Any, range_: float = 0.07, resolution: float = 0.01, time_limit: float = 1.0) -> None:
        from ompl import base as ob
        from ompl import geometric as og
        from ompl import util as ou

        ou.setLogLevel(ou.LOG_ERROR)
        self.ob, self.og = ob, og
        self.robot, self.range, self.resolution, self.time_limit = robot, range_, resolution, time_limit

    def plan(self, problem: Problem) -> PlanResult:
        t0 = time.perf_counter()
        ob, og = self.ob, self.og
        scene = problem.scene
        r2 = self.robot.radius**2
        (lx, ly), (hx, hy) = scene.low, scene.high
        boxes = []
        for b in scene.obstacles:
            rot = np.asarray(b.rotation)
            boxes.append(
                (
                    float(b.center[0]),
                    float(b.center[1]),
                    float(rot[0, 0]),
                    float(rot[1, 0]),
                    float(rot[0, 1]),
                    float(rot[1, 1]),
                    float(b.size[0]) / 2,
                    float(b.size[1]) / 2,
                )
            )
        checks = [0]

        def valid(s: Any) -> bool:
            checks[0] += 1
            x, y = s[0], s[1]
            if x < lx or x > hx or y < ly or y > hy:
                return False
            for cx, cy, r00, r10, r01, r11, hx_, hy_ in boxes:
                dx, dy = x - cx, y - cy
                u = abs(dx * r00 + dy * r10) - hx_
                v = abs(dx * r01 + dy * r11) - hy_
                u = u if u > 0.0 else 0.0
                v = v if v > 0.0 else 0.0
                if u * u + v * v <= r2:
                    return False
            return True

        space = ob.RealVectorStateSpace(2)
        bounds = ob.RealVectorBounds(2)
        for i in range(2):
            bounds.setLow(i, float(scene.low[i]))
            bounds.setHigh(i, float(scene.high[i]))
        space.setBounds(bounds)
        si = ob.SpaceInformation(space)
        si.setStateValidityChecker(valid)
        si.setStateValidityCheckingResolution(self.resolution / si.getMaximumExtent())
        si.setup()
        ss = og.SimpleSetup(si)
        start, goal = si.allocState(), si.allocState()
        for i in range(2):
            start[i], goal[i] = float(problem.start[i]), float(problem.goal[i])
        ss.setStartAndGoalStates(start, goal)
        planner = og.RRTConnect(si)
        planner.setRange(self.range)
        ss.setPlanner(planner)
        ss.solve(ob.timedPlannerTerminationCondition(self.time_limit))  # no watcher thread
        path = None
        if ss.haveExactSolutionPath():
            path = np.array([[s[0], s[1]] for s in ss.getSolutionPath().getStates()])
        data = ob.PlannerData(si)
        ss.getPlannerData(data)
        nodes = int(data.numVertices())
        del ss, planner, data, si, space
        dt = time.perf_counter() - t0
        if path is None:
            return PlanResult.failure(2, nodes, checks[0], dt)
        return PlanResult(path, True, nodes, checks[0], dt)


class PolicyBefore:
    """The per-problem path before this benchmark's changes: ``rollout_batch`` with one
    problem and the network in PyTorch (default thread count unless told)."""

    name = "policy-before"

    def __init__(self, robot: Any, torch_threads: int | None) -> None:
        self.planner = make_planner("policy", robot)
        self.torch_threads = torch_threads

        #: seconds in the batched core's observe, the network and the core's step (q_free
        #: and the rest of an env step), and steps taken
        self.split = {"observe": 0.0, "network": 0.0, "motion": 0.0, "steps": 0}

    def plan(self, problem: Problem) -> PlanResult:
        import torch

        from pointplan.envs.core import BatchedCore

        if self.torch_threads:
            torch.set_num_threads(self.torch_threads)
        p, split = self.planner, self.split
        observe, step = BatchedCore.observe, BatchedCore.step

        def timed(fn: Callable[..., Any], key: str) -> Callable[..., Any]:
            def run(*a: Any, **kw: Any) -> Any:
                t = time.perf_counter()
                out = fn(*a, **kw)
                split[key] += time.perf_counter() - t
                return out

            return run

        BatchedCore.observe, BatchedCore.step = timed(observe, "observe"), timed(step, "motion")  # type: ignore[method-assign]
        try:
            res = rollout_batch(timed(p.policy, "network"), p.robot, p.env, [problem], p.horizon)[0]
        finally:
            BatchedCore.observe, BatchedCore.step = observe, step  # type: ignore[method-assign]
        split["steps"] += res.nodes
        return res


def build(name: str, robot: Any, args: argparse.Namespace) -> Any:
    if name == "policy":
        return make_planner("policy", robot)
    if name == "policy-python":
        pl = make_planner("policy", robot, compiled=False)
        pl.name = name
        return pl
    if name == "policy-nogreedy":
        pl = make_planner("policy", robot, greedy_goal=False)
        pl.name = name
        return pl
    if name == "policy-before":
        return PolicyBefore(robot, args.torch_threads)
    if name == "ompl":
        return make_planner("ompl:RRTConnect", robot)
    if name == "ompl-simplify":
        pl = make_planner("ompl:RRTConnect", robot, simplify=True)
        pl.name = "ompl-simplify"
        return pl
    if name == "ompl-ref":
        return OMPLReference(robot)
    if name == "birrt":
        return make_planner("birrt", robot, seed=0)
    if name == "hybrid":
        return make_planner("hybrid", robot, seed=0)
    raise SystemExit(f"unknown planner {name!r}")


def step_parts(planner: Any, problems: list[Problem], reps: int = 200) -> dict[str, float]:
    """Latency of the parts of one compiled policy step, each run ``reps`` times in a
    compiled loop at the problems' starts (median over the problems, us): the point
    draw, the network, ``q_free``'s move and the goal edge's quick test and certified
    check."""
    import numba

    from pointplan.planners import _policy_kernels as K

    @numba.njit
    def loop(  # type: ignore[no-untyped-def]
        kind,
        reps,
        q,
        goal,
        u,
        count,
        n_points,
        idx,
        pts,
        nrm,
        s32,
        wflat,
        layout,
        scale,
        low,
        high,
        bc,
        br,
        bh,
        ws,
        tw,
        nq,
    ):
        for _ in range(reps):
            if kind == 0:
                K._select(u, count, n_points, idx)
            elif kind == 1:
                K._action(q, goal, idx, pts, nrm, s32, wflat, layout, scale, 2, ws)
            elif kind == 2:
                K._q_free(q, tw, 0.01, low, high, (bc, br, bh), 0.01, True, nq)
            elif kind == 3:
                K._segment_hits(q, goal, 0.01 * (1 - 1e-9), 0.01, (bc, br, bh))
            else:
                K._edge_free(q, goal, 0.01, 0.01, low, high, (bc, br, bh))

    compiled = planner.engine.compiled()
    wflat, layout, scale, fparams, iparams = compiled.args
    n_points = int(iparams[K.I_N_POINTS])
    names = ("point draw", "network", "move (q_free)", "goal quick test", "goal certified check")
    out: dict[str, list[float]] = {k: [] for k in names}
    for p in problems:
        _, _, *bx, _prims, pts, nrm = compiled._scene_inputs(p.scene)[:8]
        boxes = tuple(bx)
        count = len(pts)
        u = planner.engine._uniforms(count + n_points)[: count + n_points]
        idx = np.empty(n_points, np.int64)
        K._select(u, count, n_points, idx)
        s32 = float(fparams[K.F_S32])
        ws = K._workspace(n_points, layout, 2)
        tw, nq = np.array([0.05, 0.05]), np.empty(2)
        for kind, name in enumerate(names):
            args = (
                p.start,
                p.goal,
                u,
                count,
                n_points,
                idx,
                pts,
                nrm,
                s32,
                wflat,
                layout,
                scale,
                p.scene.low,
                p.scene.high,
                *boxes,
                ws,
                tw,
                nq,
            )
            loop(kind, 1, *args)
            t = time.perf_counter()
            loop(kind, reps, *args)
            out[name].append((time.perf_counter() - t) / reps * 1e6)
    return {k: float(np.median(v)) for k, v in out.items()}


def fmt_ms(x: float) -> str:
    return f"{1e3 * x:.2f}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--problems", type=int, default=400, help="2D-Narrow test problems 0..N-1 (default: %(default)s)")
    ap.add_argument("--seed", type=int, default=0, help="start/goal seed of the problems (default: %(default)s)")
    ap.add_argument("--planners", default="policy,policy-before,ompl,ompl-simplify,ompl-ref,birrt,hybrid")
    ap.add_argument("--torch-threads", type=int, help="PyTorch threads for policy-before (default: PyTorch's own)")
    args = ap.parse_args()

    import torch

    default_threads = torch.get_num_threads()
    scenario = Narrow2DScenario()
    robot = scenario.robot
    problems = scenario.problems("test", args.problems, seed=args.seed)
    for p in problems:  # collision worlds serve every planner: built up front, untimed
        _ = p.scene.world
    names = [n.strip() for n in args.planners.split(",") if n.strip()]
    planners = {n: build(n, robot, args) for n in names}
    warm = scenario.problems("val", 3, seed=0)
    for pl in planners.values():  # imports, compilation, first calls
        for p in warm:
            pl.plan(p)
        if hasattr(pl, "reset"):  # Bi-RRT: the same draws as `pointplan eval`
            pl.reset()
    rows: dict[str, dict[str, list[float]]] = {
        n: {"time": [], "cpu": [], "ok": [], "nodes": [], "checks": [], "length": []} for n in names
    }
    split = {"observe": 0.0, "network": 0.0, "motion": 0.0, "goal": 0.0, "compiled": 0.0, "steps": 0}
    scene_prep: list[float] = []
    gc.collect()
    gc.disable()  # no collector pauses inside a timed call
    try:
        for i, p in enumerate(problems):
            # the planners take turns, and the turn starts with a different one on each
            # problem: the first call after `gc.collect()` finds cold caches (it cost the
            # policy 0.1-0.2 ms when it always went first), so every planner pays it equally
            order = names[i % len(names) :] + names[: i % len(names)]
            for n in order:
                pl = planners[n]
                # the observer's point set of a new scene, timed apart
                if n in ("policy", "policy-python", "policy-nogreedy"):
                    t = time.perf_counter()
                    pl.engine.observer.set_scene(0, p.scene)  # computes and caches the points
                    scene_prep.append(time.perf_counter() - t)
                c = time.thread_time()
                t = time.perf_counter()
                res = pl.plan(p)
                dt = time.perf_counter() - t
                dc = time.thread_time() - c
                ok = len(res.path) > 0 and bool(check_path(robot, p, res.path))
                r = rows[n]
                r["time"].append(dt)
                r["cpu"].append(dc)
                r["ok"].append(float(ok))
                r["nodes"].append(res.nodes)
                r["checks"].append(res.collision_checks)
                r["length"].append(
                    path_length(robot, res.path) + float(robot.distance(res.path[-1], p.goal)) if ok else math.nan
                )
                if n == "policy" and "time_split" in res.info:
                    for k in split:
                        split[k] += res.info["time_split"].get(k, 0.0)
            gc.collect()
    finally:
        gc.enable()

    print(
        f"2D-Narrow test problems 0..{args.problems - 1} (seed {args.seed}), one at a time; torch default threads {default_threads}"
    )
    print(
        "wall: time per plan() call; cpu: this thread's CPU time in it (what other jobs on the machine disturb least)"
    )
    header = f"{'planner':<14} {'success':>8} {'wall median':>12} {'wall mean':>10} {'cpu median':>11} {'cpu mean':>9} {'nodes':>7} {'checks':>8} {'length':>7}"
    print(header)
    print("-" * len(header))
    med: dict[str, float] = {}
    cmed: dict[str, float] = {}
    for n in names:
        r = rows[n]
        med[n] = float(np.median(r["time"]))
        cmed[n] = float(np.median(r["cpu"]))
        print(
            f"{n:<14} {100 * np.mean(r['ok']):>7.1f}% {fmt_ms(med[n]):>12} {fmt_ms(float(np.mean(r['time']))):>10} "
            f"{fmt_ms(cmed[n]):>11} {fmt_ms(float(np.mean(r['cpu']))):>9} "
            f"{np.mean(r['nodes']):>7.1f} {np.mean(r['checks']):>8.0f} {np.nanmean(r['length']):>7.3f}"
        )
    print("(times in ms; length: path length counted to the goal, mean over the problems the evaluator accepts)")
    for name, sp in (("policy", split), ("policy-before", getattr(planners.get("policy-before"), "split", None))):
        if not sp or not sp["steps"] or name not in rows:
            continue
        s = sp["steps"]
        total = sp["observe"] + sp["network"] + sp["motion"] + sp.get("goal", 0.0) + sp.get("compiled", 0.0)
        rest = 1e6 * (float(np.sum(rows[name]["time"])) - total) / s
        if sp.get("compiled"):
            print(
                f"{name} per step ({s} steps), wall: compiled rollout (network, motion check, goal test) {1e6 * sp['compiled'] / s:.1f} us, rest {rest:.1f} us"
            )
        else:
            print(
                f"{name} per step ({s} steps), wall: observation {1e6 * sp['observe'] / s:.1f} us, network {1e6 * sp['network'] / s:.1f} us, "
                f"motion check {1e6 * sp['motion'] / s:.1f} us, rest {rest:.1f} us"
            )
    if split["steps"]:
        print(
            "  (policy: one compiled call per problem for the disc among boxes (rest = the Python around it: set-up, result); "
            "policy-before: observation = BatchedCore.observe, motion check = BatchedCore.step with its q_free)"
        )
        print(
            f"policy scene preparation (the observer's point set of a new workspace, like the collision world untimed above): median {1e6 * float(np.median(scene_prep)):.0f} us"
        )
        if "policy" in planners and planners["policy"].engine.compiled() is not None:
            for k, v in step_parts(planners["policy"], problems[: min(50, len(problems))]).items():
                print(f"  policy step parts, median over calls (compiled, called from a compiled loop): {k} {v:.1f} us")
    for a, b in (
        ("policy", "ompl"),
        ("policy", "ompl-ref"),
        ("policy-python", "ompl-ref"),
        ("policy-nogreedy", "ompl-ref"),
        ("policy", "policy-nogreedy"),
        ("policy", "birrt"),
        ("policy", "policy-before"),
        ("policy-before", "ompl-ref"),
        ("ompl", "ompl-ref"),
        ("ompl", "birrt"),
        ("hybrid", "birrt"),
    ):
        if a in med and b in med:
            print(f"median time {a} / {b}: wall {med[a] / med[b]:.2f}, cpu {cmed[a] / cmed[b]:.2f}")


if __name__ == "__main__":
    main()
