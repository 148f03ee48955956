"""The dodge among moving obstacles through the planner itself: success of ``PolicyPlanner``
(with the robot's escape) on validation problems of 3D-Dynamic, for each dodge
(docs/results/3d-sshape.md, "Keeping out of the boxes' way"). Each ``--configs`` entry is
``DRAWS:NOISE:LOOKAHEAD`` (``0`` alone: no dodge), for example:

    python experiments/dodge_sweep.py --robot sshape --observation local --configs 0 16:1:1 16:1:2 16:1:3 16:1:4

Every path is re-checked by the evaluator, against the boxes where they really are
(``claims disagree``).
"""

from __future__ import annotations

import argparse
import json
import time


def parse_config(text: str):  # type: ignore[no-untyped-def]
    from pointplan.planners.rollout import DODGE_OFF, Dodge

    if text == "0":
        return DODGE_OFF
    parts = text.split(":")
    if len(parts) != 3:
        raise argparse.ArgumentTypeError(f"a dodge is DRAWS:NOISE:LOOKAHEAD or 0, not {text!r}")
    try:
        return Dodge(draws=int(parts[0]), noise=float(parts[1]), lookahead=int(parts[2]))
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from e


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("checkpoint", nargs="?", help="policy checkpoint (default: the shipped one)")
    ap.add_argument("--robot", default="sshape")
    ap.add_argument("--observation", default=None)
    ap.add_argument("--env", default="dynamic3d")
    ap.add_argument("--episodes", type=int, default=200)
    ap.add_argument("--val-seed", type=int, default=0, help="which draw of validation problems")
    ap.add_argument("--configs", type=parse_config, nargs="+", required=True, help="dodges, DRAWS:NOISE:LOOKAHEAD or 0")
    ap.add_argument("--json", help="write the rows here")
    args = ap.parse_args()
    import torch

    torch.set_num_threads(1)
    from pointplan.evaluation.evaluate import evaluate
    from pointplan.models.policy import Policy, shipped_checkpoint
    from pointplan.planners.policy import PolicyPlanner
    from pointplan.scenes.scenarios import make_scenario

    ckpt = args.checkpoint or str(shipped_checkpoint(args.robot, args.observation))
    policy = Policy.from_checkpoint(ckpt)
    scenario = make_scenario(args.env, robot=policy.robot.name)
    problems = scenario.problems("val", args.episodes, seed=args.val_seed)
    rows = []
    for dodge in args.configs:
        planner = PolicyPlanner(policy, robot=scenario.robot, dodge=dodge)
        t0 = time.perf_counter()
        report = evaluate(planner, problems, scenario.robot, progress=False)
        m = report.metrics()
        row = {
            "dodge": {"draws": dodge.draws, "noise": dodge.noise, "lookahead": dodge.lookahead},
            "escape": str(planner.escape),
            "success": m["success_rate"],
            "mean_steps": m["nodes_mean"],
            "claims_disagree": m["planner_claims_disagree"],
            "wall_s": time.perf_counter() - t0,
        }
        rows.append(row)
        print(
            f"{dodge}: {100 * row['success']:5.1f}% of {m['episodes']} val problems (draw {args.val_seed}) in "
            f"{scenario.name}, {row['mean_steps']:.1f} steps, {row['claims_disagree']} claims disagree, "
            f"{row['wall_s']:.0f} s",
            flush=True,
        )
    if args.json:
        with open(args.json, "w") as f:
            json.dump(
                {
                    "checkpoint": ckpt,
                    "env": scenario.name,
                    "episodes": args.episodes,
                    "val_seed": args.val_seed,
                    "rows": rows,
                },
                f,
                indent=1,
            )


if __name__ == "__main__":
    main()
