"""Point clouds as obstacles: the S-shape's collision checks against a scanned scene.

A 3D-Boxes workspace is replaced by a cloud of points sampled on its boxes' surfaces
(area-weighted, with normals), as a user's scan would give it. For the S-shape (boxes as
bodies) this times:

- ``check``: one ``robot.collides`` call on a batch of configurations, through the k-d
  tree (:func:`pointplan.geometry.collision.boxes_contain_cloud_points`) against the
  brute-force test of every cloud point against every body box (the reference: the same
  answers are asserted);
- ``plan``: ``PolicyPlanner.plan`` (the shipped S-shape policy, ``global`` observation)
  on a few problems in the cloud scene, with the k-d tree, for the whole query time.

    python benchmarks/bench_cloud_collision.py --points 15000 --problems 5
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--points", type=int, default=15000, help="cloud points (default: %(default)s)")
    ap.add_argument("--configs", type=int, default=200, help="configurations per collision call (default: %(default)s)")
    ap.add_argument("--problems", type=int, default=5, help="problems planned (default: %(default)s)")
    ap.add_argument("--seed", type=int, default=2026)
    args = ap.parse_args()

    from pointplan.geometry.collision import sphere_box_sqdist
    from pointplan.geometry.sampling import area_weighted_points
    from pointplan.geometry.shapes import PointCloud
    from pointplan.planners import make_planner
    from pointplan.scenes.scenarios import make_scenario
    from pointplan.scenes.scene import Problem, Scene

    sc = make_scenario("boxes3d", robot="sshape")
    robot = sc.robot
    problems = sc.problems("test", args.problems, seed=args.seed)
    rng = np.random.default_rng(args.seed)
    base = problems[0].scene
    pts, nrm, _ = area_weighted_points(base.obstacles, args.points, rng)
    cloud = Scene([PointCloud(pts, nrm)], base.low, base.high, name="cloud")
    q = robot.sample_uniform(rng, args.configs, base.low, base.high)

    t = time.perf_counter()
    fast = robot.collides(cloud.world, q)
    t_tree = time.perf_counter() - t
    _, c, rot, h = robot.world_parts(q)  # the body boxes (the S-shape has no sphere parts)
    assert not len(robot.parts.sphere_radii)
    t = time.perf_counter()  # reference: every point against every body box, by brute force
    ref = np.any(sphere_box_sqdist(pts, c.reshape(-1, 3), rot.reshape(-1, 3, 3), h.reshape(-1, 3)) <= 0.0, 0)
    t_brute = time.perf_counter() - t
    ref = ref.reshape(c.shape[:-1]).any(-1)
    assert np.array_equal(ref, fast), "the k-d tree and the brute force disagree"
    print(f"{args.points} cloud points, {args.configs} S-shape configurations ({int(fast.sum())} in collision):")
    print(f"  k-d tree {1e3 * t_tree:.1f} ms, brute force {1e3 * t_brute:.1f} ms, ratio {t_brute / t_tree:.0f}x")

    planner = make_planner("policy", robot, observation="global")
    times, ok = [], 0
    for p in problems:
        t = time.perf_counter()
        res = planner.plan(Problem(cloud, p.start, p.goal))
        times.append(time.perf_counter() - t)
        ok += res.success
    print(f"  plan(): {ok}/{len(problems)} solved, median {1e3 * float(np.median(times)):.0f} ms per query")


if __name__ == "__main__":
    main()
