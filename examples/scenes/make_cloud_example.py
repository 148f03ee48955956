"""Write cloud_example.ply and cloud_example.json: a 2D-Narrow workspace seen as a bare point
cloud (no normals), the way a scan would give it.

Points lie along the walls' outlines about 6 mm apart, jittered by 1 mm of noise (the
disc's radius is 10 mm: the cloud must have no gap it fits through), and saved as a flat PLY (z = 0) with trimesh. Points buried inside another
wall and points on the workspace border are left out, as a scanner in the workspace would
not see them. The problems are those of the same workspace in the 2D-Narrow test split.

    python examples/scenes/make_cloud_example.py
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import trimesh

from pointplan.geometry.sampling import surface_points
from pointplan.scenes.scenarios import Narrow2DScenario

HERE = Path(__file__).resolve().parent
WORKSPACE = 3  # of the test split
SEEDS = (0, 1, 2)  # one problem each
SPACING = 0.006
NOISE = 0.001


def main() -> None:
    rng = np.random.default_rng(14)
    scenario = Narrow2DScenario()
    scene = scenario.scene("test", WORKSPACE)
    p, _ = surface_points(scene.obstacles, SPACING, scene.low, scene.high)
    p = p + rng.normal(0.0, NOISE, p.shape)
    p = np.clip(p, scene.low, scene.high)
    cloud = trimesh.PointCloud(np.c_[p, np.zeros(len(p))])
    cloud.export(HERE / "cloud_example.ply")  # binary PLY: x, y, z only
    problems = []
    for seed in SEEDS:
        prob = scenario.problem("test", WORKSPACE, seed)
        problems.append({"start": prob.start.tolist(), "goal": prob.goal.tolist(), "tag": f"cloud_example/{seed}"})
    doc = {
        "format": "pointplan-scene",
        "version": 1,
        "dim": 2,
        "name": "cloud_example",
        "bounds": {"low": scene.low.tolist(), "high": scene.high.tolist()},
        "robot": "disc2d",
        "obstacles": [{"type": "points", "path": "cloud_example.ply"}],
        "problems": problems,
    }
    (HERE / "cloud_example.json").write_text(json.dumps(doc, indent=2) + "\n")
    print(f"wrote {len(p)} points to cloud_example.ply and {len(problems)} problems to cloud_example.json")


if __name__ == "__main__":
    main()
