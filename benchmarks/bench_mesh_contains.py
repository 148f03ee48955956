"""Bi-RRT with the S-shape in 3D-YCB, with the compiled inside-the-mesh test against the
numpy one it replaced (same formula: ``collision.mesh_winding_reference``), alternating on
the same problems in one process; process time, so other jobs on the machine count less.

    python benchmarks/bench_mesh_contains.py --problems 6
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from pointplan.geometry import collision
from pointplan.planners.birrt import BiRRT
from pointplan.scenes.scenarios import make_scenario


def numpy_contains(mesh, points):  # type: ignore[no-untyped-def]
    return np.abs(collision.mesh_winding_reference(mesh, points)) > 0.5


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--problems", type=int, default=6)
    ap.add_argument("--robot", default="sshape")
    args = ap.parse_args()
    sc = make_scenario("ycb3d", robot=args.robot)
    compiled = collision.mesh_contains
    times = {"compiled": 0.0, "numpy": 0.0}
    for i in range(args.problems):
        p = sc.problem("test", i)
        order = ["compiled", "numpy"] if i % 2 == 0 else ["numpy", "compiled"]
        nodes = {}
        for name in order:
            collision.mesh_contains = compiled if name == "compiled" else numpy_contains  # type: ignore[assignment]
            t0 = time.process_time()
            res = BiRRT(sc.robot, seed=i).plan(p)
            times[name] += time.process_time() - t0
            nodes[name] = (res.success, res.nodes)
        collision.mesh_contains = compiled  # type: ignore[assignment]
        assert nodes["compiled"] == nodes["numpy"], f"problem {i}: the two tests built different trees"
        print(
            f"problem {i}: {nodes['compiled']}, compiled {times['compiled']:.1f} s, numpy {times['numpy']:.1f} s (cumulative)",
            flush=True,
        )
    print(
        f"Bi-RRT, {args.robot} in 3D-YCB, {args.problems} problems: compiled {times['compiled']:.1f} s, numpy {times['numpy']:.1f} s of process time; speed-up {times['numpy'] / times['compiled']:.2f}x"
    )


if __name__ == "__main__":
    main()
