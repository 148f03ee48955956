"""Sliding along contacts in Slot's thin openings: where a step's free motion is stopped by
an obstacle, the action is projected onto the motions that do not close any near contact
faster than its clearance (velocity dampers, linearised at the step's start: for every
contact point ``p`` of the body within ``--margin`` of an obstacle, with ``n`` the unit
direction from the body toward the obstacle and ``d`` the distance, ``n . v_p <= d -
dmin``), and the projected action is taken where its free motion goes further. One
geodesic per step, checked like any other (the evaluator re-checks every path).

Contact points: the edges of the body's bars against the obstacle boxes, and the
obstacle boxes' edges against the bars (sampled every centimetre; closed-form point-box
distances). The projection is a small quadratic programme (SLSQP) in action space.

Modes (``--modes``): ``base`` the planner as it is; ``move`` the slide on the step's
chosen action only; ``all`` also on every escape draw and lookahead motion; ``cand`` the
escape's draws as they are plus the projected mean action as one more candidate, judged by
the same lookahead; ``candall`` every draw's projection added as a candidate too.

    python experiments/slide.py --modes base move all
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.optimize import minimize


def edge_points(h: np.ndarray, step: float = 0.01) -> np.ndarray:
    """Points every ``step`` along the 12 edges of a box of half sides ``h`` (its frame)."""
    out = []
    for axis in range(3):
        n = max(2, int(np.ceil(2 * h[axis] / step)) + 1)
        t = np.linspace(-h[axis], h[axis], n)
        o = [k for k in range(3) if k != axis]
        for s1 in (-1, 1):
            for s2 in (-1, 1):
                p = np.zeros((n, 3))
                p[:, axis] = t
                p[:, o[0]] = s1 * h[o[0]]
                p[:, o[1]] = s2 * h[o[1]]
                out.append(p)
    return np.unique(np.concatenate(out).round(9), axis=0)


def point_box(p: np.ndarray, c: np.ndarray, r: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Signed distance of points ``p (N, 3)`` to the box ``(c, r, h)`` and the box's outward
    unit direction toward each point (world)."""
    pl = (p - c) @ r
    cl = np.clip(pl, -h, h)
    diff = pl - cl
    dist = np.linalg.norm(diff, axis=1)
    out = dist > 1e-12
    nl = np.zeros_like(pl)
    nl[out] = diff[out] / dist[out, None]
    d = dist.copy()
    if (~out).any():
        gap = h - np.abs(pl[~out])
        k = np.argmin(gap, axis=1)
        rows = np.flatnonzero(~out)
        d[rows] = -gap[np.arange(len(rows)), k]
        nl[rows, k] = np.sign(pl[rows, k]) + (pl[rows, k] == 0)
    return d, nl @ r.T


class Slider:
    def __init__(self, robot, margin: float, dmin: float) -> None:  # type: ignore[no-untyped-def]
        self.robot, self.margin, self.dmin = robot, margin, dmin
        self.body_pts = [edge_points(h) for h in robot.parts.box_halfs]
        self.scale = np.asarray(robot.action_scale, np.float64)
        self.cache: dict[int, list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]] = {}

    def obstacles(self, world) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:  # type: ignore[no-untyped-def]
        key = id(world)
        if key not in self.cache:
            self.cache = {
                key: [
                    (
                        world.box_c[i],
                        world.box_r[i],
                        world.box_h[i],
                        edge_points(world.box_h[i]) @ world.box_r[i].T + world.box_c[i],
                    )
                    for i in range(world.box_c.shape[0])
                ]
            }
        return self.cache[key]

    def rows(self, world, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # type: ignore[no-untyped-def]
        """Constraint rows ``G a <= h`` at configuration ``q``."""
        rot = self.robot.rotations(q[None])[0]
        pos = self.robot.positions(q[None])[0]
        _, bc, br, bh = self.robot.world_parts(q[None])
        bc, br, bh = bc[0], br[0], bh[0]
        ps, ns, ds = [], [], []
        for oc, orr, oh, opts in self.obstacles(world):
            for b in range(bc.shape[0]):
                pw = self.body_pts[b] @ br[b].T + bc[b]  # body edge points vs the obstacle
                d, n_out = point_box(pw, oc, orr, oh)
                keep = d < self.margin
                ps.append(pw[keep])
                ns.append(-n_out[keep])
                ds.append(d[keep])
                d2, n2 = point_box(opts, bc[b], br[b], bh[b])  # obstacle edge points vs the bar
                keep = d2 < self.margin
                ps.append(opts[keep] - d2[keep, None] * n2[keep])
                ns.append(n2[keep])
                ds.append(d2[keep])
        p = np.concatenate(ps)
        if p.shape[0] == 0:
            return np.zeros((0, 6)), np.zeros(0)
        n = np.concatenate(ns)
        d = np.concatenate(ds)
        gv = n @ rot  # R^T n
        gw = np.cross(p - pos, n) @ rot  # R^T (r x n)
        g = np.concatenate([gv, gw], axis=1) * self.scale
        return g, d - self.dmin

    def project(self, world, q: np.ndarray, a0: np.ndarray) -> np.ndarray:  # type: ignore[no-untyped-def]
        g, h = self.rows(world, q)
        a0 = np.clip(np.asarray(a0, np.float64), -1, 1)
        if g.shape[0] == 0:
            return a0
        res = minimize(
            lambda a: 0.5 * float(np.sum((a - a0) ** 2)),
            np.zeros_like(a0),
            jac=lambda a: a - a0,
            bounds=[(-1.0, 1.0)] * a0.shape[0],
            constraints=[{"type": "ineq", "fun": lambda a: h - g @ a, "jac": lambda a: -g}],
            method="SLSQP",
            options={"maxiter": 100},
        )
        return np.clip(res.x, -1, 1)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--modes", nargs="+", default=["base", "move", "all"])
    ap.add_argument("--episodes", type=int, default=500, help="validation problems drawn")
    ap.add_argument("--max-bars", type=float, default=3.0, help="keep the openings narrower than this (bars)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--margin", type=float, default=0.03)
    ap.add_argument("--dmin", type=float, default=0.0005)
    ap.add_argument("--tries", type=int, default=None, help="escape draws (default: the robot's)")
    args = ap.parse_args()
    import torch

    torch.set_num_threads(1)
    from pointplan.evaluation.evaluate import evaluate
    from pointplan.models.policy import Policy
    from pointplan.planners import rollout as R
    from pointplan.planners.policy import PolicyPlanner
    from pointplan.robots.sshape import BAR_THICKNESS
    from pointplan.scenes.scenarios import make_scenario

    policy = Policy.from_checkpoint("src/pointplan/data/slot_sshape_oriented_local_policy.pt")
    sc = make_scenario("slot", robot=policy.robot.name)
    robot = sc.robot
    problems = sc.problems("val", args.episodes, seed=args.seed)
    chosen = [p for p in problems if p.scene.__dict__["slot"]["width"] / BAR_THICKNESS < args.max_bars]
    slider = Slider(robot, args.margin, args.dmin)
    base_free = R._OneRobot._free_move
    base_move = R._OneRobot.move
    stats = {"slides": 0, "taken": 0}

    def slid(self, q, a):  # type: ignore[no-untyped-def]
        q1, col, n = base_free(self, q, a)
        if not col[0]:
            return q1, col, n
        stats["slides"] += 1
        a2 = slider.project(self.scene.world, q[0], a[0])
        q2, col2, n2 = base_free(self, q, np.asarray(a2, np.float32)[None])
        d1 = float(np.asarray(robot.distance(q1, q))[0])
        d2 = float(np.asarray(robot.distance(q2, q))[0])
        if d2 > d1 + 1e-6:
            stats["taken"] += 1
            return q2, col2, n + n2
        return q1, col, n + n2

    def move_only(self, a, st):  # type: ignore[no-untyped-def]
        self._free_move = lambda q, b: slid(self, q, b)  # type: ignore[method-assign]
        try:
            return base_move(self, a, st)
        finally:
            del self._free_move

    base_furthest = R._OneRobot._furthest

    def furthest(self, obs, q, target):  # type: ignore[no-untyped-def]
        eng = self.engine
        mean = np.asarray(eng._act(obs, q, target, None), np.float64)
        cands = [mean]
        for _ in range(eng.escape.tries):
            cands.append(np.asarray(eng._act(obs, q, target, self._noise(True)), np.float64))
        extra = [slider.project(self.scene.world, q, c) for c in (cands if mode == "candall" else cands[:1])]
        cands = cands[1:] + extra
        best, far = None, -np.inf
        for a in cands:
            d = self._score(a, q, target)
            if d > far:
                best, far = a, d
        stats["taken"] += any(best is e for e in extra)
        stats["slides"] += 1
        return best

    for mode in args.modes:
        R._OneRobot._furthest = furthest if mode.startswith("cand") else base_furthest  # type: ignore[method-assign]
        R._OneRobot._free_move = slid if mode == "all" else base_free  # type: ignore[method-assign]
        R._OneRobot.move = move_only if mode == "move" else base_move  # type: ignore[method-assign]
        stats.update(slides=0, taken=0)
        kw = (
            {}
            if args.tries is None
            else {"escape": R.Escape(steps=10, noise=2.0, still=0.01, tries=args.tries, lookahead=3)}
        )
        planner = PolicyPlanner(policy, robot=robot, compiled=False, **kw)
        t0 = time.perf_counter()
        report = evaluate(planner, chosen, robot, progress=False)
        ok = sum(r.success for r in report.records)
        steps = np.mean([len(r.path) - 1 for r in report.records])
        print(
            f"{mode}: {ok}/{len(chosen)} solved (openings < {args.max_bars} bars, val seed {args.seed}), "
            f"{steps:.1f} steps, slides {stats['slides']} taken {stats['taken']}, {time.perf_counter() - t0:.0f} s",
            flush=True,
        )


if __name__ == "__main__":
    main()
