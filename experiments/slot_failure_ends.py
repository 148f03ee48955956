"""Where the oriented S-shape's failed Slot rollouts end: for the validation problems
(both draws of 500) whose opening is ``--min-bars`` to ``--max-bars`` bar thicknesses
wide, each failure's end (``info["end"]``), steps, final frame position and geodesic
distance to the goal, how many of its last steps did not move it at all (frozen) and its
final clearance (the evaluator's exact distance), with the shipped `local` policy through the planner as it is (its
default escape and motion check). A failure still in the opening ends near x = 0; one
past the wall ends at x > 0.1.

    python experiments/slot_failure_ends.py --min-bars 2 --max-bars 2.5
    python experiments/slot_failure_ends.py --min-bars 2.5 --max-bars 100
"""

from __future__ import annotations

import argparse

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--min-bars", type=float, default=2.0)
    ap.add_argument("--max-bars", type=float, default=100.0)
    ap.add_argument("--episodes", type=int, default=500)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    args = ap.parse_args()
    import torch

    torch.set_num_threads(1)
    from pointplan.evaluation.clearance import Clearance
    from pointplan.evaluation.evaluate import evaluate
    from pointplan.models.policy import Policy
    from pointplan.planners.policy import PolicyPlanner
    from pointplan.robots.sshape import BAR_THICKNESS
    from pointplan.scenes.scenarios import make_scenario

    policy = Policy.from_checkpoint("src/pointplan/data/slot_sshape_oriented_local_policy.pt")
    sc = make_scenario("slot", robot=policy.robot.name)
    for seed in args.seeds:
        problems = sc.problems("val", args.episodes, seed=seed)
        bars = [p.scene.__dict__["slot"]["width"] / BAR_THICKNESS for p in problems]
        idx = [i for i, b in enumerate(bars) if args.min_bars <= b < args.max_bars]
        planner = PolicyPlanner(policy, robot=sc.robot)
        report = evaluate(planner, [problems[i] for i in idx], sc.robot, progress=False)
        for i, rec in zip(idx, report.records):
            if rec.success:
                continue
            p = problems[i]
            res = planner.plan(p)
            q = res.path[-1]
            dist = float(sc.robot.distance(q[None], p.goal[None])[0])
            moved = sc.robot.distance(res.path[1:], res.path[:-1])
            frozen = len(moved) - (int(np.flatnonzero(moved > 1e-9)[-1]) + 1 if np.any(moved > 1e-9) else 0)
            clearance = Clearance(sc.robot, p.scene.obstacles)(q)
            print(
                f"draw {seed} problem {i}: {bars[i]:.2f} bars, end {res.info.get('end')} after {len(res.path) - 1} steps "
                f"at {np.round(q[:3], 2)}, {dist:.2f} from the goal at {np.round(p.goal[:3], 2)}, "
                f"{res.info.get('escapes', 0)} escapes, frozen for the last {frozen} steps, clearance {1000 * clearance:.2f} mm",
                flush=True,
            )


if __name__ == "__main__":
    main()
