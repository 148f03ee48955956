"""How much 3D-Dynamic's motion law matters to a policy trained in 3D-Boxes.

The paper says only that each box's placement is interpolated between two sampled ones.
pointplan's ``dynamic3d`` moves every box there and back over the 80-step horizon; read
as one way, the box reaches its second placement at the horizon (half the speed). This
rolls the shipped policy (or ``--checkpoint``) out on validation problems drawn under each
period (one attempt, the planner's escape for the robot; every success re-checked by the
evaluator in time) and prints the success and how often the planner's claim disagreed:

    python experiments/dynamic_motion_law.py --robot sshape --observation local --periods 80 160
"""

from __future__ import annotations

import argparse


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--robot", default="sshape")
    ap.add_argument("--observation", default=None)
    ap.add_argument("--checkpoint", default=None, help="policy checkpoint (default: the shipped one)")
    ap.add_argument("--periods", type=int, nargs="+", default=[80, 160], help="steps of one there-and-back cycle")
    ap.add_argument("--episodes", type=int, default=200)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    import torch

    torch.set_num_threads(1)
    from pointplan.evaluation.evaluate import evaluate
    from pointplan.models.policy import Policy, shipped_checkpoint
    from pointplan.planners.policy import PolicyPlanner
    from pointplan.scenes.scenes3d import Dynamic3DScenario

    policy = Policy.from_checkpoint(args.checkpoint or str(shipped_checkpoint(args.robot, args.observation)))
    for period in args.periods:
        scenario = Dynamic3DScenario(policy.robot.name, period=period)
        problems = scenario.problems("val", args.episodes, seed=args.seed)
        report = evaluate(PolicyPlanner(policy, robot=scenario.robot), problems, scenario.robot, progress=False)
        m = report.metrics()
        print(
            f"period {period}: {100 * m['success_rate']:.1f}% of {m['episodes']} validation problems, "
            f"{m['nodes_mean']:.1f} steps, {m['planner_claims_disagree']} claims disagree",
            flush=True,
        )


if __name__ == "__main__":
    main()
