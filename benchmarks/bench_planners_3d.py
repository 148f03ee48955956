"""3D planning speed and success against OMPL, planners taking turns on the same problems.

For each robot (the sphere with its ``global`` policy, the S-shape with its ``local``
one), the same 3D-Boxes test problems are planned by every planner in turn (the order
rotates from problem to problem, so that a busy machine slows them alike), one thread,
``planner.plan(problem)``; every returned path is re-checked by the evaluator
(:func:`pointplan.evaluation.check_path`), and only accepted paths count as solved.
Prints success, median and mean seconds per query, and each planner's median over
OMPL's (``ompl:RRTConnect`` with pointplan's certified motion checks).

    python benchmarks/bench_planners_3d.py --problems 40 --robots sphere3d,sshape

A planner name ``policy@N`` is the policy planner with N draws per escape step instead of
the robot's default (``--planners policy,policy@8,ompl:RRTConnect`` compares two in one run);
``policy@NlL`` also looks ahead L steps from each draw (``policy@8l0``: by its own motion).
"""

from __future__ import annotations

import argparse
import gc
import re
import time
from dataclasses import replace
from typing import Any

import numpy as np

DEFAULT = "policy,hybrid,hybrid-ompl,ompl:RRTConnect,birrt"


def run_robot(
    robot_name: str, observation: str, planners: list[str], n: int, seed: int, env: str
) -> dict[str, dict[str, Any]]:
    import torch

    from pointplan.evaluation import check_path
    from pointplan.planners import make_planner
    from pointplan.planners.rollout import RolloutOptions
    from pointplan.scenes.scenarios import make_scenario

    torch.set_num_threads(1)
    sc = make_scenario(env, robot=robot_name)
    problems = sc.problems("test", n, seed=seed)
    built = {}
    for name in planners:
        base, _, tries = name.partition("@")  # policy@8: the policy planner with 8 draws per escape step
        kw: dict[str, Any] = {"observation": observation} if base in ("policy", "hybrid", "hybrid-ompl") else {}
        if base.startswith("ompl:"):
            kw["time_limit"] = 10.0
        if tries:
            m = re.fullmatch(r"(\d+)(?:l(\d+))?", tries)
            if base != "policy" or m is None or int(m[1]) < 1:
                raise SystemExit(
                    f"{name!r}: only the policy planner takes @N or @NlL (N >= 1 draws per escape step, L steps of lookahead)"
                )
            kw["escape"] = RolloutOptions().escape_for(sc.robot, int(m[1]))
            if m[2] is not None:
                kw["escape"] = replace(kw["escape"], lookahead=int(m[2]))
        built[name] = make_planner(base, sc.robot, **kw)
    out: dict[str, dict[str, Any]] = {k: {"times": [], "ok": 0} for k in planners}
    prep: list[float] = []
    for i, p in enumerate(problems):
        # a new workspace's collision world and observer point set, timed apart (a user
        # planning many queries in one workspace pays them once)
        t = time.perf_counter()
        _ = p.scene.world
        for pl in built.values():
            # the policy planner's engine, or the hybrids' policy planner's
            engine = getattr(pl, "engine", None) or getattr(getattr(pl, "policy", None), "engine", None)
            if engine is not None and engine.one_robot():
                engine.observer.set_scene(0, p.scene)
        prep.append(time.perf_counter() - t)
        for name in planners[i % len(planners) :] + planners[: i % len(planners)]:
            gc.collect()
            t = time.perf_counter()
            res = built[name].plan(p)
            out[name]["times"].append(time.perf_counter() - t)
            out[name]["ok"] += bool(res.success and check_path(sc.robot, p, res.path))
    out["(workspace preparation)"] = {"times": prep, "ok": -1}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--problems", type=int, default=40, help="test problems per robot (default: %(default)s)")
    ap.add_argument("--seed", type=int, default=2026, help="problem seed (default: %(default)s)")
    ap.add_argument("--env", default="boxes3d", help="3D scenario (default: %(default)s)")
    ap.add_argument("--robots", default="sphere3d,sshape", help="sphere3d and/or sshape (default: %(default)s)")
    ap.add_argument("--planners", default=DEFAULT, help="comma-separated planner names (default: %(default)s)")
    args = ap.parse_args()
    observations = {"sphere3d": "global", "sshape": "local"}
    planners = [s.strip() for s in args.planners.split(",") if s.strip()]
    for robot in [r.strip() for r in args.robots.split(",") if r.strip()]:
        res = run_robot(robot, observations[robot], planners, args.problems, args.seed, args.env)
        ref = float(np.median(res["ompl:RRTConnect"]["times"])) if "ompl:RRTConnect" in res else None
        print(
            f"\n{args.env}, {robot} ({observations[robot]} policy), {args.problems} test problems (seed {args.seed}), one thread, planners taking turns"
        )
        print(f"{'planner':24s} {'solved':>8s} {'median ms':>10s} {'mean ms':>9s} {'median / OMPL':>14s}")
        for name, r in res.items():
            med, mean = 1e3 * float(np.median(r["times"])), 1e3 * float(np.mean(r["times"]))
            ratio = f"{med / (1e3 * ref):.2f}" if ref and r["ok"] >= 0 else "-"
            solved = f"{r['ok']:>4d}/{args.problems:<3d}" if r["ok"] >= 0 else f"{'-':>8s}"
            print(f"{name:24s} {solved} {med:>10.2f} {mean:>9.1f} {ratio:>14s}")


if __name__ == "__main__":
    main()
