"""The policy planner's escape in lockstep (``RolloutEngine.run``: PPO's validation, the
moving-obstacle scenes) against the same planner one problem at a time (``plan``).

    OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 python benchmarks/bench_lockstep_escape.py --robot sshape --scene boxes3d --problems 100

Both run the robot's shipped policy with its default escape on the same validation
problems, from the mean action (no restarts), the compiled rollout off so that both step
through numpy. Each problem's scene is first planned once by an untimed planner (its
cached point pool and obstacle worlds are paid by neither); then the two take turns, the
lockstep batch first on even repeats. Every path is re-checked by ``check_path``. Printed:
wall time per problem of each, their ratio (lockstep / one at a time), success, steps and
how many rollouts escaped.
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
    ap.add_argument("--robot", default="sshape")
    ap.add_argument("--observation", default="local")
    ap.add_argument("--scene", default="boxes3d", help="a 3D scenario (default: %(default)s)")
    ap.add_argument("--problems", type=int, default=100)
    ap.add_argument("--repeats", type=int, default=2, help="turns of each (default: %(default)s)")
    args = ap.parse_args()
    sc = make_scenario(args.scene, robot=args.robot)
    ckpt = shipped_checkpoint(args.robot, args.observation)
    problems = sc.problems("val", args.problems, seed=0)
    planner = PolicyPlanner(ckpt, robot=sc.robot, compiled=False)
    for p in problems:  # warm the scenes' caches
        PolicyPlanner(ckpt, robot=sc.robot, escape=0, compiled=False).plan(p)
    times: dict[str, list[float]] = {"lockstep": [], "one at a time": []}
    results = {}

    def lockstep() -> list:  # type: ignore[type-arg]
        return planner.engine.run(problems)

    def one_at_a_time() -> list:  # type: ignore[type-arg]
        return [planner.plan(p) for p in problems]

    runs = {"lockstep": lockstep, "one at a time": one_at_a_time}
    for r in range(args.repeats):
        order = list(runs) if r % 2 == 0 else list(runs)[::-1]
        for name in order:
            t0 = time.perf_counter()
            results[name] = runs[name]()
            times[name].append((time.perf_counter() - t0) / len(problems))
    for name, res in results.items():
        ok = [bool(check_path(sc.robot, p, r.path)) for p, r in zip(problems, res)]
        claims = sum(o != r.success for o, r in zip(ok, res))
        escaped = sum(r.info.get("escapes", 0) > 0 for r in res)
        steps = np.mean([r.nodes for r in res])
        print(
            f"{name:14s} {1000 * np.median(times[name]):8.1f} ms per problem (median of {args.repeats}), "
            f"solved {sum(ok)}/{len(problems)}, {steps:.1f} steps, {escaped} escaped, {claims} claims disagree"
        )
    ratio = np.median(times["lockstep"]) / np.median(times["one at a time"])
    print(f"lockstep / one at a time: {ratio:.2f} ({sc.name}, {args.robot} {args.observation}, default escape)")


if __name__ == "__main__":
    main()
