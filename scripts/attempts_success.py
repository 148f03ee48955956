"""The policy planner with sampled retries (``--attempts``) on validation problems.

A policy whose mean action stalls may still solve a problem with sampled actions; the
planner's ``attempts`` rolls out again from the start with ``tanh(mean + s * std * noise)``
when the mean-action rollout fails. This measures success (every path re-checked by the
evaluator), steps of all attempts, motion checks and time per problem for each attempt
budget, on the validation split (for choosing the budget; the test split is for the end):

    python scripts/attempts_success.py checkpoints/sshape_local_bc_spread.pt --attempts 1 2 4 8
    python scripts/attempts_success.py --robot sphere3d --observation local --env ycb3d
    python scripts/attempts_success.py runs/bc_slotwide_local/bc.pt --env slot --attempts 1 16

In Slot (and its wide-slot stage ``slotwide``) success is also given per slot width, in
bands of one bar thickness.

Without a checkpoint the policy that ships for ``--robot`` and ``--observation`` is used.
"""

from __future__ import annotations

import argparse
import json

import numpy as np
import torch


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("checkpoint", nargs="?", help="policy checkpoint (default: the shipped one)")
    ap.add_argument("--robot", default=None, help="robot (default: the checkpoint's)")
    ap.add_argument("--observation", default=None)
    ap.add_argument("--env", default=None, help="scene id (default: the one the policy was trained in)")
    ap.add_argument("--episodes", type=int, default=200)
    ap.add_argument("--split", default="val", choices=["train", "val"])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--attempts", type=int, nargs="+", default=[1, 2, 4, 8])
    ap.add_argument("--action-noise", type=float, default=1.0)
    ap.add_argument(
        "--escape",
        type=int,
        default=None,
        help="sampled steps after a stall (default: the planner's for the robot; 0: off)",
    )
    ap.add_argument(
        "--escape-tries",
        type=int,
        default=None,
        help="draws per escape step, the furthest free motion taken (default: the robot's; 1: the plain escape)",
    )
    ap.add_argument(
        "--escape-lookahead",
        type=int,
        default=None,
        help="steps of the mean action judging each escape draw (default: the robot's; 0: the draw's own motion)",
    )
    ap.add_argument("--json", help="write the rows here")
    args = ap.parse_args()
    if any(k < 1 for k in args.attempts):
        ap.error("--attempts must be >= 1")
    torch.set_num_threads(1)
    from pointplan.evaluation.evaluate import evaluate
    from pointplan.models.policy import Policy, shipped_checkpoint
    from pointplan.planners.policy import PolicyPlanner
    from pointplan.scenes.scenarios import make_scenario

    ckpt = args.checkpoint or str(shipped_checkpoint(args.robot or "sshape", args.observation))
    policy = Policy.from_checkpoint(ckpt)
    scenario = make_scenario(args.env or policy.env, robot=policy.robot.name)
    problems = scenario.problems(args.split, args.episodes, seed=args.seed)
    escape: object = args.escape
    if args.escape_tries is not None or args.escape_lookahead is not None:
        from dataclasses import replace

        from pointplan.planners.rollout import RolloutOptions

        escape = RolloutOptions(escape=args.escape).escape_for(scenario.robot, args.escape_tries)
        if args.escape_lookahead is not None:
            escape = replace(escape, lookahead=args.escape_lookahead)
    rows = []
    for k in args.attempts:
        planner = PolicyPlanner(policy, robot=scenario.robot, attempts=k, action_noise=args.action_noise, escape=escape)
        rep = evaluate(planner, problems, scenario.robot, progress=False)
        m = rep.metrics()
        row = {
            "attempts": k,
            "success": m["success_rate"],
            "mean_steps": m["nodes_mean"],
            "mean_checks": m["collision_checks_mean"],
            "time_s": m["time_mean_s"],
            "path_length": m["path_length_mean"],
            "claims_disagree": m["planner_claims_disagree"],
        }
        widths = [p.scene.__dict__.get("slot", {}).get("width") for p in problems]
        if all(w is not None for w in widths):
            from pointplan.robots.sshape import BAR_THICKNESS

            band = np.floor(np.asarray(widths) / BAR_THICKNESS).astype(int)
            ok = np.array([r.success for r in rep.records])
            row["by_width"] = {
                f"{b}-{b + 1} bars": [int(ok[band == b].sum()), int((band == b).sum())]
                for b in sorted(set(band.tolist()))
            }
        rows.append(row)
        print(
            f"attempts {k:2d}: {100 * row['success']:5.1f}% of {m['episodes']} {args.split} problems in {scenario.name}, "
            f"{row['mean_steps']:.1f} steps, {row['mean_checks']:.0f} checks, {1000 * row['time_s']:.0f} ms per problem, {row['claims_disagree']} claims disagree",
            flush=True,
        )
        for name, (k_ok, k_n) in row.get("by_width", {}).items():
            print(f"    {name}: {k_ok}/{k_n}", flush=True)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(
                {
                    "checkpoint": ckpt,
                    "escape": args.escape,
                    "escape_tries": args.escape_tries,
                    "escape_lookahead": args.escape_lookahead,
                    "split": args.split,
                    "episodes": args.episodes,
                    "action_noise": args.action_noise,
                    "rows": rows,
                },
                f,
                indent=1,
            )


if __name__ == "__main__":
    main()
