"""Markdown table of the 3D Bi-RRT evaluations written by `pointplan eval --json`.

    python scripts/table_birrt3d.py docs/data/birrt3d/*.json

Each file is named ``SCENE_ROBOT.json``; the rows are sorted by scene, then robot.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

ORDER = ["boxes3d", "synthetic3d", "ycb3d", "dynamic3d", "slot", "slotmoving", "qureshi3d"]


def table(paths: list[str]) -> str:
    """The table of the metrics files ``paths``."""
    rows = []
    for p in paths:
        d = json.loads(Path(p).read_text())
        scene, robot = Path(p).stem.rsplit("_", 1)
        rows.append((ORDER.index(scene) if scene in ORDER else 99, scene, robot, d))
    lines = [
        "| scene | robot | success | nodes (mean / median) | collision checks (mean) | path length (mean) | time per problem (mean / median) |",
        "|---|---|---|---|---|---|---|",
    ]
    for _, scene, robot, d in sorted(rows, key=lambda r: (r[0], r[2])):
        lines.append(
            f"| {scene} | {robot} | {100 * d['success_rate']:.0f}% | {d['nodes_mean']:.0f} / {d['nodes_median']:.0f} | "
            f"{d['collision_checks_mean']:,.0f} | {d['path_length_mean']:.3f} | {d['time_mean_s']:.3f} s / {d['time_median_s']:.3f} s |"
        )
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("json", nargs="+", help="metrics files of pointplan eval --json, named SCENE_ROBOT.json")
    args = ap.parse_args()
    print(table(args.json))


if __name__ == "__main__":
    main()
