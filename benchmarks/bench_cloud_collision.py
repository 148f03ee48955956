"""Point clouds as obstacles: the S-shape's collision checks against a scanned scene.

A 3D-Boxes workspace is replaced by a cloud of points sampled on its boxes' surfaces
(area-weighted, with normals), as a user's scan would give it. For the S-shape (boxes as
bodies) this times:

- ``check``: one ``robot.collides`` call on a batch of configurations, through the
  compiled grid of the cloud (``SShape.collides``: :mod:`pointplan.robots._cloud_kernels`)
  and through the k-d tree (:func:`pointplan.geometry.collision.boxes_contain_cloud_points`,
  the numpy path), against the brute-force test of every cloud point (a sphere of the
  cloud's point radius) against every body box (the reference: the same answers are
  asserted);
- ``plan``: ``PolicyPlanner.plan`` (the shipped S-shape policy, ``global`` observation)
  on a few problems (their starts and goals) in the first problem's scene given as the
  cloud, with the compiled checks (and, with ``--kdtree``, through the k-d tree), and in
  the same scene given as its boxes, for the whole query time (after one query to warm
  up), and that time over the configurations checked (the rollouts in a cloud and among
  the boxes differ: the cloud's points are spheres, and only scenes of boxes have the
  compiled rollout, so the step loop plans in the cloud);
- ``--success``: the shipped policies (``--robots``, ``--observations``) on each problem
  given as boxes and as a fresh cloud of its boxes' surfaces; a cloud path counts only if
  the evaluator finds it free of the true boxes (it shows whether a path slips between
  the points). Each query is timed, then timed again (on the cloud, the second query
  finds the cloud's grids and trees built).

    python benchmarks/bench_cloud_collision.py --points 15000 --problems 5
    python benchmarks/bench_cloud_collision.py --points 100000 --problems 5 --kdtree
    python benchmarks/bench_cloud_collision.py --points 15000 --problems 20 --success
    python benchmarks/bench_cloud_collision.py --points 100000 --problems 400 --success \\
        --robots sshape,sphere3d --observations local --out docs/data/clouds/success.jsonl
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--points", type=int, default=15000, help="cloud points (default: %(default)s)")
    ap.add_argument("--configs", type=int, default=200, help="configurations per collision call (default: %(default)s)")
    ap.add_argument("--problems", type=int, default=5, help="problems planned (default: %(default)s)")
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--kdtree", action="store_true", help="also plan through the k-d tree (the numpy checks; slow)")
    ap.add_argument("--success", action="store_true", help="compare success on boxes and on clouds instead of timing")
    ap.add_argument("--robots", default="sshape", help="with --success: robots, comma-separated (default: %(default)s)")
    ap.add_argument(
        "--observations",
        default="local,global",
        help="with --success: policies, comma-separated (default: %(default)s)",
    )
    ap.add_argument("--out", default=None, help="with --success: JSON lines, one per problem and policy (appended)")
    args = ap.parse_args()
    if args.success:
        success(args)
        return

    from pointplan.geometry.collision import sphere_box_sqdist
    from pointplan.geometry.sampling import area_weighted_points
    from pointplan.geometry.shapes import PointCloud
    from pointplan.robots.base import Robot
    from pointplan.scenes.scenarios import make_scenario
    from pointplan.scenes.scene import Scene

    sc = make_scenario("boxes3d", robot="sshape")
    robot = sc.robot
    problems = sc.problems("test", args.problems, seed=args.seed)
    rng = np.random.default_rng(args.seed)
    base = problems[0].scene
    pts, nrm, _ = area_weighted_points(base.obstacles, args.points, rng)
    cloud = Scene([PointCloud(pts, nrm)], base.low, base.high, name="cloud")
    q = robot.sample_uniform(rng, args.configs, base.low, base.high)

    robot.collides(cloud.world, q[:2])  # compiles the kernels, builds the grid
    t = time.perf_counter()
    fast = robot.collides(cloud.world, q)
    t_grid = time.perf_counter() - t
    t = time.perf_counter()
    tree = Robot.collides(robot, cloud.world, q)
    t_tree = time.perf_counter() - t
    _, c, rot, h = robot.world_parts(q)  # the body boxes (the S-shape has no sphere parts)
    assert not len(robot.parts.sphere_radii)
    t = time.perf_counter()  # reference: every point against every body box, by brute force
    r = cloud.obstacles[0].point_radius()  # each point is a sphere of the cloud's point radius
    ref = np.any(sphere_box_sqdist(pts, c.reshape(-1, 3), rot.reshape(-1, 3, 3), h.reshape(-1, 3)) <= r * r, 0)
    t_brute = time.perf_counter() - t
    ref = ref.reshape(c.shape[:-1]).any(-1)
    assert np.array_equal(ref, tree), "the k-d tree and the brute force disagree"
    assert np.array_equal(ref, fast), "the compiled grid and the brute force disagree"
    print(f"{args.points} cloud points, {args.configs} S-shape configurations ({int(fast.sum())} in collision):")
    print(
        f"  check: compiled grid {1e3 * t_grid:.2f} ms, k-d tree {1e3 * t_tree:.1f} ms, "
        f"brute force {1e3 * t_brute:.1f} ms"
    )
    print(f"  plan(): {_plan(robot, cloud, problems)} (cloud, compiled grid)")
    if args.kdtree:
        print(f"  plan(): {_plan(_kdtree_robot(), cloud, problems)} (cloud, k-d tree)")
    print(f"  plan(): {_plan(robot, base, problems)} (the same scene as boxes)")


def _plan(robot: Any, scene: Any, problems: list[Any]) -> str:
    """The shipped policy (``global``) on the problems' starts and goals in ``scene``: solved
    and the median query time, after one query to warm up."""
    from pointplan.planners import make_planner
    from pointplan.scenes.scene import Problem

    planner = make_planner("policy", robot, observation="global")
    planner.plan(Problem(scene, problems[0].start, problems[0].goal))
    times, ok, checks = [], 0, 0
    for p in problems:
        t = time.perf_counter()
        res = planner.plan(Problem(scene, p.start, p.goal))
        times.append(time.perf_counter() - t)
        ok += res.success
        checks += res.collision_checks
    per = 1e6 * sum(times) / max(checks, 1)
    return (
        f"{ok}/{len(problems)} solved, median {1e3 * float(np.median(times)):.1f} ms per query "
        f"({per:.2f} us per configuration checked)"
    )


def _kdtree_robot() -> Any:
    """The S-shape whose checks against clouds go through the k-d tree (numpy)."""
    from pointplan.robots.sshape import SShape

    class KdTreeSShape(SShape):
        def _obstacles(self, world: Any) -> tuple[Any, ...] | None:
            return super()._obstacles(world) if world.boxes_only else None

    return KdTreeSShape()


def success(args: argparse.Namespace) -> None:
    """Success of the shipped policies on problems given as boxes and as clouds of their
    surfaces (same problems, one fresh cloud per problem); one JSON line per problem and
    policy in ``--out`` (appended as it goes: Ctrl-C keeps what was done)."""
    import json
    import os

    from pointplan.evaluation import check_path
    from pointplan.geometry.sampling import area_weighted_points
    from pointplan.geometry.shapes import PointCloud
    from pointplan.planners import make_planner
    from pointplan.progress import progress_bar
    from pointplan.scenes.scenarios import make_scenario
    from pointplan.scenes.scene import Problem, Scene

    out = open(args.out, "a") if args.out else None  # noqa: SIM115 (closed in finally)
    rows: dict[tuple[str, str], list[dict[str, Any]]] = {}
    try:
        for robot in args.robots.split(","):
            sc = make_scenario("boxes3d", robot=robot)
            problems = sc.problems("test", args.problems, seed=args.seed)
            for obs in args.observations.split(","):
                rng = np.random.default_rng(args.seed)
                planner = make_planner("policy", sc.robot, observation=obs)
                got = rows.setdefault((robot, obs), [])
                for i, p in enumerate(progress_bar(problems, desc=f"{robot} {obs}", unit="problem")):
                    pts, nrm, _ = area_weighted_points(p.scene.obstacles, args.points, rng)
                    cloud = Problem(Scene([PointCloud(pts, nrm)], p.scene.low, p.scene.high), p.start, p.goal)
                    t = time.perf_counter()
                    on_boxes = planner.plan(p)
                    t_boxes = time.perf_counter() - t
                    t = time.perf_counter()
                    on_cloud = planner.plan(cloud)
                    t_cloud = time.perf_counter() - t
                    t = time.perf_counter()  # again, the cloud's structures built (a scan planned twice)
                    planner.plan(cloud)
                    t_again = time.perf_counter() - t
                    t = time.perf_counter()
                    planner.plan(p)
                    t_boxes_again = time.perf_counter() - t
                    boxes_check = check_path(sc.robot, p, on_boxes.path)
                    row = {
                        "robot": robot,
                        "observation": obs,
                        "index": i,
                        "points": args.points,
                        "point_radius": float(cloud.scene.obstacles[0].point_radius()),
                        "boxes": bool(boxes_check),
                        # how near the boxes the path on the boxes passes (a cloud is thicker by its point radius)
                        "boxes_clearance": (
                            float(boxes_check.clearance) if boxes_check and np.isfinite(boxes_check.clearance) else None
                        ),
                        "cloud_claimed": bool(on_cloud.success),
                        "cloud_free": bool(on_cloud.success and check_path(sc.robot, p, on_cloud.path)),
                        "time_boxes_s": t_boxes,
                        "time_cloud_s": t_cloud,
                        "time_boxes_again_s": t_boxes_again,
                        "time_cloud_again_s": t_again,
                    }
                    got.append(row)
                    if out is not None:
                        out.write(json.dumps(row) + "\n")
                        out.flush()
    except KeyboardInterrupt:
        print("interrupted: the problems done so far")
    finally:
        if out is not None:
            out.close()
    for (robot, obs), got in rows.items():
        n = len(got)
        if not n:
            continue
        b, c, f = (sum(r[k] for r in got) for k in ("boxes", "cloud_claimed", "cloud_free"))
        lost = [r for r in got if r["boxes"] and not r["cloud_free"]]
        thin = sum(r.get("boxes_clearance") is not None and r["boxes_clearance"] < r["point_radius"] for r in lost)
        tb, tc, tb2, tc2 = (
            1e3 * float(np.median([r[k] for r in got]))
            for k in ("time_boxes_s", "time_cloud_s", "time_boxes_again_s", "time_cloud_again_s")
        )
        print(
            f"{robot} {obs}: boxes {b}/{n} ({100 * b / n:.1f}%); clouds of {args.points} points: "
            f"{c} claimed, {f} free of the true boxes ({100 * f / n:.1f}%); median query on boxes "
            f"{tb:.1f} ms (again {tb2:.1f}), on the cloud {tc:.1f} ms (again, its structures built: {tc2:.1f}); "
            f"of the {len(lost)} solved on the boxes only, {thin} passed the boxes closer than the point radius"
        )
    if args.out:
        print(f"records: {os.path.abspath(args.out)}")


if __name__ == "__main__":
    main()
