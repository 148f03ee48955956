"""The dodge among moving boxes, seen: one validation problem of 3D-Dynamic rolled out by
the planner twice, without the dodge (hit by a box) and with it (at the goal), as two GIFs.

The problem is the first of the validation problems (seed 0, in order) where the rollout
without the dodge is crushed and the one with it is certified by the evaluator:

    python scripts/dodge_gif.py --robot sshape --observation local -o docs/img/dodge_sshape
"""

from __future__ import annotations

import argparse
import sys


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--robot", default="sshape")
    ap.add_argument("--observation", default="local")
    ap.add_argument("--tries", type=int, default=100, help="validation problems to look through (default: 100)")
    ap.add_argument("-o", "--output", required=True, help="prefix: writes PREFIX_off.gif and PREFIX_on.gif")
    args = ap.parse_args()
    import torch

    torch.set_num_threads(1)
    from pointplan.evaluation.evaluate import check_path
    from pointplan.models.policy import Policy, shipped_checkpoint
    from pointplan.planners.policy import PolicyPlanner
    from pointplan.planners.rollout import DODGE_DEFAULT, DODGE_OFF
    from pointplan.scenes.scenarios import make_scenario
    from pointplan.viz.plot3d import render_rollout_gif

    policy = Policy.from_checkpoint(shipped_checkpoint(args.robot, args.observation))
    scenario = make_scenario("dynamic3d", robot=policy.robot.name)
    robot = scenario.robot
    off = PolicyPlanner(policy, robot=robot, dodge=DODGE_OFF)
    on = PolicyPlanner(policy, robot=robot, dodge=DODGE_DEFAULT)
    for problem in scenario.problems("val", args.tries, seed=0):
        a = off.plan(problem)
        if a.info.get("end") != "crushed":
            continue
        b = on.plan(problem)
        if not (b.success and check_path(robot, problem, b.path)):
            continue
        for name, res in (("off", a), ("on", b)):
            out = f"{args.output}_{name}.gif"
            render_rollout_gif(problem, robot, res.path, out, obstacles_at=problem.scene.obstacles_at)
            print(f"{problem.tag}: dodge {name}, {len(res.path) - 1} steps, {res.info.get('end', 'goal')} -> {out}")
        return
    sys.exit(f"none of the first {args.tries} validation problems is crushed without the dodge and solved with it")


if __name__ == "__main__":
    main()
