"""Collision checks per second: the batched numpy checker versus a per-pair coal loop.

    python benchmarks/bench_collision.py            # M = 1000 and 10000 configurations
    python benchmarks/bench_collision.py --quick    # M = 1000 only, shorter timings

A "check" is one configuration tested against every obstacle of the scene. The batched
checker answers ``robot.collides(world, q)`` for ``q: (M, config_dim)`` in one call; the
baseline loops in Python over configurations, robot parts and obstacles and calls
``coal.collide`` on pre-built coal geometries, stopping at the first hit. 2D cases are
embedded in 3D for coal (the disc is a sphere in the plane z = 0, boxes are extruded to
a height of 1). Both answers are compared on every benchmarked configuration.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import coal
import numpy as np

from pointplan.geometry import lie
from pointplan.geometry.shapes import Box
from pointplan.robots import Disc2D, Sphere3D, SShape
from pointplan.robots.base import Robot
from pointplan.scenes import Scene

HALF_EXTENT = 0.6
SIDE_RANGE = (0.15, 0.5)


@dataclass
class Case:
    name: str
    robot: Robot
    n_boxes: int


def random_boxes(rng: np.random.Generator, n: int, dim: int) -> list[Box]:
    """``n`` oriented boxes, centres uniform in ``[-0.6, 0.6]^dim``, full sides in [0.15, 0.5]."""
    centers = rng.uniform(-HALF_EXTENT, HALF_EXTENT, (n, dim))
    sizes = rng.uniform(*SIDE_RANGE, (n, dim))
    if dim == 3:
        rots = lie.random_rotations(rng, n)
    else:
        a = rng.uniform(-np.pi, np.pi, n)
        rots = np.stack([np.stack([np.cos(a), -np.sin(a)], -1), np.stack([np.sin(a), np.cos(a)], -1)], -2)
    return [Box(c, s, r) for c, s, r in zip(centers, sizes, rots)]


def _lift(rotation: np.ndarray, translation: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """2D pose to a 3D pose about z (3D poses pass through)."""
    if rotation.shape == (3, 3):
        return rotation, translation
    r = np.eye(3)
    r[:2, :2] = rotation
    return r, np.array([translation[0], translation[1], 0.0])


def coal_obstacles(boxes: list[Box]) -> list[tuple[Any, Any]]:
    out = []
    for b in boxes:
        size = b.size if b.dim == 3 else np.array([b.size[0], b.size[1], 1.0])
        rot, pos = _lift(b.rotation, b.center)
        out.append((coal.Box(*map(float, size)), coal.Transform3s(rot, pos)))
    return out


def coal_loop(robot: Robot, obstacles: list[tuple[Any, Any]], q: np.ndarray) -> np.ndarray:
    """Per configuration, per robot part, per obstacle ``coal.collide``; first hit stops."""
    sc, bc, br, bh = robot.world_parts(q)
    # each part: coal geometry, per-configuration rotations (None: identity) and centres
    parts: list[tuple[Any, np.ndarray | None, np.ndarray]] = []
    for p, r in enumerate(robot.parts.sphere_radii):
        parts.append((coal.Sphere(float(r)), None, sc[:, p]))
    for p, h in enumerate(robot.parts.box_halfs):
        parts.append((coal.Box(*map(float, 2 * h)), br[:, p], bc[:, p]))
    req = coal.CollisionRequest()
    res = coal.CollisionResult()
    eye = np.eye(robot.dim)
    out = np.zeros(len(q), dtype=bool)
    for m in range(len(q)):
        hit = False
        for geom, rots, centers in parts:
            rot, pos = _lift(eye if rots is None else rots[m], centers[m])
            tf = coal.Transform3s(rot, pos)
            for ob, otf in obstacles:
                res.clear()
                if coal.collide(geom, tf, ob, otf, req, res):
                    hit = True
                    break
            if hit:
                break
        out[m] = hit
    return out


def rate(fn: Callable[[], Any], n_items: int, min_time: float) -> tuple[float, Any]:
    """Items per second of ``fn`` (best of repeats lasting at least ``min_time`` in total)."""
    out = fn()  # warm-up, and the answer
    best = np.inf
    total = 0.0
    while total < min_time:
        t0 = time.perf_counter()
        fn()
        dt = time.perf_counter() - t0
        best = min(best, dt)
        total += dt
    return n_items / best, out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="M = 1000 only and short timings")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    sizes = [1000] if args.quick else [1000, 10000]
    min_time = 0.2 if args.quick else 1.0

    cases = [
        Case("Sphere3D", Sphere3D(), 10),
        Case("Sphere3D", Sphere3D(), 50),
        Case("Disc2D", Disc2D(), 10),
        Case("Disc2D", Disc2D(), 50),
        Case("SShape", SShape(), 10),
    ]
    header = f"{'robot':<9} {'boxes':>5} {'M':>6} {'batched checks/s':>17} {'coal checks/s':>14} {'speed-up':>9} {'in collision':>12} {'agreement':>15}"
    print(header)
    print("-" * len(header))
    all_agree = True
    for case in cases:
        rng = np.random.default_rng([args.seed, case.n_boxes, case.robot.config_dim])
        robot = case.robot
        boxes = random_boxes(rng, case.n_boxes, robot.dim)
        scene = Scene(boxes, low=np.full(robot.dim, -HALF_EXTENT), high=np.full(robot.dim, HALF_EXTENT))
        world = scene.world
        obstacles = coal_obstacles(boxes)
        for m in sizes:
            q = robot.sample_uniform(rng, m, scene.low, scene.high)
            fast, fast_hit = rate(lambda robot=robot, world=world, q=q: robot.collides(world, q), m, min_time)
            t0 = time.perf_counter()
            coal_hit = coal_loop(robot, obstacles, q)
            slow = m / (time.perf_counter() - t0)
            agree = int(np.sum(fast_hit == coal_hit))
            all_agree &= agree == m
            print(
                f"{robot.name:<9} {case.n_boxes:>5} {m:>6} {fast:>17,.0f} {slow:>14,.0f} {fast / slow:>8.1f}x "
                f"{np.mean(fast_hit):>11.1%} {agree:>7}/{m:<6}{'' if agree == m else ' !'}"
            )
    print()
    print("all answers agree" if all_agree else "DISAGREEMENT: some configurations differ (marked !)")


if __name__ == "__main__":
    main()
