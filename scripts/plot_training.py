"""Plot validation success against wall time (and env steps) for training runs.

    python scripts/plot_training.py runs/a/metrics.csv runs/b/metrics.csv -o docs/img/training.png \\
        --labels "SAC+HER from scratch" "BC then SAC+HER"
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt


def read(path: Path, offset_s: float = 0.0, metric: str = "val_success") -> dict[str, list[float]]:
    """Steps, wall time (plus ``offset_s``) and ``metric`` (as ``val_success``) of each row."""
    with path.open() as f:
        rows = list(csv.DictReader(f))
    if rows and metric not in rows[0]:
        raise SystemExit(f"{path}: no column {metric!r} (columns: {', '.join(rows[0])})")
    return {
        "env_steps": [float(r["env_steps"]) for r in rows],
        "wall_time_s": [float(r["wall_time_s"]) + offset_s for r in rows],
        "val_success": [float(r[metric]) for r in rows],
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("csv", nargs="+", type=Path, help="metrics.csv files of training runs (pointplan train, bc, ppo)")
    ap.add_argument("--labels", nargs="*", help="one legend label per run (default: each run's folder name)")
    ap.add_argument("--offsets", nargs="*", type=float, help="seconds to add to each run's wall time (e.g. BC time)")
    ap.add_argument(
        "--ymin", type=float, default=0.0, help="lower end of the success axis (e.g. 0.95 to see late training)"
    )
    ap.add_argument("--from-steps", type=float, default=0.0, help="leave out evaluations before this many env steps")
    ap.add_argument(
        "--metrics",
        nargs="*",
        help="the column plotted for each run (default: val_success; e.g. val_success_escape of pointplan ppo)",
    )
    ap.add_argument("-o", "--output", default="training.png", help="the PNG to write (default: %(default)s)")
    args = ap.parse_args()
    labels = args.labels or [p.parent.name for p in args.csv]
    offsets = args.offsets or [0.0] * len(args.csv)
    metrics = args.metrics or ["val_success"] * len(args.csv)
    if len(metrics) != len(args.csv):
        ap.error("--metrics needs one column per run")
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    for path, label, off, metric in zip(args.csv, labels, offsets, metrics):
        d = read(path, off, metric)
        keep = [i for i, n in enumerate(d["env_steps"]) if n >= args.from_steps]
        d = {k: [v[i] for i in keep] for k, v in d.items()}
        if not keep:
            continue
        axes[0].plot([t / 60 for t in d["wall_time_s"]], d["val_success"], marker="o", ms=3, label=label)
        axes[1].plot([s / 1000 for s in d["env_steps"]], d["val_success"], marker="o", ms=3, label=label)
    axes[0].set_xlabel("wall time on 2 CPU cores (min)")
    axes[1].set_xlabel("environment steps (thousands)")
    for ax in axes:
        ax.set_ylabel("validation success")
        ax.set_ylim(args.ymin, 1)
        ax.grid(alpha=0.3)
    axes[0].legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    fig.savefig(args.output, dpi=130)
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
