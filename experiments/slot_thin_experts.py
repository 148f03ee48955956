"""Can a classical planner demonstrate the thin slots of Slot?

Bi-RRT with 50,000 nodes solves none of the test slots under 3 bar thicknesses and 39% of
those of 3-4 (``docs/data/birrt3d/slot_sshape_50k_certified.jsonl``), so behavioural cloning
has no demonstrations there. This plans training problems of 2-4 bars (``SlotConfig``'s
``min_width_bars``/``max_width_bars``, the Slot workspaces' stream) with

- ``ompl``: OMPL's planners (``--planners``, a time limit each, ``--time-limit``);
- ``biased``: pointplan's Bi-RRT with a privileged sampler that draws a share
  (``--share``) of its targets with the body's frame in a box around the slot
  (``+-0.3`` across the wall, ``+-spread`` along it) and a uniform rotation;
- ``aligned``: the same, and the rotation turns one body axis (x, y or z, either sign)
  onto the slot's narrow axis, then spins about it (uniform) and perturbs it
  (``--noise`` rad, normal per axis): the orientations in which one bend of the S lies
  in the slot's plane.

Every solution is re-checked by the evaluator (``check_path``). One line per problem:
slot width in bars, solved, nodes, seconds.

    python experiments/slot_thin_experts.py ompl --planners BKPIECE1 LBKPIECE1 RRTConnect PRM --time-limit 20
    python experiments/slot_thin_experts.py biased --share 0.7 --spread 0.25 --max-nodes 20000
    python experiments/slot_thin_experts.py aligned --share 0.7 --noise 0.05 --max-nodes 20000
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numpy as np
from scipy.spatial.transform import Rotation

from pointplan.evaluation.evaluate import check_path
from pointplan.planners import make_planner
from pointplan.planners.birrt import BiRRT
from pointplan.scenes.scene import Problem
from pointplan.scenes.scenes3d import SlotConfig, SlotMovingScenario

E = np.eye(3)


def biased_sampler(robot, share: float, spread: float) -> Callable:  # type: ignore[no-untyped-def]
    def factory(problem: Problem):  # type: ignore[no-untyped-def]
        c = problem.scene.__dict__["slot"]["center"]
        low, high = problem.scene.low, problem.scene.high

        def draw(rng: np.random.Generator, k: int) -> np.ndarray:
            q = robot.sample_uniform(rng, k, low, high)
            m = rng.random(k) < share
            pos = c + rng.uniform(-1, 1, (k, 3)) * np.array([0.3, spread, spread])
            pos[:, 1:] = np.clip(pos[:, 1:], low[1:], high[1:])
            q[m, :3] = pos[m]
            return q

        return draw

    return factory


def aligned_sampler(robot, share: float, noise: float) -> Callable:  # type: ignore[no-untyped-def]
    def factory(problem: Problem):  # type: ignore[no-untyped-def]
        s = problem.scene.__dict__["slot"]
        c, low, high = s["center"], problem.scene.low, problem.scene.high
        normal = E[3 - s["long_axis"]]  # the slot's narrow axis

        def draw(rng: np.random.Generator, k: int) -> np.ndarray:
            q = robot.sample_uniform(rng, k, low, high)
            m = np.flatnonzero(rng.random(k) < share)
            axes, signs = rng.integers(0, 3, len(m)), rng.choice([-1.0, 1.0], len(m))
            onto = [Rotation.align_vectors([sg * normal], [E[a]])[0] for a, sg in zip(axes, signs)]
            spin = Rotation.from_rotvec(rng.uniform(-np.pi, np.pi, (len(m), 1)) * normal)
            pert = Rotation.from_rotvec(rng.normal(0, noise, (len(m), 3)))
            if len(m):
                q[m, 3:] = np.array([(pert[i] * spin[i] * onto[i]).as_quat() for i in range(len(m))])  # (x, y, z, w)
                q[m, :3] = np.clip(c + rng.uniform(-0.3, 0.3, (len(m), 3)), low, high)
            return q

        return draw

    return factory


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("expert", choices=["ompl", "biased", "aligned"])
    ap.add_argument("--problems", type=int, default=6, help="training problems (default: %(default)s)")
    ap.add_argument("--min-bars", type=float, default=2.0)
    ap.add_argument("--max-bars", type=float, default=4.0)
    ap.add_argument("--seed", type=int, default=5, help="problem seed (default: %(default)s)")
    ap.add_argument("--planners", nargs="+", default=["BKPIECE1", "LBKPIECE1", "RRTConnect", "PRM"])
    ap.add_argument("--time-limit", type=float, default=20.0)
    ap.add_argument("--max-nodes", type=int, default=20000)
    ap.add_argument("--share", type=float, default=0.7)
    ap.add_argument("--spread", type=float, default=0.25)
    ap.add_argument("--noise", type=float, default=0.05)
    args = ap.parse_args()

    sc = SlotMovingScenario(config=SlotConfig(min_width_bars=args.min_bars, max_width_bars=args.max_bars))
    robot = sc.robot
    problems = sc.problems("train", args.problems, seed=args.seed)
    if args.expert == "ompl":
        makers = {f"ompl:{n}": (lambda n=n: make_planner(f"ompl:{n}", robot, seed=0, time_limit=args.time_limit)) for n in args.planners}
    elif args.expert == "biased":
        makers = {"biased": lambda: BiRRT(robot, seed=0, max_nodes=args.max_nodes, sampler=biased_sampler(robot, args.share, args.spread))}
    else:
        makers = {"aligned": lambda: BiRRT(robot, seed=0, max_nodes=args.max_nodes, sampler=aligned_sampler(robot, args.share, args.noise))}
    for name, make in makers.items():
        solved = 0
        for p in problems:
            t = time.perf_counter()
            res = make().plan(p)
            dt = time.perf_counter() - t
            good = bool(res.success and check_path(robot, p, res.path))
            solved += good
            print(f"{name}: width {p.scene.__dict__['slot']['width'] / 0.036:.2f} bars, solved {good}, nodes {res.nodes}, {dt:.1f} s", flush=True)
        print(f"{name}: {solved}/{len(problems)} solved")


if __name__ == "__main__":
    main()
