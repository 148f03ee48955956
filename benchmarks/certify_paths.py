"""Independent dense certification of the paths planners return.

Every path a planner returns as a success is densified at ``--spacing`` (0.001 of the
configuration distance) and the exact distance from the robot's body to every obstacle is
computed with coal at every vertex and every dense configuration (2D scenes are extruded
along z: a disc is a sphere in the plane ``z = 0``, a box a tall box). A path *touches* when
some configuration has a distance below ``--touch`` (default 0: contact or penetration);
the penetration is minus the smallest signed distance. Counted among the paths the planner
claims and, separately, among those ``pointplan.evaluation.check_path`` accepts. Moving obstacles (3D-Dynamic) are
checked in time: the path is cut into moves one action can make, and move ``k`` (from its
start pose on) against the obstacles at time ``k + 1``.

This script shares no code with the planners' motion validator or the evaluator's check:
only the robots' group operations (``integrate``/``log``, body parts) and the scenes.

    python benchmarks/certify_paths.py --scenes narrow2d                 # 400 problems, 3 planners
    python benchmarks/certify_paths.py --scenes boxes3d slot --episodes 20 --robots sphere3d sshape
    python benchmarks/certify_paths.py --scenes boxes3d --planners policy --checkpoint run/policy.pt
    python benchmarks/certify_paths.py --scenes boxes3d qureshi3d dynamic3d --robots sphere3d --planners policy --observation local
"""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import dataclass
from typing import Any

import coal
import numpy as np
from numpy.typing import NDArray

from pointplan.geometry.shapes import Box, Capsule, Cone, Cylinder, Mesh, Shape, Sphere
from pointplan.planners import make_planner
from pointplan.robots.base import Robot
from pointplan.scenes.scenarios import make_scenario
from pointplan.scenes.scene import Problem, Scene

Array = NDArray[np.float64]

SCENES_3D = ["boxes3d", "synthetic3d", "ycb3d", "dynamic3d", "slot", "slotmoving", "qureshi3d"]
#: extrusion of 2D shapes along z (tall enough that the nearest point to a body in the
#: plane z = 0 is always in that plane)
_TALL = 10.0


@dataclass
class Obstacle:
    """A coal object with a bounding sphere (for the prefilter) and, for meshes, the mesh."""

    geom: Any
    tf: Any
    center: Array
    radius: float
    mesh: Mesh | None = None


def _tf(rot: Array, pos: Array) -> Any:
    return coal.Transform3s(np.asarray(rot, np.float64), np.asarray(pos, np.float64))


def _lift(rot2: Array) -> Array:
    out = np.eye(3)
    out[:2, :2] = rot2
    return out


def _axis_frame(axis: Array) -> Array:
    z = axis / max(np.linalg.norm(axis), 1e-300)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z], 1)


def obstacle(shape: Shape, dim: int) -> Obstacle:
    """One obstacle as a coal object, 2D shapes extruded along z."""
    if isinstance(shape, Box):
        size = np.asarray(shape.size, np.float64)
        if dim == 2:
            return Obstacle(
                coal.Box(size[0], size[1], _TALL),
                _tf(_lift(shape.rotation), [*shape.center, 0.0]),
                np.array([*shape.center, 0.0]),
                float(np.linalg.norm(size) / 2),
            )
        return Obstacle(
            coal.Box(*size),
            _tf(shape.rotation, shape.center),
            np.asarray(shape.center, np.float64),
            float(np.linalg.norm(size) / 2),
        )
    if isinstance(shape, Sphere):
        c = np.array([*shape.center, 0.0]) if dim == 2 else np.asarray(shape.center, np.float64)
        return Obstacle(coal.Sphere(float(shape.radius)), _tf(np.eye(3), c), c, float(shape.radius))
    if isinstance(shape, Capsule):
        a, b = (np.array([*p, 0.0]) if dim == 2 else np.asarray(p, np.float64) for p in (shape.a, shape.b))
        length = float(np.linalg.norm(b - a))
        return Obstacle(
            coal.Capsule(float(shape.radius), length),
            _tf(_axis_frame(b - a), (a + b) / 2),
            (a + b) / 2,
            length / 2 + float(shape.radius),
        )
    if isinstance(shape, (Cylinder, Cone)):
        kind = coal.Cylinder if isinstance(shape, Cylinder) else coal.Cone
        return Obstacle(
            kind(float(shape.radius), float(shape.length)),
            _tf(shape.rotation, shape.center),
            np.asarray(shape.center, np.float64),
            float(math.hypot(shape.radius, shape.length / 2)),
        )
    if isinstance(shape, Mesh):
        model = coal.BVHModelOBBRSS()
        model.beginModel(len(shape.faces), len(shape.vertices))
        model.addVertices(np.ascontiguousarray(shape.vertices, np.float64))
        model.addTriangles(np.ascontiguousarray(shape.faces, np.int64))
        model.endModel()
        c = (shape.vertices.min(0) + shape.vertices.max(0)) / 2
        return Obstacle(
            model, _tf(np.eye(3), np.zeros(3)), c, float(np.sqrt(np.max(np.sum((shape.vertices - c) ** 2, -1)))), shape
        )
    raise TypeError(f"certify_paths does not handle {type(shape).__name__}")


def winding_inside(mesh: Mesh, p: Array) -> bool:
    """Is the point inside the closed mesh (|generalised winding number| > 1/2)?"""
    v = mesh.vertices[mesh.faces] - p  # (F, 3, 3)
    a, b, c = v[:, 0], v[:, 1], v[:, 2]
    la, lb, lc = (np.linalg.norm(x, axis=-1) for x in (a, b, c))
    num = np.einsum("fi,fi->f", a, np.cross(b, c))
    den = (
        la * lb * lc
        + np.einsum("fi,fi->f", a, b) * lc
        + np.einsum("fi,fi->f", a, c) * lb
        + np.einsum("fi,fi->f", b, c) * la
    )
    return bool(abs(np.sum(np.arctan2(num, den)) / (2 * np.pi)) > 0.5)


def body(robot: Robot, qs: Array) -> list[tuple[Any, Array, Array, float]]:
    """Per body part: coal geometry, world rotations ``(N, 3, 3)``, centres ``(N, 3)``, and
    the part's bounding radius (parts of ``robot.parts``, placed at ``qs: (N, cdim)``)."""
    rot = robot.rotations(qs)
    pos = robot.positions(qs)
    n, d = len(qs), robot.dim
    parts = robot.parts
    out = []

    def lift(c: Array, r: Array) -> tuple[Array, Array]:
        if d == 3:
            return c, r
        r3 = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
        r3[:, :2, :2] = r
        return np.concatenate([c, np.zeros((n, 1))], -1), r3

    for c, rad in zip(parts.sphere_centers, parts.sphere_radii):
        centers, rots = lift(pos + np.einsum("nij,j->ni", rot, c), rot)
        out.append((coal.Sphere(float(rad)), rots, centers, float(rad)))
    for c, br, h in zip(parts.box_centers, parts.box_rotations, parts.box_halfs):
        centers, rots = lift(pos + np.einsum("nij,j->ni", rot, c), np.einsum("nij,jk->nik", rot, br))
        out.append((coal.Box(*(2.0 * h)), rots, centers, float(np.linalg.norm(h))))
    return out


def clearance(robot: Robot, obstacles: list[Obstacle], qs: Array) -> Array:
    """Signed distance ``(N,)`` from the body at each of ``qs`` to the nearest obstacle
    (``+inf`` when nothing is within reach of the bounding spheres)."""
    best = np.full(len(qs), np.inf)
    req = coal.DistanceRequest()
    for geom, rots, centers, reach in body(robot, qs):
        for ob in obstacles:
            gap = np.linalg.norm(centers - ob.center, axis=-1) - reach - ob.radius
            best = np.minimum(best, np.where(gap > 0, gap, np.inf))  # a lower bound, far pairs
            for i in np.flatnonzero(gap <= 0):
                res = coal.DistanceResult()
                dist = coal.distance(geom, _tf(rots[i], centers[i]), ob.geom, ob.tf, req, res)
                if ob.mesh is not None and dist > 0 and winding_inside(ob.mesh, centers[i]):
                    dist = 0.0  # a body part buried inside a solid mesh
                best[i] = min(best[i], dist)
    return best


def dense(robot: Robot, path: Array, spacing: float) -> list[Array]:
    """Per segment: configurations ``(n + 1, cdim)`` from its start to its end, ``n =
    ceil(length / spacing)``."""
    out = []
    for q0, q1 in zip(path[:-1], path[1:]):
        v = robot.log(q0, q1)
        n = max(1, math.ceil(float(np.linalg.norm(v)) / spacing))
        s = np.arange(n + 1) / n
        out.append(robot.integrate(np.broadcast_to(q0, (n + 1, len(q0))), v[None] * s[:, None]))
    return out


def time_steps(robot: Robot, path: Array) -> Array:
    """The path cut into moves one action can make (each twist coordinate within the
    action scale): one move per time step."""
    out = [path[:1]]
    for q0, q1 in zip(path[:-1], path[1:]):
        v = robot.log(q0, q1)
        k = max(1, math.ceil(float(np.max(np.abs(v) / robot.action_scale)) - 1e-9))
        out.append(robot.integrate(np.broadcast_to(q0, (k, len(q0))), v[None] * (np.arange(1, k + 1) / k)[:, None]))
    return np.concatenate(out)


def worst_clearance(robot: Robot, scene: Scene, path: Array, spacing: float) -> float:
    """Smallest signed distance over the vertices and dense configurations of the path."""
    path = np.asarray(path, np.float64)
    if not scene.dynamic:
        obs = [obstacle(s, scene.dim) for s in scene.obstacles]
        qs = np.concatenate(dense(robot, path, spacing)) if len(path) > 1 else path
        return float(clearance(robot, obs, qs).min())
    timed = time_steps(robot, path)
    worst = math.inf
    for k, seg in enumerate(dense(robot, timed, spacing)):
        obs = [obstacle(s, scene.dim) for s in scene.obstacles_at(k + 1)]
        worst = min(worst, float(clearance(robot, obs, seg).min()))
    if len(timed) == 1:
        worst = float(clearance(robot, [obstacle(s, scene.dim) for s in scene.obstacles_at(0)], path).min())
    return worst


def plan_all(
    name: str,
    robot: Robot,
    problems: list[Problem],
    checkpoint: str | None,
    max_nodes: int,
    observation: str | None = None,
) -> list[Any]:
    if name == "policy":  # with the planner's defaults for the robot (its escape included)
        planner = make_planner("policy", robot, checkpoint=checkpoint, observation=None if checkpoint else observation)
        return [planner.plan(p) for p in problems]  # one by one, as the evaluator plans (greedy goal test included)
    kwargs: dict[str, Any] = {"max_nodes": max_nodes, "seed": 0} if name == "birrt" else {}
    planner = make_planner(name, robot, **kwargs)
    return [planner.plan(p) for p in problems]


def certify(scene_name: str, robot_name: str | None, planner: str, args: argparse.Namespace) -> str:
    """Plan the test problems and count the touching paths among those the planner claims
    and among those the evaluator accepts (in 3D-Dynamic, planners that ignore time claim
    paths in the scene at time 0: only the evaluator's verdict is about the moving scene)."""
    from pointplan.evaluation import check_path

    scenario = make_scenario(scene_name, robot=robot_name)
    robot = scenario.robot
    n = args.episodes_2d if robot.dim == 2 else args.episodes
    problems = scenario.problems("test", n, seed=args.seed)
    t0 = time.perf_counter()
    results = plan_all(
        planner, robot, problems, args.checkpoint, args.max_nodes, args.observation if robot.dim == 3 else None
    )
    t_plan = time.perf_counter() - t0
    count = {"claimed": [0, 0, 0.0], "accepted": [0, 0, 0.0]}  # paths, touching, deepest
    for prob, res in zip(problems, results):
        path = np.asarray(res.path, np.float64)
        if not len(path):
            continue
        kinds = [k for k, yes in (("claimed", res.success), ("accepted", bool(check_path(robot, prob, path)))) if yes]
        if not kinds:
            continue
        d = worst_clearance(robot, prob.scene, path, args.spacing)
        for k in kinds:
            count[k][0] += 1
            if d <= args.touch:
                count[k][1] += 1
                count[k][2] = max(count[k][2], -d)
    t_all = time.perf_counter() - t0
    cells = "  ".join(f"{k} {c[0]:4d} touching {c[1]:4d} (max {1000 * c[2]:.3f} mm)" for k, c in count.items())
    return f"{scene_name:12s} {robot.name:9s} {planner:9s} problems {len(problems):4d}  {cells}  plan {t_plan:.0f} s, total {t_all:.0f} s"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scenes", nargs="*", default=["narrow2d", *SCENES_3D])
    p.add_argument("--robots", nargs="*", default=["sphere3d", "sshape"], help="3D robots")
    p.add_argument(
        "--planners", nargs="*", default=None, help="default: birrt straight policy (2D), birrt straight (3D)"
    )
    p.add_argument(
        "--checkpoint",
        help="policy checkpoint for 3D scenes (default: the policy shipped for the robot; 2D: the shipped policy)",
    )
    p.add_argument(
        "--observation", help="3D, without --checkpoint: which shipped policy (global or local; default: the robot's)"
    )
    p.add_argument("--episodes", type=int, default=100, help="test problems per 3D scene")
    p.add_argument("--episodes-2d", type=int, default=400, help="2D-Narrow test problems")
    p.add_argument("--spacing", type=float, default=0.001)
    p.add_argument("--touch", type=float, default=0.0, help="distance at or below which a path touches")
    p.add_argument("--max-nodes", type=int, default=20000)
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args()
    for scene in args.scenes:
        robots: list[str | None] = [None] if scene == "narrow2d" else list(args.robots)
        for robot in robots:
            default = ["birrt", "straight", "policy"] if scene == "narrow2d" else ["birrt", "straight"]
            for planner in args.planners or default:
                print(certify(scene, robot, planner, args), flush=True)


if __name__ == "__main__":
    main()
