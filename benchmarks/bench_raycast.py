"""Rays per second of ``pointplan.geometry.raycast.cast_rays``.

    python benchmarks/bench_raycast.py            # E = 1 and 16 scenes, 256 rays each
    python benchmarks/bench_raycast.py --quick    # shorter timings

Three worlds: 9 random oriented boxes; a mix of primitives (3 boxes, 2 spheres, 2
capsules, 2 cylinders, 2 cones); one mesh (a trimesh icosphere of subdivision 4, 5120
faces). With E > 1 the scenes (each drawn at random) are stacked into one batched world
and answered in one call. Rays start at random points of the workspace [-1, 1]^3 in
random directions; timings exclude building the worlds and the first (warm-up) call, which
builds the mesh intersector.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numpy as np
import trimesh

from pointplan.geometry.collision import CollisionWorld
from pointplan.geometry.raycast import cast_rays
from pointplan.geometry.shapes import Box, Capsule, Cone, Cylinder, Mesh, Shape, Sphere

N_RAYS = 256


def rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def boxes(rng: np.random.Generator) -> list[Shape]:
    return [Box(rng.uniform(-1, 1, 3), rng.uniform(0.1, 0.5, 3), rotation(rng)) for _ in range(9)]


def mix(rng: np.random.Generator) -> list[Shape]:
    out: list[Shape] = [Box(rng.uniform(-1, 1, 3), rng.uniform(0.1, 0.5, 3), rotation(rng)) for _ in range(3)]
    out += [Sphere(rng.uniform(-1, 1, 3), rng.uniform(0.1, 0.3)) for _ in range(2)]
    for _ in range(2):
        a = rng.uniform(-1, 1, 3)
        out.append(Capsule(a, a + rng.normal(size=3) * 0.3, rng.uniform(0.05, 0.2)))
    out += [
        Cylinder(rng.uniform(-1, 1, 3), rng.uniform(0.05, 0.3), rng.uniform(0.2, 0.8), rotation(rng)) for _ in range(2)
    ]
    out += [Cone(rng.uniform(-1, 1, 3), rng.uniform(0.05, 0.3), rng.uniform(0.2, 0.8), rotation(rng)) for _ in range(2)]
    return out


def mesh(rng: np.random.Generator) -> list[Shape]:
    ico = trimesh.creation.icosphere(subdivisions=4, radius=rng.uniform(0.3, 0.6))
    return [Mesh(ico.vertices + rng.uniform(-0.5, 0.5, 3), ico.faces)]


def rays_per_second(
    make: Callable[[np.random.Generator], list[Shape]], n_scenes: int, seconds: float
) -> tuple[float, float]:
    rng = np.random.default_rng(0)
    worlds = [CollisionWorld.from_shapes(make(rng), 3) for _ in range(n_scenes)]
    world = worlds[0] if n_scenes == 1 else CollisionWorld.stack(worlds)
    batch = () if n_scenes == 1 else (n_scenes,)
    o = rng.uniform(-1, 1, batch + (N_RAYS, 3))
    d = rng.normal(size=batch + (N_RAYS, 3))
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    hits = cast_rays(world, o, d)  # warm-up (builds mesh intersectors)
    reps, start = 0, time.perf_counter()
    while True:
        cast_rays(world, o, d)
        reps += 1
        elapsed = time.perf_counter() - start
        if elapsed >= seconds and reps >= 3:
            break
    return reps * n_scenes * N_RAYS / elapsed, float(hits.hit.mean())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="0.3 s per case instead of 1.5 s")
    args = parser.parse_args()
    seconds = 0.3 if args.quick else 1.5
    print(f"{'world':<8} {'E':>3} {'rays/call':>9} {'rays/s':>12} {'ms/call':>8} {'hit rate':>8}")
    for name, make in (("boxes", boxes), ("mix", mix), ("mesh", mesh)):
        for n_scenes in (1, 16):
            rate, hit = rays_per_second(make, n_scenes, seconds)
            per_call = n_scenes * N_RAYS
            print(f"{name:<8} {n_scenes:>3} {per_call:>9} {rate:>12,.0f} {1e3 * per_call / rate:>8.2f} {hit:>8.2f}")


if __name__ == "__main__":
    main()
