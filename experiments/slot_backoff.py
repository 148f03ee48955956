"""Backing off where every escape draw is refused, in Slot: the oriented S-shape's shipped
`local` policy through the planner (its default escape and motion check), with the
escape's back-off (``Escape.backoff``) set to each ``--back``: at an escape step whose
draws all fail to move the robot (the body wedged 0.1-0.5 mm from a wall), the step heads
back to the latest pose of its path more than that far away (a geodesic move, checked
like any other). ``--back 0``: no back-off. ``--problems frozen``: the 24 validation
problems (of twice 500) that end frozen in an opening without it; ``all``: the 500 of
``--seed``. (First measured by patching the numpy rollout; the planner has it since.)

    python experiments/slot_backoff.py --problems frozen --back 0 0.03 0.1
    python experiments/slot_backoff.py --problems all --seed 0 --back 0 0.03
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace

#: the validation problems whose rollouts end frozen in an opening (experiments/slot_failure_ends.py)
FROZEN = {
    0: [32, 119, 181, 182, 188, 222, 306, 343, 387, 489, 428],
    1: [32, 181, 182, 188, 216, 222, 343, 387, 407, 422, 487, 47, 325],
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--problems", choices=["frozen", "all"], default="frozen")
    ap.add_argument("--seed", type=int, default=0, help="with --problems all: which draw of 500 validation problems")
    ap.add_argument("--back", type=float, nargs="+", default=[0.0, 0.03])
    args = ap.parse_args()
    import torch

    torch.set_num_threads(1)
    from pointplan.evaluation.evaluate import evaluate
    from pointplan.models.policy import Policy
    from pointplan.planners.policy import PolicyPlanner
    from pointplan.planners.rollout import ESCAPE_DEFAULTS
    from pointplan.scenes.scenarios import make_scenario

    policy = Policy.from_checkpoint("src/pointplan/data/slot_sshape_oriented_local_policy.pt")
    sc = make_scenario("slot", robot=policy.robot.name)
    robot = sc.robot
    if args.problems == "frozen":
        problems = [sc.problems("val", 500, seed=s)[i] for s, ii in FROZEN.items() for i in ii]
    else:
        problems = sc.problems("val", 500, seed=args.seed)
    for back in args.back:
        esc = replace(ESCAPE_DEFAULTS["sshape-oriented"], backoff=back)
        t0 = time.perf_counter()
        report = evaluate(PolicyPlanner(policy, robot=robot, escape=esc), problems, robot, progress=False)
        solved = sum(bool(r.success) for r in report.records)
        print(
            f"back {back}: {solved} of {len(problems)} ({args.problems}"
            + (f", seed {args.seed}" if args.problems == "all" else "")
            + f"), {report.metrics()['planner_claims_disagree']} claims disagree, {time.perf_counter() - t0:.0f} s",
            flush=True,
        )


if __name__ == "__main__":
    main()
