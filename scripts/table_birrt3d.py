"""Markdown table of the 3D Bi-RRT evaluations written by `pointplan eval --json`.

python scripts/table_birrt3d.py docs/data/birrt3d/*.json
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

ORDER = ["boxes3d", "synthetic3d", "ycb3d", "dynamic3d", "slot", "qureshi3d"]


def main(paths: list[str]) -> None:
    rows = []
    for p in paths:
        d = json.loads(Path(p).read_text())
        scene, robot = Path(p).stem.rsplit("_", 1)
        rows.append((ORDER.index(scene) if scene in ORDER else 99, scene, robot, d))
    print("| scene | robot | success | nodes (mean / median) | collision checks (mean) | path length (mean) | time per problem (mean / median) |")
    print("|---|---|---|---|---|---|---|")
    for _, scene, robot, d in sorted(rows, key=lambda r: (r[0], r[2])):
        print(
            f"| {scene} | {robot} | {100 * d['success_rate']:.0f}% | {d['nodes_mean']:.0f} / {d['nodes_median']:.0f} | "
            f"{d['collision_checks_mean']:,.0f} | {d['path_length_mean']:.3f} | {d['time_mean_s']:.3f} s / {d['time_median_s']:.3f} s |"
        )


if __name__ == "__main__":
    main(sys.argv[1:])
