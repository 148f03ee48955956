"""The sphere's policy planner with its default escape: compiled rollout with the hand-over
to numpy at the first escape, against the numpy rollout from the start (``compiled=False``).

    OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 python benchmarks/bench_escape_compiled.py --problems 400

Each problem is first planned once by an untimed planner, so that the scene's point pool
(sampled once per scene and kept with it, about 4 ms) is paid by neither timed planner;
then the two take turns, the first of the pair alternating from problem to problem. Every
path is re-checked by ``check_path``. Printed: time per problem (mean / median, ms, wall
time), success, steps, how many rollouts escaped and the ratio numpy / compiled.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from pointplan.evaluation import check_path
from pointplan.models.policy import shipped_checkpoint
from pointplan.planners.policy import PolicyPlanner
from pointplan.scenes.scenarios import make_scenario


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--problems", type=int, default=400)
    ap.add_argument("--scene", default="boxes3d", help="a 3D scenario (default: %(default)s)")
    ap.add_argument(
        "--observation",
        default="global",
        choices=["global"],
        help="the point-set observer (the ray-cast one is not compiled)",
    )
    ap.add_argument("--split", default="val")
    args = ap.parse_args()
    sc = make_scenario(args.scene, robot="sphere3d")
    ckpt = shipped_checkpoint("sphere3d", args.observation)
    warm = PolicyPlanner(ckpt, robot=sc.robot, escape=0, compiled=False)
    planners = {
        "compiled": PolicyPlanner(ckpt, robot=sc.robot),
        "numpy": PolicyPlanner(ckpt, robot=sc.robot, compiled=False),
    }
    probs = sc.problems(args.split, args.problems, seed=0)
    for pl in planners.values():  # numba's first call and the planners' set-up
        pl.plan(sc.problems("train", 1, seed=0)[0])
    times: dict[str, list[float]] = {k: [] for k in planners}
    results: dict[str, list] = {k: [] for k in planners}
    names = list(planners)
    for i, p in enumerate(probs):
        warm.plan(p)
        for name in names if i % 2 == 0 else names[::-1]:
            t = time.perf_counter()
            r = planners[name].plan(p)
            times[name].append(time.perf_counter() - t)
            results[name].append(r)
    same = sum(
        a.success == b.success and a.path.shape == b.path.shape and np.allclose(a.path, b.path, atol=1e-5)
        for a, b in zip(results["compiled"], results["numpy"], strict=True)
    )
    print(
        f"{args.scene}, sphere3d {args.observation}, {len(probs)} {args.split} problems; escape {planners['compiled'].escape}"
    )
    for name in names:
        ts = np.array(times[name]) * 1e3
        res = results[name]
        ok = [bool(check_path(sc.robot, p, r.path)) and r.success for p, r in zip(probs, res, strict=True)]
        print(
            f"{name:9s} {ts.mean():6.2f} / {np.median(ts):5.2f} ms (mean / median)  success {np.mean(ok):.3f}  "
            f"steps {np.mean([r.nodes for r in res]):5.1f}  escaped {sum(r.info.get('escapes', 0) > 0 for r in res)}"
        )
    print(
        f"numpy / compiled: {np.mean(times['numpy']) / np.mean(times['compiled']):.2f}x (mean), "
        f"{np.median(times['numpy']) / np.median(times['compiled']):.2f}x (median); same paths {same}/{len(probs)}"
    )


if __name__ == "__main__":
    main()
