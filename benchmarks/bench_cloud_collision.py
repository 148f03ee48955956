"""Point clouds as obstacles: the S-shape's collision checks against a scanned scene.

A 3D-Boxes workspace is replaced by a cloud of points sampled on its boxes' surfaces
(area-weighted, with normals), as a user's scan would give it. For the S-shape (boxes as
bodies) this times:

- ``check``: one ``robot.collides`` call on a batch of configurations, through the k-d
  tree (:func:`pointplan.geometry.collision.boxes_contain_cloud_points`) against the
  brute-force test of every cloud point (a sphere of the cloud's point radius) against
  every body box (the reference: the same answers are asserted);
- ``plan``: ``PolicyPlanner.plan`` (the shipped S-shape policy, ``global`` observation)
  on a few problems in the cloud scene, with the k-d tree, for the whole query time;
- ``--success``: the shipped S-shape policies (``local`` and ``global``) on each problem
  given as boxes and as a fresh cloud of its boxes' surfaces; a cloud path counts only if
  the evaluator finds it free of the true boxes (it shows whether a path slips between
  the points).

    python benchmarks/bench_cloud_collision.py --points 15000 --problems 5
    python benchmarks/bench_cloud_collision.py --points 15000 --problems 20 --success
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
    ap.add_argument("--success", action="store_true", help="compare success on boxes and on clouds instead of timing")
    args = ap.parse_args()
    if args.success:
        success(args.points, args.problems, args.seed)
        return

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
    r = cloud.obstacles[0].point_radius()  # each point is a sphere of the cloud's point radius
    ref = np.any(sphere_box_sqdist(pts, c.reshape(-1, 3), rot.reshape(-1, 3, 3), h.reshape(-1, 3)) <= r * r, 0)
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


def success(n_points: int, n_problems: int, seed: int) -> None:
    """Success of the shipped S-shape policies on problems given as boxes and as clouds."""
    from pointplan.evaluation import check_path
    from pointplan.geometry.sampling import area_weighted_points
    from pointplan.geometry.shapes import PointCloud
    from pointplan.planners import make_planner
    from pointplan.scenes.scenarios import make_scenario
    from pointplan.scenes.scene import Problem, Scene

    sc = make_scenario("boxes3d", robot="sshape")
    problems = sc.problems("test", n_problems, seed=seed)
    for obs in ("local", "global"):
        rng = np.random.default_rng(seed)
        planner = make_planner("policy", sc.robot, observation=obs)
        boxes = claimed = free = 0
        for p in problems:
            pts, nrm, _ = area_weighted_points(p.scene.obstacles, n_points, rng)
            cloud = Problem(Scene([PointCloud(pts, nrm)], p.scene.low, p.scene.high), p.start, p.goal)
            boxes += bool(check_path(sc.robot, p, planner.plan(p).path))
            res = planner.plan(cloud)
            claimed += res.success
            free += bool(res.success and check_path(sc.robot, p, res.path))
        print(
            f"S-shape {obs}: boxes {boxes}/{n_problems}; clouds of {n_points} points: {claimed} claimed, {free} free of the true boxes"
        )


if __name__ == "__main__":
    main()
