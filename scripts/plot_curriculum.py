"""Plot a reverse-curriculum PPO run (``pointplan ppo --start-demos``): validation success
and how far before the goal its demonstration starts reach, against wall time.

    python scripts/plot_curriculum.py runs/a/metrics.csv runs/b/metrics.csv --labels A B \\
        --marks 32 38 52 --mark-labels "frame past the wall" "insertion pose" "whole path (median)" \\
        -o docs/img/slot_curriculum.png

``--marks`` draws horizontal lines on the reach panel (steps before the goal), e.g. where
the demonstrations' insertion pose lies.
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt


def column(rows: list[dict[str, str]], key: str) -> list[float]:
    return [float(r[key]) if r.get(key) not in (None, "") else float("nan") for r in rows]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("csv", nargs="+", type=Path)
    ap.add_argument("--labels", nargs="*")
    ap.add_argument("--marks", nargs="*", type=float, default=[])
    ap.add_argument("--mark-labels", nargs="*", default=[])
    ap.add_argument("--ymax", type=float, default=1.0, help="upper end of the success axis")
    ap.add_argument("-o", "--output", default="curriculum.png")
    args = ap.parse_args()
    labels = args.labels or [p.parent.name for p in args.csv]
    if len(labels) != len(args.csv):
        ap.error("--labels needs one label per run")
    fig, axes = plt.subplots(1, 2, figsize=(10.5, 3.8))
    for path, label in zip(args.csv, labels):
        with path.open() as f:
            rows = list(csv.DictReader(f))
        if not rows or "start_back" not in rows[0]:
            raise SystemExit(f"{path}: not a curriculum run's metrics (no start_back column)")
        t = [x / 60 for x in column(rows, "wall_time_s")]
        (line,) = axes[0].plot(
            t, column(rows, "val_success_escape"), marker="o", ms=3, label=f"{label}, with the escape"
        )
        axes[0].plot(
            t,
            column(rows, "val_success"),
            marker=".",
            ms=3,
            ls="--",
            color=line.get_color(),
            label=f"{label}, mean action",
        )
        axes[1].plot(t, column(rows, "start_back"), marker="o", ms=3, color=line.get_color(), label=label)
    for k, m in enumerate(args.marks):
        axes[1].axhline(m, color="grey", lw=0.8, ls=":")
        if k < len(args.mark_labels):
            axes[1].text(
                0.01,
                m,
                args.mark_labels[k],
                transform=axes[1].get_yaxis_transform(),
                va="bottom",
                fontsize=7,
                color="grey",
            )
    axes[0].set_ylabel("validation success")
    axes[0].set_ylim(0, args.ymax)
    axes[1].set_ylabel("starts reach back (steps before the goal)")
    axes[1].set_ylim(bottom=0)
    for ax in axes:
        ax.set_xlabel("wall time, one core (min)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    Path(args.output).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.output, dpi=120)
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
