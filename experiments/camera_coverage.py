"""How much of a MotionBenchMaker scene's boxes simulated depth cameras see: the share of
each box surface (points sampled ``--spacing`` apart) within ``--within`` of a cloud point,
averaged over the first ``--problems`` problems of each scenario, for 2 and 3 cameras.

    python experiments/camera_coverage.py
"""

from __future__ import annotations

import argparse

import numpy as np
from scipy.spatial import cKDTree

from pointplan.geometry.sampling import surface_points
from pointplan.geometry.shapes import Box
from pointplan.scenes.cameras import CameraModel, camera_ring, seen_by_cameras
from pointplan.scenes.mbm import SCENARIOS, load_problem


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--arm", default="panda")
    ap.add_argument("--problems", type=int, default=3)
    ap.add_argument("--cameras", type=int, nargs="+", default=[2, 3])
    ap.add_argument("--spacing", type=float, default=0.01)
    ap.add_argument("--within", type=float, default=0.01)
    args = ap.parse_args()
    camera = CameraModel(640, 480, 550.0)
    for n in args.cameras:
        cells = []
        for sc in SCENARIOS:
            seen = []
            for i in range(1, args.problems + 1):
                p = load_problem(args.arm, sc, i)
                pts, _ = surface_points([o for o in p.scene.obstacles if isinstance(o, Box)], args.spacing)
                cloud = seen_by_cameras(p.scene, camera_ring(p.scene, n, distance=1.5), camera).obstacles[0]
                d, _ = cKDTree(cloud.points).query(pts)
                seen.append(float((d <= args.within).mean()))
            cells.append(f"{sc} {np.mean(seen):.0%}")
        print(f"{n} cameras, box surface within {args.within} m of a cloud point: " + "; ".join(cells), flush=True)


if __name__ == "__main__":
    main()
