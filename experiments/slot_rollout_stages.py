"""Where a Slot policy's rollouts fail, against the slot threading expert's template.

For each validation problem the policy is rolled out (the planner, mean action, no escape
unless ``--escape``), the template is placed on the problem's slot, and the rollout is
sorted by the last stage it reached:

- ``approach``: it never came within ``--pos`` (position) and ``--rot`` (degrees) of the
  template's insertion pose (the first pose with the leading bar in the opening);
- ``insertion``: it came there but its frame never got past the wall (x > 0);
- ``exit``: past the wall, but not to the goal;
- ``solved``.

Also reported: at the visited state nearest (in position) to the insertion pose, how far
it was and by how much it was turned, and how many of those turns were 60-120 degrees
(the slot's long axis taken for the other one).

    python experiments/slot_rollout_stages.py runs/bc_slot_local/bc.pt --episodes 50
    python experiments/slot_rollout_stages.py runs/bc_slot_local/bc.pt --episodes 50 --from-approach

With ``--from-approach`` each rollout starts where the expert's approach ends, which
measures the threading alone.
"""

from __future__ import annotations

import argparse
import json

import numpy as np
import torch


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("checkpoint")
    ap.add_argument("--episodes", type=int, default=50)
    ap.add_argument("--env", default="slotmoving", choices=["slot", "slotmoving", "slotwide", "slotclassic"])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--escape", type=int, default=0, help="the planner's escape steps (default: 0, the mean action alone)")
    ap.add_argument("--pos", type=float, default=0.05, help="metres from the insertion pose that count as reaching it")
    ap.add_argument("--rot", type=float, default=20.0, help="degrees from the insertion pose that count as reaching it")
    ap.add_argument(
        "--from-approach",
        action="store_true",
        help="start each rollout at the template's first pose placed on the slot (0.3 before the wall, turned for the threading) instead of the problem's start; slots narrower than the template are left out",
    )
    ap.add_argument("--template", help="the threading template (default: the shipped one)")
    ap.add_argument(
        "--copies",
        action="store_true",
        help="with the template's symmetric copies: --from-approach starts at the approach of the copy turned least from the problem's start, and reaching any copy's insertion pose counts",
    )
    ap.add_argument("--json", help="write the counts and the per-problem rows here")
    args = ap.parse_args()
    torch.set_num_threads(1)
    from tqdm import tqdm

    from pointplan.models.policy import Policy
    from pointplan.planners.policy import PolicyPlanner
    from pointplan.planners.slot_threading import SlotThreading
    from pointplan.robots.sshape import BAR_THICKNESS
    from pointplan.scenes.scenarios import make_scenario
    from pointplan.scenes.scene import Problem

    policy = Policy.from_checkpoint(args.checkpoint)
    sc = make_scenario(args.env, robot="sshape")
    robot = sc.robot
    expert = SlotThreading.load(robot, args.template, copies=args.copies)
    n_copies = 4 if args.copies else 1
    planner = PolicyPlanner(policy, robot=robot, attempts=1, escape=args.escape)
    rows = []
    for p in tqdm(sc.problems("val", args.episodes, seed=args.seed), desc="rollouts", unit="problem"):
        slot = p.scene.__dict__["slot"]
        if args.from_approach:
            if not expert.threads(slot):
                continue
            p = Problem(p.scene, expert.choose(slot, p.start)[0], p.goal, p.tag)
        r = planner.plan(p)
        path = np.asarray(r.path)
        # the insertion pose of each copy (one without --copies); the nearest visit to any
        d, turn = np.full(len(path), np.inf), np.full(len(path), np.inf)
        at_t1 = False
        for k in range(n_copies):
            t1 = expert.place(slot, k)[1]
            dk = np.linalg.norm(path[:, :3] - t1[:3], axis=1)
            tk = np.array([np.degrees(np.linalg.norm(robot.log(q, t1)[3:])) for q in path])
            at_t1 = at_t1 or bool(np.any((dk <= args.pos) & (tk <= args.rot)))
            better = dk < d
            d, turn = np.where(better, dk, d), np.where(better, tk, turn)
        past = bool(np.any(path[:, 0] > 0))
        stage = "solved" if r.success else ("exit" if past else ("insertion" if at_t1 else "approach"))
        j = int(d.argmin())
        rows.append(
            {
                "width_bars": slot["width"] / BAR_THICKNESS,
                "long_axis": int(slot["long_axis"]),
                "stage": stage,
                "nearest_m": float(d[j]),
                "nearest_turn_deg": float(turn[j]),
            }
        )
    counts = {s: sum(r["stage"] == s for r in rows) for s in ("approach", "insertion", "exit", "solved")}
    failed = [r for r in rows if r["stage"] == "approach"]
    summary = {
        "checkpoint": args.checkpoint,
        "env": args.env,
        "episodes": len(rows),
        "escape": args.escape,
        "from_approach": args.from_approach,
        "template": args.template,
        "copies": args.copies,
        "stages": counts,
        "approach_failures_nearest_m_median": float(np.median([r["nearest_m"] for r in failed])) if failed else None,
        "approach_failures_nearest_turn_deg_median": float(np.median([r["nearest_turn_deg"] for r in failed])) if failed else None,
        "approach_failures_turned_60_120_deg": sum(60 <= r["nearest_turn_deg"] <= 120 for r in failed),
    }
    print(json.dumps(summary, indent=1))
    if args.json:
        with open(args.json, "w") as f:
            json.dump({**summary, "rows": rows}, f, indent=1)


if __name__ == "__main__":
    main()
