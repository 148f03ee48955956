"""A Slot policy through a thin and through a wide slot: two GIFs and a picture of both.

For each width band (``--thin`` and ``--wide``, in bars of 0.036) the policy is rolled out
by the planner (its escape and greedy goal test, one attempt) on the validation problems of
that band in order, from the problem's start; the first solved rollout is drawn. Where none
of ``--tries`` is solved from the start, the rollouts start instead at the slot threading
template's approach pose (0.3 before the wall, turned for the threading; the title says
so), as ``experiments/slot_rollout_stages.py --from-approach`` does. Every drawn path is
certified by the evaluator's ``check_path``.

    python scripts/slot_gifs.py src/pointplan/data/slotmoving_sshape_local_policy.pt --env slotmoving -o docs/img/slot_policy
    python scripts/slot_gifs.py checkpoints/slotclassic_local_ppo_best.pt --env slotclassic -o docs/img/slotclassic_policy
"""

from __future__ import annotations

import argparse
import sys

import numpy as np
import torch


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("checkpoint")
    ap.add_argument(
        "-o", "--output", required=True, help="prefix: writes PREFIX_thin.gif, PREFIX_wide.gif and PREFIX.png"
    )
    ap.add_argument(
        "--thin",
        nargs=2,
        type=float,
        default=[2.0, 3.0],
        metavar=("LOW", "HIGH"),
        help="the thin band, bars (default: 2 3)",
    )
    ap.add_argument(
        "--wide",
        nargs=2,
        type=float,
        default=[6.0, 8.0],
        metavar=("LOW", "HIGH"),
        help="the wide band, bars (default: 6 8)",
    )
    ap.add_argument(
        "--tries",
        type=int,
        default=40,
        help="validation problems of a band rolled out from their start before the approach pose is used",
    )
    ap.add_argument("--escape", type=int, default=10)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--env", default="slot", choices=["slot", "slotmoving", "slotclassic"], help="the Slot scene (default: slot)"
    )
    args = ap.parse_args()
    torch.set_num_threads(1)

    from pointplan.evaluation.evaluate import check_path, timed_path
    from pointplan.models.policy import Policy
    from pointplan.planners.policy import PolicyPlanner
    from pointplan.planners.slot_threading import SlotThreading
    from pointplan.robots.sshape import BAR_THICKNESS
    from pointplan.scenes.scenarios import make_scenario
    from pointplan.scenes.scene import Problem
    from pointplan.viz.plot3d import render_grid_3d, render_rollout_gif

    policy = Policy.from_checkpoint(args.checkpoint)
    sc = make_scenario(args.env, robot=policy.robot.name)  # sshape, or sshape-oriented
    robot = sc.robot
    planner = PolicyPlanner(policy, robot=robot, attempts=1, escape=args.escape)
    expert = SlotThreading.load(robot)

    def band(low: float, high: float) -> list[Problem]:
        out = []
        for k in range(5000):
            p = sc.problem("val", k, seed=args.seed)
            if low <= p.scene.__dict__["slot"]["width"] / BAR_THICKNESS < high:
                out.append(p)
                if len(out) == args.tries:
                    break
        return out

    def solved(problems: list[Problem], from_approach: bool) -> tuple[Problem, np.ndarray, int] | None:
        for i, p in enumerate(problems):
            slot = p.scene.__dict__["slot"]
            if from_approach:
                if not expert.threads(slot):
                    continue
                p = Problem(p.scene, expert.place(slot)[0], p.goal, p.tag)
            r = planner.plan(p)
            if r.success and check_path(robot, p, np.asarray(r.path)):
                return p, np.asarray(r.path), i + 1
        return None

    chosen, titles = [], []
    for name, (low, high) in (("thin", args.thin), ("wide", args.wide)):
        problems = band(low, high)
        found, where = solved(problems, False), "from the start"
        if found is None:
            found, where = solved(problems, True), "from the approach pose"
        if found is None:
            print(
                f"{name}: no solved rollout among {len(problems)} problems of {low}-{high} bars, from the start or the approach pose",
                file=sys.stderr,
            )
            continue
        p, path, tried = found
        w = p.scene.__dict__["slot"]["width"] / BAR_THICKNESS
        steps = len(path) - 1
        title = f"{w:.2f}-bar slot, {where} ({steps} steps)"
        p = Problem(p.scene, p.start, p.goal, f"{p.tag}: {title}")
        gif = f"{args.output}_{name}.gif"
        render_rollout_gif(p, robot, timed_path(robot, path), gif, azim=-35)
        print(f"{name}: {p.tag}, solved on try {tried} of {len(problems)}; wrote {gif}")
        chosen.append((p, path))
        titles.append(title)
    if chosen:
        render_grid_3d(
            [p for p, _ in chosen],
            robot,
            [q for _, q in chosen],
            output=f"{args.output}.png",
            cols=len(chosen),
            titles=titles,
            azim=-35,
        )
        print(f"wrote {args.output}.png")


if __name__ == "__main__":
    main()
