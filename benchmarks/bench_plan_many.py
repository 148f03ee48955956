"""Many queries at once: ``plan_many`` (one by one through the compiled or one-robot
rollout where the observer has one, else the rollout engine's lockstep stepper: one
batched network call and one batched motion check per step for all problems) against
``plan`` in a loop, the hybrid in a loop (the policy, then Bi-RRT where it fails) and
OMPL's RRTConnect in a loop, planners taking turns in blocks of problems; queries per
second of wall time, one thread. Every returned path is re-checked by the evaluator and
only accepted ones count as solved. Each workspace's collision world and the policy's view
of it (its point set, or the boxes its rays hit) are built before the turns, for all
planners alike (a user planning many queries in one workspace pays them once).

    python benchmarks/bench_plan_many.py --env boxes3d --robot sphere3d --problems 400 --block 100
"""

from __future__ import annotations

import argparse
import time


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--env", default="boxes3d", help="scenario (default: %(default)s)")
    ap.add_argument("--robot", default="sphere3d", help="robot (default: %(default)s)")
    ap.add_argument("--observation", default=None, help="the policy's observation (default: the robot's)")
    ap.add_argument("--problems", type=int, default=400, help="test problems (default: %(default)s)")
    ap.add_argument("--block", type=int, default=100, help="problems per turn (default: %(default)s)")
    ap.add_argument("--seed", type=int, default=2026)
    args = ap.parse_args()

    import torch

    from pointplan.evaluation import check_path
    from pointplan.planners import make_planner
    from pointplan.scenes.scenarios import make_scenario

    torch.set_num_threads(1)
    sc = make_scenario(args.env, robot=args.robot) if sc_needs_robot(args.env) else make_scenario(args.env)
    robot = sc.robot
    problems = sc.problems("test", args.problems, seed=args.seed)
    policy = make_planner("policy", robot, observation=args.observation)
    hybrid = make_planner("hybrid", robot, observation=args.observation)
    observer = policy.engine.observer
    for p in problems:  # each workspace's collision world and what the policy sees, built once for all
        _ = p.scene.world
        observer.set_scene(0, p.scene)  # (a point set is cached in the scene for every planner)
        if hasattr(observer, "ray_world"):
            observer.ray_world(p.scene)
    runs = {
        "policy.plan_many": lambda ps: policy.plan_many(ps),
        "policy.plan (loop)": lambda ps: [policy.plan(p) for p in ps],
        "hybrid (loop)": lambda ps: [hybrid.plan(p) for p in ps],
    }
    try:
        ompl = make_planner("ompl:RRTConnect", robot, time_limit=10.0)
        runs["ompl:RRTConnect (loop)"] = lambda ps: [ompl.plan(p) for p in ps]
    except ImportError:
        pass
    for run in runs.values():  # warm up: compiled code loaded, first calls made, before any timing
        run(problems[:2])
    wall = {k: 0.0 for k in runs}
    ok = {k: 0 for k in runs}
    names = list(runs)
    for b, s in enumerate(range(0, len(problems), args.block)):
        block = problems[s : s + args.block]
        for name in names[b % len(names) :] + names[: b % len(names)]:
            t = time.perf_counter()
            res = runs[name](block)
            wall[name] += time.perf_counter() - t
            ok[name] += sum(bool(r.success and check_path(robot, p, r.path)) for p, r in zip(block, res))
    print(
        f"{args.env}, {robot.name}, {len(problems)} test problems (seed {args.seed}) in blocks of {args.block}, one thread"
    )
    print(f"{'planner':26s} {'solved':>9s} {'queries/s':>10s}")
    for name in names:
        print(f"{name:26s} {ok[name]:>4d}/{len(problems):<4d} {len(problems) / wall[name]:>10.1f}")


def sc_needs_robot(env: str) -> bool:
    return env != "narrow2d"


if __name__ == "__main__":
    main()
