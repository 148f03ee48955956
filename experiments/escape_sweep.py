"""Escapes through the planner itself: success of ``PolicyPlanner`` with each escape on
validation problems (docs/results/3d-sphere.md, "How the escape was chosen"). Each ``--configs`` entry is
``STEPS:NOISE:STILL:WINDOW[:subgoal][:tN][:lN][:bX]`` (``0`` alone: no escape; ``tN``: N draws
per escape step, the furthest-moving taken; ``lN``: judged by N steps of lookahead; ``bX``:
where no draw moves, back off along the path to a pose more than X away), for example the sphere's default and the S-shape's:

    python experiments/escape_sweep.py --robot sphere3d --observation local --episodes 500 --configs 0 10:0:0.1:6:subgoal
    python experiments/escape_sweep.py --robot sshape --observation global --configs 10:2:0.01:1:t8 10:0:0.01:1:subgoal

``--val-seed 1`` draws another 500 validation problems, to confirm a choice made on the
first draw. Every path is re-checked by the evaluator (``claims disagree``).
"""

from __future__ import annotations

import argparse
import json
import time


def parse_config(text: str):  # type: ignore[no-untyped-def]
    from pointplan.planners.policy import Escape

    if text == "0":
        return Escape(steps=0)
    parts = text.split(":")
    # draws per escape step (the furthest taken); steps of lookahead; the back-off's distance
    extra: dict[str, float] = {"t": 1, "l": 0, "b": 0.0}
    while parts and parts[-1][:1] in extra and parts[-1][1:].replace(".", "", 1).isdigit():
        last = parts.pop()
        extra[last[0]] = float(last[1:])
    tries, lookahead, backoff = int(extra["t"]), int(extra["l"]), extra["b"]
    if len(parts) not in (4, 5) or (len(parts) == 5 and parts[4] != "subgoal"):
        raise argparse.ArgumentTypeError(
            f"an escape is STEPS:NOISE:STILL:WINDOW[:subgoal][:tN][:lN][:bX] or 0, not {text!r}"
        )
    try:
        return Escape(
            steps=int(parts[0]),
            noise=float(parts[1]),
            still=float(parts[2]),
            window=int(parts[3]),
            subgoal=len(parts) == 5,
            tries=tries,
            lookahead=lookahead,
            backoff=backoff,
        )
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from e


#: Slot's bands of opening widths, in bar thicknesses
WIDTH_BANDS = (2.0, 2.5, 3.0, 4.0, 6.0, 8.0)


def by_width(widths: list[float], success: list[bool]) -> dict[str, list[int]]:
    """``{"a-b": [solved, problems]}`` per band of Slot's opening widths (metres in, bands in bar thicknesses)."""
    from pointplan.robots.sshape import BAR_THICKNESS

    bars = [w / BAR_THICKNESS for w in widths]
    out = {}
    for a, b in zip(WIDTH_BANDS[:-1], WIDTH_BANDS[1:]):
        inside = [ok for x, ok in zip(bars, success) if a <= x < b or (b == WIDTH_BANDS[-1] and x == b)]
        out[f"{a:g}-{b:g}"] = [int(sum(inside)), len(inside)]
    return out


def policy_and_problems(args: argparse.Namespace):  # type: ignore[no-untyped-def]
    """The policy (``args.checkpoint`` or the shipped one of ``args.robot`` and
    ``args.observation``), its checkpoint's path, the scenario (``args.env`` or the
    policy's own) and ``args.episodes`` validation problems of draw ``args.val_seed``."""
    from pointplan.models.policy import Policy, shipped_checkpoint
    from pointplan.scenes.scenarios import make_scenario

    ckpt = args.checkpoint or str(shipped_checkpoint(args.robot, args.observation))
    policy = Policy.from_checkpoint(ckpt)
    scenario = make_scenario(args.env or policy.env, robot=policy.robot.name)
    return policy, ckpt, scenario, scenario.problems("val", args.episodes, seed=args.val_seed)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("checkpoint", nargs="?", help="policy checkpoint (default: the shipped one)")
    ap.add_argument("--robot", default="sphere3d")
    ap.add_argument("--observation", default=None)
    ap.add_argument("--env", default=None, help="scene id (default: the one the policy was trained in)")
    ap.add_argument("--episodes", type=int, default=500)
    ap.add_argument("--val-seed", type=int, default=0, help="which draw of validation problems")
    ap.add_argument("--escape-seed", type=int, default=0, help="seed of the escape's random draws")
    ap.add_argument(
        "--configs",
        type=parse_config,
        nargs="+",
        required=True,
        help="escapes, STEPS:NOISE:STILL:WINDOW[:subgoal][:tN][:lN][:bX] or 0",
    )
    ap.add_argument("--json", help="write the rows here")
    args = ap.parse_args()
    import torch

    torch.set_num_threads(1)
    from pointplan.evaluation.evaluate import evaluate
    from pointplan.planners.policy import PolicyPlanner

    policy, ckpt, scenario, problems = policy_and_problems(args)
    rows = []
    for esc in args.configs:
        planner = PolicyPlanner(policy, robot=scenario.robot, escape=esc, seed=args.escape_seed)
        t0 = time.perf_counter()
        report = evaluate(planner, problems, scenario.robot, progress=False)
        m = report.metrics()
        row = {
            "escape": {
                "steps": esc.steps,
                "noise": esc.noise,
                "still": esc.still,
                "window": esc.window,
                "subgoal": esc.subgoal,
                "tries": esc.tries,
                "lookahead": esc.lookahead,
                "backoff": esc.backoff,
            },
            "success": m["success_rate"],
            "mean_steps": m["nodes_mean"],
            "claims_disagree": m["planner_claims_disagree"],
            "wall_s": time.perf_counter() - t0,
        }
        if "slot" in problems[0].scene.__dict__:  # Slot: solved per band of the opening's width (bar thicknesses)
            row["by_width_bars"] = by_width(
                [p.scene.__dict__["slot"]["width"] for p in problems], [r.success for r in report.records]
            )
        rows.append(row)
        print(
            f"{esc}: {100 * row['success']:5.1f}% of {m['episodes']} val problems (draw {args.val_seed}) in {scenario.name}, "
            f"{row['mean_steps']:.1f} steps, {row['claims_disagree']} claims disagree, {row['wall_s']:.0f} s"
            + (
                "".join(f"; {k} bars {v[0]}/{v[1]}" for k, v in row["by_width_bars"].items())
                if "by_width_bars" in row
                else ""
            ),
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
                    "escape_seed": args.escape_seed,
                    "rows": rows,
                },
                f,
                indent=1,
            )


if __name__ == "__main__":
    main()
