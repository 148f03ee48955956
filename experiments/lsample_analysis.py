"""Where learned sampling's nodes go (docs/results/baselines-mpnet-lsample.md).

1. Per problem, on the test problems (the ones `pointplan eval` plans, same seeds): nodes of
   Bi-RRT against lsample-0.5 / lsample-0.9 (percentiles; problems better or worse by more
   than 50 nodes).
2. On validation problems: Bi-RRT with an *oracle* sampler that draws a fraction lambda of
   its targets from a known solution (a Bi-RRT path planned with another seed, resampled by
   arc length, plus Gaussian noise): what a perfect learned sampler could save.

    OMP_NUM_THREADS=1 python experiments/lsample_analysis.py --test 400 --val 200
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from pointplan.learning.lsample import resample_by_length
from pointplan.planners import BiRRT, make_planner
from pointplan.scenes.scenarios import Narrow2DScenario


def per_problem(n: int) -> dict[str, object]:
    sc = Narrow2DScenario()
    problems = sc.problems("test", n, seed=0)
    nodes = {}
    for name in ("birrt", "lsample-0.5", "lsample-0.9"):
        planner = make_planner(name, sc.robot, seed=0, max_nodes=20000)
        nodes[name] = np.array([planner.plan(p).nodes for p in problems])
    base = nodes["birrt"]
    out: dict[str, object] = {}
    for name, x in nodes.items():
        row = {
            "mean": float(x.mean()),
            "median": float(np.median(x)),
            "p90": float(np.percentile(x, 90)),
            "p99": float(np.percentile(x, 99)),
            "max": int(x.max()),
        }
        if name != "birrt":
            row["worse_by_50"] = int(np.sum(x - base > 50))
            row["better_by_50"] = int(np.sum(base - x > 50))
            row["mean_without_worst_5"] = float(np.sort(x)[:-5].mean())
        out[name] = row
    out["birrt"]["mean_without_worst_5"] = float(np.sort(base)[:-5].mean())  # type: ignore[index]
    return out


def oracle(n: int) -> dict[str, object]:
    sc = Narrow2DScenario()
    robot = sc.robot
    problems = sc.problems("val", n, seed=0)
    known = {id(p): resample_by_length(BiRRT(robot, seed=123).plan(p).path, 0.005) for p in problems}

    def sampler(lam: float, noise: float) -> object:
        def factory(problem: object) -> object:
            path = known[id(problem)]
            low, high = problem.scene.low, problem.scene.high  # type: ignore[attr-defined]

            def draw(rng: np.random.Generator, k: int) -> np.ndarray:
                u = robot.sample_uniform(rng, k, low, high)
                m = rng.random(k) < lam
                u[m] = np.clip(path[rng.integers(0, len(path), int(m.sum()))] + rng.normal(0.0, noise, (int(m.sum()), 2)), low, high)
                return u

            return draw

        return factory

    out: dict[str, object] = {}
    for lam, noise in ((0.0, 0.0), (0.5, 0.0), (0.9, 0.0), (0.5, 0.03), (0.9, 0.03)):
        planner = BiRRT(robot, seed=0, max_nodes=20000, sampler=sampler(lam, noise))  # type: ignore[arg-type]
        res = [planner.plan(p) for p in problems]
        nodes = np.array([r.nodes for r in res])
        out[f"lambda {lam}, noise {noise}"] = {
            "success": float(np.mean([r.success for r in res])),
            "nodes_mean": float(nodes.mean()),
            "nodes_median": float(np.median(nodes)),
            "checks_mean": float(np.mean([r.collision_checks for r in res])),
        }
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--test", type=int, default=400, help="test problems for the per-problem comparison (0: skip)")
    ap.add_argument("--val", type=int, default=200, help="validation problems for the oracle sampler (0: skip)")
    ap.add_argument("--json", help="write the results here")
    args = ap.parse_args()
    res: dict[str, object] = {}
    if args.test:
        res["per_problem_test"] = per_problem(args.test)
    if args.val:
        res["oracle_val"] = oracle(args.val)
    text = json.dumps(res, indent=1)
    print(text)
    if args.json:
        with open(args.json, "w") as f:
            f.write(text + "\n")


if __name__ == "__main__":
    main()
