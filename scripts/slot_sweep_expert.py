"""A thin-slot expert for Slot: sweep the S-shape's centreline through the opening.

On any path through the wall every point of the S-shape's centreline crosses the wall's
mid-plane inside the slot. This expert follows that literally: for arc lengths ``s`` from
the tip of one end bar to the tip of the other, it finds a free pose with the centreline
point at ``s`` in the opening (x = 0), each warm-started from the previous pose and kept
close to it, maximising the clearance to the wall (coal's signed distance, capped) with a
soft preference for the part of the centreline before ``s`` to be past the wall and the
part after it before the wall. Consecutive poses are joined by straight edges; then
pointplan's Bi-RRT joins the start to the sweep's first pose (backed off from the wall)
and its last pose to the goal. The whole path is re-checked by the evaluator
(``check_path``); nothing counts as solved otherwise.

    python scripts/slot_sweep_expert.py --problems 6 --min-bars 2 --max-bars 4 --seed 5
    python scripts/slot_sweep_expert.py --problems 12 --first 100
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import coal
import numpy as np
from scipy.optimize import minimize
from scipy.spatial.transform import Rotation

from pointplan.evaluation.evaluate import check_path, timed_path
from pointplan.planners.base import path_length
from pointplan.planners.birrt import BiRRT
from pointplan.planners.edges import edge_free
from pointplan.robots.sshape import S_CORNERS, SShape
from pointplan.scenes.scene import Problem
from pointplan.scenes.scenes3d import SlotConfig, SlotScenario


class WallClearance:
    """Smallest signed distance (coal) between the S-shape's bars at a pose and the scene's
    boxes (the Slot wall)."""

    def __init__(self, robot: SShape, problem: Problem) -> None:
        parts = robot.parts
        self.bars = [(coal.Box(*(2 * h)), c) for c, h in zip(parts.box_centers, parts.box_halfs, strict=True)]
        self.wall = [
            (coal.Box(*o.size), coal.Transform3s(np.asarray(o.rotation, np.float64), np.asarray(o.center, np.float64))) for o in problem.scene.obstacles
        ]
        self.req = coal.DistanceRequest()
        self.req.enable_signed_distance = True
        # the wall: boxes spanning the plane x = plane, half_wall thick; a bar's reach: its half diagonal
        self.plane = float(problem.scene.obstacles[0].center[0])
        self.half_wall = max(float(o.size[0]) for o in problem.scene.obstacles) / 2
        self.reach = [float(np.linalg.norm(h)) for h in parts.box_halfs]

    def __call__(self, rot: np.ndarray, pos: np.ndarray, above: float = np.inf) -> float:
        """The clearance; with ``above``, a bar whose centre is farther from the wall's
        plane than its reach plus the wall's half thickness plus ``above`` is skipped (its
        distance is more than ``above``), and the answer is exact only up to ``above``."""
        best = np.inf
        for (shape, c), reach in zip(self.bars, self.reach, strict=True):  # the bars are axis-aligned in the body frame
            centre = rot @ c + pos
            if abs(centre[0] - self.plane) > reach + self.half_wall + above:
                best = min(best, abs(centre[0] - self.plane) - reach - self.half_wall)
                continue
            tf = coal.Transform3s(rot, centre)
            for wshape, wtf in self.wall:
                best = min(best, coal.distance(shape, tf, wshape, wtf, self.req, coal.DistanceResult()))
        return float(best)


def centreline(order: str) -> tuple[np.ndarray, np.ndarray]:
    """The centreline's corners from the leading tip (``"A"``: bar A first, ``"E"``: bar E
    first) and their arc lengths."""
    pts = S_CORNERS if order == "A" else S_CORNERS[::-1]
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
    return pts, arc


def point_at(pts: np.ndarray, arc: np.ndarray, s: float) -> np.ndarray:
    k = int(np.clip(np.searchsorted(arc, s, side="right") - 1, 0, len(arc) - 2))
    f = (s - arc[k]) / (arc[k + 1] - arc[k])
    return pts[k] + f * (pts[k + 1] - pts[k])


class Sweep:
    """The sweep of one problem and one leading end (``order``)."""

    def __init__(self, robot: SShape, problem: Problem, order: str, rng: np.random.Generator, min_clearance: float = 0.0015, guide: float = 0.0) -> None:
        slot = problem.scene.__dict__["slot"]
        self.problem, self.rng, self.min_clearance = problem, rng, float(min_clearance)
        #: with ``guide > 0``, the sweep toward a bend is pulled to a free pose of the bend in
        #: the opening found beforehand (weight ``guide`` on the squared angle, rising along
        #: the bar that leads there)
        self.guide, self.target, self.w_target = float(guide), None, 0.0
        width, self.mid, long_axis = float(slot["width"]), np.asarray(slot["center"], np.float64), int(slot["long_axis"])
        self.e_long, self.e_thin = np.eye(3)[long_axis], np.eye(3)[3 - long_axis]
        self.half = np.array([0.2, width / 2])
        self.cap = max((width - 0.036) / 2 * 0.6, 0.002)  # the clearance asked for, below what the slot allows
        self.clear = WallClearance(robot, problem)
        self.pts, self.arc = centreline(order)
        self.samples = np.linspace(0, self.arc[-1], 60)
        self.sample_pts = np.array([point_at(self.pts, self.arc, a) for a in self.samples])

    def pose(self, v: np.ndarray, rot0: np.ndarray, s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        rot = rot0 @ Rotation.from_rotvec(v[:3]).as_matrix()
        u = self.half * np.tanh(v[3:5])
        c = point_at(self.pts, self.arc, s)
        pos = self.mid + u[0] * self.e_long + u[1] * self.e_thin - rot @ c
        return rot, pos, u

    def cost(self, v: np.ndarray, rot0: np.ndarray, u0: np.ndarray, s: float, w_cont: float) -> float:
        rot, pos, u = self.pose(v, rot0, s)
        cl = self.clear(rot, pos, self.cap)
        x = (self.sample_pts @ rot.T + pos)[:, 0]
        side = np.sum(np.maximum(0.0, -x[self.samples < s - 0.02])) + np.sum(np.maximum(0.0, x[self.samples > s + 0.02]))
        pull = 0.0
        if self.target is not None and self.w_target > 0:
            pull = self.w_target * float(np.sum(Rotation.from_matrix(self.target.T @ rot).as_rotvec() ** 2))
        return -20.0 * min(cl, self.cap) + 2.0 * side + w_cont * (np.sum(v[:3] ** 2) + 10.0 * np.sum((u - u0) ** 2)) + pull

    def bend_poses(self, k: int, starts: int = 16) -> list[np.ndarray]:
        """Rotations of free poses with the centreline's corner ``k`` in the opening (the
        part before it past the wall), from random starts."""
        found = []
        target, self.target = self.target, None
        for _ in range(starts):
            rot0 = Rotation.random(random_state=self.rng).as_matrix()
            v0 = np.concatenate([np.zeros(3), self.rng.normal(0, 0.3, 2)])
            r = minimize(self.cost, v0, args=(rot0, np.zeros(2), float(self.arc[k]), 0.0), method="Nelder-Mead", options={"maxiter": 800})
            rot, pos, _ = self.pose(r.x, rot0, float(self.arc[k]))
            if self.clear(rot, pos) >= self.min_clearance:
                found.append(rot)
        self.target = target
        return found

    def aim(self, rot: np.ndarray, s: float, cache: dict[int, list[np.ndarray]]) -> None:
        """Set the target for arc length ``s``: the free pose of the next bend nearest to
        ``rot`` (chosen once per bar), its weight rising from 0 at the bar's start."""
        if self.guide <= 0:
            return
        k = int(np.searchsorted(self.arc, s, side="left"))  # the corner at or after s
        if k <= 0 or k >= len(self.arc) - 1:
            self.target, self.w_target = None, 0.0
            return
        if k not in cache:
            poses = self.bend_poses(k)
            cache[k] = [min(poses, key=lambda r: float(np.linalg.norm(Rotation.from_matrix(r.T @ rot).as_rotvec())))] if poses else []
        self.target = cache[k][0] if cache[k] else None
        self.w_target = self.guide * (s - self.arc[k - 1]) / (self.arc[k] - self.arc[k - 1])

    def first(self) -> tuple[np.ndarray, np.ndarray]:
        """The first pose: the leading tip in the opening, the body behind the wall."""
        best = None
        for _ in range(40):
            rot0 = Rotation.random(random_state=self.rng).as_matrix()
            v0 = np.concatenate([np.zeros(3), self.rng.normal(0, 0.3, 2)])
            r = minimize(self.cost, v0, args=(rot0, np.zeros(2), 0.0, 0.0), method="Nelder-Mead", options={"maxiter": 800, "xatol": 1e-6, "fatol": 1e-9})
            if best is None or r.fun < best[0]:
                best = (r.fun, r.x, rot0)
        assert best is not None
        rot, _, u = self.pose(best[1], best[2], 0.0)
        return rot, u

    def next(self, rot: np.ndarray, u: np.ndarray, s: float) -> tuple[bool, float, np.ndarray, np.ndarray]:
        """A free pose with the centreline point ``s`` in the opening, near ``(rot, u)``:
        ``(found, clearance, rotation, opening coordinates)``."""
        vu = np.arctanh(np.clip(u / self.half, -0.999, 0.999))
        cands = []
        for k in range(8):
            v0 = np.concatenate([np.zeros(3) if k == 0 else self.rng.normal(0, 0.15, 3), vu])
            r = minimize(self.cost, v0, args=(rot, u, s, 0.02), method="Nelder-Mead", options={"maxiter": 600, "xatol": 1e-6, "fatol": 1e-9})
            nrot, npos, nu = self.pose(r.x, rot, s)
            cl = self.clear(nrot, npos)
            cands.append((cl >= self.min_clearance, -float(np.linalg.norm(r.x[:3])), cl, nrot, nu))
            if k == 0 and cl >= self.min_clearance:
                break
        ok, _, cl, nrot, nu = max(cands, key=lambda c: (c[0], c[1]))
        return ok, max(c[2] for c in cands), nrot, nu

    def config(self, rot: np.ndarray, u: np.ndarray, s: float) -> np.ndarray:
        c = point_at(self.pts, self.arc, s)
        pos = self.mid + u[0] * self.e_long + u[1] * self.e_thin - rot @ c
        return np.concatenate([pos, Rotation.from_matrix(rot).as_quat()])


def sweep(
    robot: SShape,
    problem: Problem,
    order: str,
    ds: float,
    rng: np.random.Generator,
    verbose: bool = False,
    min_clearance: float = 0.0015,
    guide: float = 0.0,
) -> list[np.ndarray] | None:
    """The sweep's poses, joined by certified straight edges (an edge that collides is
    split at its middle arc length, up to 4 times), or ``None`` where no free pose was
    found for some ``s``."""
    sw = Sweep(robot, problem, order, rng, min_clearance, guide)
    rot, u = sw.first()
    states = [(0.0, rot, u)]
    s = 0.0
    targets: dict[int, list[np.ndarray]] = {}
    while s < sw.arc[-1]:
        s = min(s + ds, sw.arc[-1])
        sw.aim(rot, s, targets)
        ok, cl, rot, u = sw.next(rot, u, s)
        if not ok:
            if verbose:
                print(f"  {order}: stuck at s = {s:.3f} (clearance {cl:+.4f})", file=sys.stderr)
            return None
        states.append((s, rot, u))

    def join(a: tuple, b: tuple, depth: int) -> list[np.ndarray] | None:
        qa, qb = sw.config(a[1], a[2], a[0]), sw.config(b[1], b[2], b[0])
        if edge_free(robot, problem, qa, qb)[0]:
            return [qb]
        if depth == 0:
            return None
        ok, _, rot, u = sw.next(a[1], a[2], (a[0] + b[0]) / 2)
        if not ok:
            return None
        m = ((a[0] + b[0]) / 2, rot, u)
        left = join(a, m, depth - 1)
        right = join(m, b, depth - 1) if left is not None else None
        return None if left is None or right is None else left + right

    poses = [sw.config(states[0][1], states[0][2], 0.0)]
    for a, b in zip(states[:-1], states[1:], strict=True):
        more = join(a, b, 4)
        if more is None:
            if verbose:
                print(f"  {order}: the edge at s = {a[0]:.3f} collides and could not be split", file=sys.stderr)
            return None
        poses += more
    return poses


def simplify(robot: SShape, problem: Problem, path: np.ndarray, seed: int, shortcuts: int = 200) -> np.ndarray:
    """Fewer, longer edges: from each vertex, the farthest later vertex the certified
    straight edge reaches (doubling, then bisection: an edge that collides somewhere
    is taken to collide farther on too, which only keeps more vertices), then Bi-RRT's
    random shortcuts."""
    out, i, n = [path[0]], 0, len(path)
    while i < n - 1:
        step, good = 1, i + 1
        while i + 2 * step < n and edge_free(robot, problem, path[i], path[i + 2 * step])[0]:
            step *= 2
            good = i + step
        lo, hi = good, min(i + 2 * step, n - 1)
        while hi - lo > 1:
            m = (lo + hi) // 2
            if edge_free(robot, problem, path[i], path[m])[0]:
                lo = m
            else:
                hi = m
        if hi > lo and edge_free(robot, problem, path[i], path[hi])[0]:
            lo = hi
        out.append(path[lo])
        i = lo
    short, _ = BiRRT(robot, seed=seed, shortcut_iters=shortcuts).shortcut(np.array(out), problem, np.random.default_rng(seed))
    return short


def plan(
    robot: SShape,
    problem: Problem,
    ds: float,
    seed: int,
    max_nodes: int,
    verbose: bool = False,
    min_clearance: float = 0.0015,
    tries: int = 1,
    guide: float = 0.0,
) -> tuple[np.ndarray | None, dict]:
    """A path of ``problem`` through its slot, or ``None``: the sweep led by bar A, then by
    bar E, ``tries`` times (each from another random first pose), the first that works."""
    rng = np.random.default_rng(seed)
    info: dict = {}
    for order in ("A", "E") * max(1, tries):
        t0 = time.perf_counter()
        poses = sweep(robot, problem, order, ds, rng, verbose, min_clearance, guide)
        info[f"sweep_{order}_s"] = round(info.get(f"sweep_{order}_s", 0.0) + time.perf_counter() - t0, 1)
        if poses is None:
            continue
        pre, post = poses[0].copy(), poses[-1].copy()
        pre[0] -= 0.08
        post[0] += 0.08
        ends = []
        for a, b in ((problem.start, pre), (post, problem.goal)):
            r = BiRRT(robot, seed=seed, max_nodes=max_nodes).plan(Problem(problem.scene, np.asarray(a), np.asarray(b)))
            ends.append(r)
        if not edge_free(robot, problem, pre, poses[0])[0] or not edge_free(robot, problem, poses[-1], post)[0]:
            info[f"sweep_{order}_backoff"] = "collides"
            continue
        if not all(r.success for r in ends):
            info[f"sweep_{order}_ends"] = [bool(r.success) for r in ends]
            continue
        raw = np.concatenate([ends[0].path, np.array(poses), ends[1].path])  # (Bi-RRT's paths end at pre and start at post)
        info["order"] = order
        info["sweep_poses"] = len(poses)
        t1 = time.perf_counter()
        path = simplify(robot, problem, raw, seed)
        info["simplify_s"] = round(time.perf_counter() - t1, 1)
        info["vertices"] = len(path)
        info["length"] = round(float(path_length(robot, path)), 3)
        info["raw_length"] = round(float(path_length(robot, raw)), 3)
        info["steps"] = len(timed_path(robot, path)) - 1
        return path, info
    return None, info


def demos(args: argparse.Namespace) -> None:
    """Demonstrations of Slot (the scenario as it ships, slots of 2-8 bars) in the file format
    of ``pointplan bc --demos``: training problems ``_demo_index(seed, n, i)`` for ``i`` in
    ``first .. first + problems - 1`` (``n = --demo-n``, the same for every process that
    fills one range), Bi-RRT (``--max-nodes``) for slots of ``--max-bars`` or more and the
    sweep below that or where Bi-RRT fails. The file is rewritten after every solved
    problem and problems already in it are skipped, so a run can stop and go on."""
    from pointplan.learning.bc import _demo_index, load_demos, resample_path, save_demos
    from pointplan.scenes.scenarios import make_scenario

    sc = make_scenario("slot", robot="sshape")
    robot = sc.robot
    out = Path(args.save_demos)
    paths: list[tuple[int, np.ndarray]] = []
    if out.exists():
        d = load_demos(out, sc)
        paths = list(d.paths)
    done = {k for k, _ in paths}
    for i in range(args.first, args.first + args.problems):
        index = _demo_index(args.seed, args.demo_n, i)
        if index in done:
            continue
        p = sc.problem("train", index, seed=args.seed)
        wb = p.scene.__dict__["slot"]["width"] / 0.036
        if wb < args.skip_below:
            print(f"demo {i}: width {wb:.2f} bars, skipped (--skip-below {args.skip_below})", flush=True)
            continue
        t = time.perf_counter()
        path, how = None, "sweep"
        if wb >= args.max_bars:
            res = BiRRT(robot, seed=index, max_nodes=args.max_nodes).plan(p)
            path, how = (res.path if res.success else None), "birrt"
        if path is None:
            path, _ = plan(robot, p, args.ds, index, args.max_nodes, args.verbose, args.min_clearance, args.tries, args.guide)
            how = "sweep"
        good = path is not None and bool(check_path(robot, p, path))
        print(f"demo {i}: width {wb:.2f} bars, {how}, solved {good}, {time.perf_counter() - t:.1f} s", flush=True)
        if good:
            assert path is not None
            paths.append((index, resample_path(robot, path)))
            from pointplan.learning.bc import demos_from_paths

            save_demos(out, sc, demos_from_paths(sc, "train", args.seed, paths), "train", args.seed)


def merge(out: str, files: list[str]) -> None:
    """One demonstration file of several written by ``--save-demos`` (the same seed; a problem
    in more than one keeps its first path)."""
    from pointplan.learning.bc import demos_from_paths, load_demos, save_demos
    from pointplan.scenes.scenarios import make_scenario

    sc = make_scenario("slot", robot="sshape")
    seeds, paths, seen = set(), [], set()
    for f in files:
        with np.load(f, allow_pickle=False) as z:
            seeds.add(int(z["seed"]))
        for k, path in load_demos(f, sc).paths:
            if k not in seen:
                seen.add(k)
                paths.append((k, path))
    if len(seeds) != 1:
        raise SystemExit(f"the files have different seeds: {sorted(seeds)}")
    seed = seeds.pop()
    save_demos(out, sc, demos_from_paths(sc, "train", seed, paths), "train", seed)
    print(f"{out}: {len(paths)} demonstrations from {len(files)} files", file=sys.stderr)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--problems", type=int, default=6)
    ap.add_argument("--min-bars", type=float, default=2.0)
    ap.add_argument("--max-bars", type=float, default=4.0)
    ap.add_argument("--seed", type=int, default=5, help="problem seed (slot_thin_experts.py's default)")
    ap.add_argument("--split", default="train")
    ap.add_argument("--first", type=int, default=0, help="the first workspace index (problems are workspaces first .. first + problems - 1)")
    ap.add_argument("--ds", type=float, default=0.004, help="arc length between sweep poses")
    ap.add_argument("--max-nodes", type=int, default=5000, help="Bi-RRT nodes for each end")
    ap.add_argument("--min-clearance", type=float, default=0.0015, help="clearance (coal) every sweep pose must have")
    ap.add_argument("--guide", type=float, default=0.0, help="pull toward free poses of the next bend found beforehand (weight; 0: off)")
    ap.add_argument("--tries", type=int, default=1, help="rounds of the two sweeps (A first, E first), each from a new first pose")
    ap.add_argument("--only", type=int, nargs="*", help="plan only these of the problems (0-based)")
    ap.add_argument("--verbose", action="store_true")
    ap.add_argument("--save-demos", help="plan Slot's training problems for pointplan bc --demos into this file (see demos())")
    ap.add_argument("--skip-below", type=float, default=0.0, help="with --save-demos: leave slots narrower than this (bars) out")
    ap.add_argument("--merge", nargs="+", help="with --save-demos: write these demonstration files into that one instead of planning")
    ap.add_argument("--demo-n", type=int, default=3000, help="the n of the demonstration indices")
    args = ap.parse_args()
    if args.save_demos and args.merge:
        merge(args.save_demos, args.merge)
        return
    if args.save_demos:
        demos(args)
        return
    sc = SlotScenario(config=SlotConfig(min_width_bars=args.min_bars, max_width_bars=args.max_bars))
    robot = sc.robot
    solved = 0
    problems = [sc.problem(args.split, args.first + i, seed=args.seed) for i in range(args.problems)]
    for i, p in enumerate(problems):
        if args.only is not None and i not in args.only:
            continue
        t = time.perf_counter()
        path, info = plan(robot, p, args.ds, i, args.max_nodes, args.verbose, args.min_clearance, args.tries, args.guide)
        good = path is not None and bool(check_path(robot, p, path))
        solved += good
        wb = p.scene.__dict__["slot"]["width"] / 0.036
        print(f"sweep: width {wb:.2f} bars, solved {good}, {time.perf_counter() - t:.1f} s, {info}", flush=True)
    print(f"sweep: {solved}/{len(problems) if args.only is None else len(args.only)} solved")


if __name__ == "__main__":
    main()
