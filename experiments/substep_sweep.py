"""The motion check's sub-step in the planner: success of ``PolicyPlanner`` on validation
problems with each ``--substeps`` value (the largest sub-step of a checked move, geodesic
distance; the environments train with 0.01). The check grows the body by half a
sub-step's sweep, so a finer sub-step certifies moves that pass closer to an obstacle;
in Slot's thinnest openings the S-shape has 1-2 mm to spare. ``--max-bars`` keeps Slot's
openings under that many bar thicknesses. Every path is re-checked by the evaluator
(``claims disagree``), whose check does not depend on the sub-step.

    python experiments/substep_sweep.py src/pointplan/data/slot_sshape_oriented_local_policy.pt --env slot --max-bars 3
    python experiments/substep_sweep.py --robot sshape --observation local --env boxes3d --substeps 0.01 0.005
"""

from __future__ import annotations

import argparse
import json
import time


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("checkpoint", nargs="?", help="policy checkpoint (default: the shipped one)")
    ap.add_argument("--robot", default="sshape")
    ap.add_argument("--observation", default=None)
    ap.add_argument("--env", default=None, help="scene id (default: the one the policy was trained in)")
    ap.add_argument("--substeps", type=float, nargs="+", default=[0.01, 0.005, 0.0025])
    ap.add_argument("--episodes", type=int, default=500)
    ap.add_argument("--val-seed", type=int, default=0, help="which draw of validation problems")
    ap.add_argument("--max-bars", type=float, default=None, help="Slot: only openings under this many bars")
    ap.add_argument("--json", help="write the rows here")
    args = ap.parse_args()
    import torch

    torch.set_num_threads(1)
    from escape_sweep import by_width, policy_and_problems  # type: ignore[import-not-found]

    from pointplan.evaluation.evaluate import evaluate
    from pointplan.planners.policy import PolicyPlanner
    from pointplan.robots.sshape import BAR_THICKNESS

    policy, ckpt, scenario, problems = policy_and_problems(args)
    slot = "slot" in problems[0].scene.__dict__
    if args.max_bars is not None:
        if not slot:
            ap.error("--max-bars: the scene has no slot")
        problems = [p for p in problems if p.scene.__dict__["slot"]["width"] / BAR_THICKNESS < args.max_bars]
    rows = []
    for s in args.substeps:
        planner = PolicyPlanner(policy, robot=scenario.robot, substep=s)
        t0 = time.perf_counter()
        report = evaluate(planner, problems, scenario.robot, progress=False)
        m = report.metrics()
        ok = [bool(r.success) for r in report.records]
        row = {
            "substep": s,
            "solved": int(sum(ok)),
            "problems": len(ok),
            "mean_steps": m["nodes_mean"],
            "collision_checks_mean": m.get("collision_checks_mean"),
            "claims_disagree": m["planner_claims_disagree"],
            "wall_s": time.perf_counter() - t0,
        }
        if slot:
            row["by_width_bars"] = by_width([p.scene.__dict__["slot"]["width"] for p in problems], ok)
        rows.append(row)
        print(
            f"substep {s}: {row['solved']}/{row['problems']} val problems (draw {args.val_seed}) in {scenario.name}, "
            f"{row['mean_steps']:.1f} steps, {row['claims_disagree']} claims disagree, {row['wall_s']:.0f} s"
            + ("".join(f"; {k} bars {v[0]}/{v[1]}" for k, v in row["by_width_bars"].items()) if slot else ""),
            flush=True,
        )
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"checkpoint": ckpt, "env": scenario.name, "val_seed": args.val_seed, "rows": rows}, f, indent=1)


if __name__ == "__main__":
    main()
