"""S-shape paths read as linear translation + slerp rotation (OMPL's, MoveIt's reading).

Plans 3D-Boxes test problems with Bi-RRT and with the shipped ``local`` policy, keeps the
paths the evaluator certifies (as pointplan's screw motions), and counts how many are
not free under linear + slerp interpolation
(:func:`pointplan.evaluation.interpolation.check_linear_slerp`), then how many are free
under both readings after :func:`~pointplan.evaluation.interpolation.for_linear_slerp`,
with the waypoints it added and its time per path.

    python benchmarks/bench_linear_slerp.py --problems 30
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--problems", type=int, default=30, help="3D-Boxes test problems (default: %(default)s)")
    ap.add_argument("--seed", type=int, default=2026)
    args = ap.parse_args()

    from pointplan.evaluation import check_path
    from pointplan.evaluation.interpolation import check_linear_slerp, for_linear_slerp
    from pointplan.planners import make_planner
    from pointplan.scenes.scenarios import make_scenario

    sc = make_scenario("boxes3d", robot="sshape")
    problems = sc.problems("test", args.problems, seed=args.seed)
    for name, kw in (("birrt", {}), ("policy", {"observation": "local"})):
        planner = make_planner(name, sc.robot, **kw)
        n = bad = fixed = 0
        added, secs = [], []
        for p in problems:
            res = planner.plan(p)
            if not (res.success and check_path(sc.robot, p, res.path)):
                continue
            n += 1
            bad += not check_linear_slerp(sc.robot, p, res.path)[0]
            t = time.perf_counter()
            path = for_linear_slerp(sc.robot, p, res.path)
            secs.append(time.perf_counter() - t)
            fixed += bool(check_linear_slerp(sc.robot, p, path)[0] and check_path(sc.robot, p, path))
            added.append(len(path) - len(res.path))
        print(
            f"{name}: {n} certified paths, {bad} not free read as linear + slerp; after for_linear_slerp {fixed}/{n} free under both, "
            f"{np.mean(added):.1f} waypoints added on average, median {1e3 * np.median(secs):.0f} ms per path"
        )


if __name__ == "__main__":
    main()
