"""How robust is the shipped 2D policy?

    OMP_NUM_THREADS=1 python scripts/robustness.py --episodes 400                    # everything
    python scripts/robustness.py --parts variants --episodes 200
    python scripts/robustness.py --parts noise --plot docs/img/robustness_noise_2d.png
    python scripts/robustness.py --parts draws

Parts (markdown tables on stdout; ``--json`` writes the numbers):

- ``variants``: the policy, the hybrid planner and Bi-RRT on the 2D-Narrow test problems
  and on the variants' test problems (``narrow2d-ends``, ``-many``, ``-narrow``,
  ``-manynarrow``, ``docs/guide/scenarios.md``): success (paths re-checked by the evaluator),
  nodes, time per problem.
- ``noise``: the policy on the 2D-Narrow test problems with perturbed observations
  (:mod:`pointplan.observers.perturb`): Gaussian noise on the observed points' positions,
  a share of the scene's points dropped, points hidden from one viewpoint. With ``--plot``
  also a figure.
- ``draws``: the policy with three observation seeds (which random 64 points it sees)
  on every set, how many problems change outcome with the seed, and two inference-time
  remedies: the mean action over K = 4 random subsets (``PolicyPlanner(draws=4)``) and
  farthest-point subsets (``perturbation(subset="fps")``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from pointplan.evaluation.evaluate import evaluate
from pointplan.observers.perturb import perturbation
from pointplan.planners import make_planner
from pointplan.scenes.scenarios import make_scenario

SETS = ["narrow2d", "narrow2d-ends", "narrow2d-many", "narrow2d-narrow", "narrow2d-manynarrow"]
CAMERA = (0.5, -0.5)


def run(planner: Any, problems: list, robot: Any) -> dict[str, Any]:
    report = evaluate(planner, problems, robot, progress=False)
    m = report.metrics()
    m["failed"] = [i for i, r in enumerate(report.records) if not r.success]
    return m


def row(label: str, m: dict[str, Any], extra: str = "") -> str:
    return f"| {label} | {m['success_rate']:.1%} | {m['nodes_mean']:.1f} / {m['nodes_median']:.0f} | {1e3 * m['time_mean_s']:.1f} / {1e3 * m['time_median_s']:.1f} ms |{extra}"


def part_variants(sets: list[str], n: int, seed: int, out: dict[str, Any]) -> None:
    print(f"\n### Planners on the variants ({n} test problems each, problem seed {seed})\n")
    print("| set | planner | success | nodes (mean / median) | time (mean / median) |")
    print("|---|---|---|---|---|")
    for name in sets:
        sc = make_scenario(name)
        probs = sc.problems("test", n, seed=seed)
        for pname in ("policy", "hybrid", "birrt"):
            m = run(make_planner(pname, sc.robot), probs, sc.robot)
            out.setdefault("variants", {}).setdefault(name, {})[pname] = m
            print(row(f"{name} | {pname}", m), flush=True)


def noise_conditions() -> list[tuple[str, str, float, dict[str, Any]]]:
    """(group, label, x value, perturbation keywords)."""
    conds = [("noise", f"sigma {s:g} mm", s, {"noise": s / 1000}) for s in (0, 2, 5, 10, 20, 40)]
    conds += [("drop", f"{d:g}% of points dropped", d, {"drop": d / 100}) for d in (10, 25, 50, 75, 90)]
    conds += [("view", "visible from the start only", 0, {"viewpoint": "start"})]
    conds += [("view", f"visible from a camera at {CAMERA} only", 1, {"viewpoint": CAMERA})]
    return conds


def part_noise(n: int, seed: int, out: dict[str, Any], plot: str | None) -> None:
    sc = make_scenario("narrow2d")
    probs = sc.problems("test", n, seed=seed)
    print(f"\n### The shipped policy under perturbed observations ({n} 2D-Narrow test problems)\n")
    print("| observation | success | nodes (mean / median) | time (mean / median) |")
    print("|---|---|---|---|")
    res = out.setdefault("noise", {})
    for group, label, x, kw in noise_conditions():
        m = run(make_planner("policy", sc.robot, observer_wrapper=perturbation(seed=0, **kw)), probs, sc.robot)
        m.update(group=group, x=x)
        res[label] = m
        print(row(label, m), flush=True)
    if plot:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(1, 3, figsize=(11, 3.4), sharey=True)
        noise = [m for m in res.values() if m["group"] == "noise"]
        ax[0].plot([m["x"] for m in noise], [100 * m["success_rate"] for m in noise], "o-")
        ax[0].set_xlabel("position noise sigma (mm)")
        ax[0].set_ylabel(f"success on {n} test problems (%)")
        base = res["sigma 0 mm"]
        drop = [base] + [m for m in res.values() if m["group"] == "drop"]
        ax[1].plot([0] + [m["x"] for m in drop[1:]], [100 * m["success_rate"] for m in drop], "o-")
        ax[1].set_xlabel("scene points dropped (%)")
        view = [("all points", base)] + [
            (lbl.replace("visible from ", "").replace(" only", ""), m) for lbl, m in res.items() if m["group"] == "view"
        ]
        ax[2].bar(range(len(view)), [100 * m["success_rate"] for _, m in view])
        ax[2].set_xticks(range(len(view)), [v[0] for v in view], fontsize=7)
        ax[2].set_xlabel("occlusion (one viewpoint)")
        for a in ax:
            a.grid(alpha=0.3)
        fig.suptitle("shipped 2D-Narrow policy, perturbed observations")
        fig.tight_layout()
        Path(plot).parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(plot, dpi=110)
        print(f"\nwrote {plot}")


def part_draws(sets: list[str], n: int, seed: int, obs_seeds: list[int], k: int, out: dict[str, Any]) -> None:
    print(f"\n### The point draw: observation seeds {obs_seeds} ({n} test problems per set)\n")
    variants = [
        ("policy", {}),
        (f"mean action over K={k} draws", {"draws": k}),
        ("farthest-point subsets", {"observer_wrapper": perturbation(subset="fps")}),
    ]
    print(
        "| set | planner | success per observation seed | mean | nodes (mean) | problems whose outcome depends on the seed | time (mean) |"
    )
    print("|---|---|---|---|---|---|---|")
    res = out.setdefault("draws", {})
    for name in sets:
        sc = make_scenario(name)
        probs = sc.problems("test", n, seed=seed)
        for label, kw in variants:
            ms = [run(make_planner("policy", sc.robot, seed=s, **kw), probs, sc.robot) for s in obs_seeds]
            fails = [set(m["failed"]) for m in ms]
            flaky = len(set.union(*fails) - set.intersection(*fails))
            succ = [m["success_rate"] for m in ms]
            res.setdefault(name, {})[label] = {
                "success": succ,
                "nodes": [m["nodes_mean"] for m in ms],
                "flaky": flaky,
                "failed": [sorted(f) for f in fails],
                "time_mean_s": [m["time_mean_s"] for m in ms],
            }
            per = " / ".join(f"{s:.1%}" for s in succ)
            print(
                f"| {name} | {label} | {per} | {np.mean(succ):.2%} | {np.mean([m['nodes_mean'] for m in ms]):.1f} | {flaky} | {1e3 * np.mean([m['time_mean_s'] for m in ms]):.1f} ms |",
                flush=True,
            )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--parts", default="variants,noise,draws", help="comma-separated: variants, noise, draws")
    ap.add_argument("--episodes", type=int, default=400, help="problems per set (default 400)")
    ap.add_argument("--sets", nargs="+", default=SETS)
    ap.add_argument("--seed", type=int, default=0, help="start/goal seed (0: the problems of pointplan eval)")
    ap.add_argument("--obs-seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--draws", type=int, default=4, help="K of the mean-action remedy")
    ap.add_argument("--plot", help="PNG of the noise part (e.g. docs/img/robustness_noise_2d.png)")
    ap.add_argument("--json", help="write every number here")
    args = ap.parse_args()
    try:
        import torch

        torch.set_num_threads(1)
    except ImportError:  # pragma: no cover
        pass
    out: dict[str, Any] = {"episodes": args.episodes, "seed": args.seed}
    t0 = time.perf_counter()
    parts = [p.strip() for p in args.parts.split(",") if p.strip()]
    for p in parts:
        if p == "variants":
            part_variants(args.sets, args.episodes, args.seed, out)
        elif p == "noise":
            part_noise(args.episodes, args.seed, out, args.plot)
        elif p == "draws":
            part_draws(args.sets, args.episodes, args.seed, args.obs_seeds, args.draws, out)
        else:
            sys.exit(f"unknown part {p!r}")
    print(f"\n({time.perf_counter() - t0:.0f} s)")
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(out, indent=1, default=float) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
