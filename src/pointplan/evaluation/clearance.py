"""The evaluator's own certificate: exact clearances and conservative advancement.

This is deliberately a second method, sharing no code with the robots' motion validator
(:mod:`pointplan.robots.motion`) or the batched collision checker: distances come from coal
(2D shapes are extruded along z, the disc is a sphere in the plane ``z = 0``), point clouds
in closed form. Along a geodesic ``q0 exp(s v)`` every body point moves at most ``V |ds|``
(:func:`speed_bound`), so from a configuration with clearance ``d`` the next ``d / V`` of
``s`` cannot touch anything: the check advances by that much and repeats, and calls a
clearance below :data:`TOUCH` a contact.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..geometry.shapes import Box, Capsule, Cone, Cylinder, Mesh, PointCloud, Shape, Sphere
from ..robots.base import Robot

Array = NDArray[np.float64]

#: a clearance below this is a contact
TOUCH = 1e-6
#: 2D shapes become prisms this tall along z
_TALL = 10.0
#: give up on a segment after this many advancement steps (counted as touching)
MAX_STEPS = 200_000


def _coal() -> Any:
    import coal

    return coal


def _tf(rot: Array, pos: Array) -> Any:
    return _coal().Transform3s(np.ascontiguousarray(rot, np.float64), np.ascontiguousarray(pos, np.float64))


def _to3(p: Array) -> Array:
    p = np.asarray(p, np.float64)
    return p if p.shape[-1] == 3 else np.concatenate([p, np.zeros(p.shape[:-1] + (1,))], -1)


def _rot3(r: Array) -> Array:
    r = np.asarray(r, np.float64)
    if r.shape[-1] == 3:
        return r
    out = np.zeros(r.shape[:-2] + (3, 3))
    out[..., :2, :2] = r
    out[..., 2, 2] = 1.0
    return out


@dataclass
class _Obstacle:
    geom: Any
    tf: Any
    center: Array  # bounding sphere, 3D
    radius: float
    mesh: Mesh | None = None


def _frame_z(axis: Array) -> Array:
    z = axis / max(float(np.linalg.norm(axis)), 1e-300)
    x = np.cross(np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0]), z)
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z], 1)


def _obstacle(s: Shape) -> _Obstacle:
    """A coal object with a bounding sphere for one obstacle (2D: extruded)."""
    coal = _coal()
    if isinstance(s, Box):
        size = np.asarray(s.size, np.float64)
        full = size if len(size) == 3 else np.array([*size, _TALL])
        return _Obstacle(
            coal.Box(*full), _tf(_rot3(s.rotation), _to3(s.center)), _to3(s.center), float(np.linalg.norm(size) / 2)
        )
    if isinstance(s, Sphere):
        return _Obstacle(coal.Sphere(float(s.radius)), _tf(np.eye(3), _to3(s.center)), _to3(s.center), float(s.radius))
    if isinstance(s, Capsule):
        a, b = _to3(s.a), _to3(s.b)
        half = float(np.linalg.norm(b - a)) / 2
        return _Obstacle(
            coal.Capsule(float(s.radius), 2 * half),
            _tf(_frame_z(b - a), (a + b) / 2),
            (a + b) / 2,
            half + float(s.radius),
        )
    if isinstance(s, (Cylinder, Cone)):
        kind = coal.Cylinder if isinstance(s, Cylinder) else coal.Cone
        return _Obstacle(
            kind(float(s.radius), float(s.length)),
            _tf(s.rotation, s.center),
            np.asarray(s.center, np.float64),
            math.hypot(s.radius, s.length / 2),
        )
    if isinstance(s, Mesh):
        model = coal.BVHModelOBBRSS()
        model.beginModel(len(s.faces), len(s.vertices))
        model.addVertices(np.ascontiguousarray(s.vertices, np.float64))
        model.addTriangles(np.ascontiguousarray(s.faces, np.int64))
        model.endModel()
        c = (s.vertices.min(0) + s.vertices.max(0)) / 2 if len(s.vertices) else np.zeros(3)
        r = float(np.sqrt(np.max(np.sum((s.vertices - c) ** 2, -1)))) if len(s.vertices) else 0.0
        return _Obstacle(model, _tf(np.eye(3), np.zeros(3)), c, r, s)
    raise TypeError(f"no clearance for {type(s).__name__}")


def _winding_inside(mesh: Mesh, p: Array) -> bool:
    """Is ``p: (3,)`` inside the closed mesh (generalised winding number above 1/2)?"""
    if not len(mesh.faces):
        return False
    v = mesh.vertices[mesh.faces] - p
    a, b, c = v[:, 0], v[:, 1], v[:, 2]
    la, lb, lc = (np.linalg.norm(x, axis=-1) for x in (a, b, c))
    num = np.einsum("fi,fi->f", a, np.cross(b, c))
    den = (
        la * lb * lc
        + np.einsum("fi,fi->f", a, b) * lc
        + np.einsum("fi,fi->f", a, c) * lb
        + np.einsum("fi,fi->f", b, c) * la
    )
    return bool(abs(np.sum(np.arctan2(num, den))) / (2 * np.pi) > 0.5)


class Clearance:
    """Exact distance from a robot's body to a set of obstacles (one scene at one time)."""

    def __init__(self, robot: Robot, obstacles: Sequence[Shape]) -> None:
        coal = _coal()
        self.robot = robot
        self.items = [_obstacle(s) for s in obstacles if not isinstance(s, PointCloud)]
        clouds = [s for s in obstacles if isinstance(s, PointCloud)]
        self.points = (
            np.concatenate([np.asarray(s.points, np.float64) for s in clouds]) if clouds else np.zeros((0, robot.dim))
        )
        # each cloud point stands for a sphere of its cloud's point radius
        self.point_r = (
            np.concatenate([np.full(len(s.points), s.point_radius()) for s in clouds]) if clouds else np.zeros(0)
        )
        p = robot.parts
        halfs = [h if len(h) == 3 else np.array([*h, _TALL / 2]) for h in p.box_halfs]
        self.geoms = [coal.Sphere(float(r)) for r in p.sphere_radii] + [coal.Box(*(2 * h)) for h in halfs]
        self.reach = np.concatenate([p.sphere_radii, np.linalg.norm(p.box_halfs, axis=-1)])
        self.request = coal.DistanceRequest()

    def _parts(self, q: Array) -> tuple[Array, Array]:
        """World centres ``(P, 3)`` and rotations ``(P, 3, 3)`` of the body parts."""
        r = self.robot
        rot, pos = r.rotations(q), r.positions(q)
        p = r.parts
        centers = np.concatenate([p.sphere_centers, p.box_centers]) @ rot.T + pos
        rots = np.concatenate([np.broadcast_to(rot, (len(p.sphere_radii),) + rot.shape), rot @ p.box_rotations])
        return _to3(centers), _rot3(rots)

    def __call__(self, q: Array) -> float:
        """Smallest signed distance from the body at ``q: (config_dim,)`` to an obstacle."""
        coal = _coal()
        centers, rots = self._parts(q)
        best = self._cloud_distance(centers, rots) if len(self.points) else math.inf
        for k, geom in enumerate(self.geoms):
            for ob in self.items:
                gap = float(np.linalg.norm(centers[k] - ob.center)) - self.reach[k] - ob.radius
                if gap >= best:
                    continue
                res = coal.DistanceResult()
                best = min(
                    best, float(coal.distance(geom, _tf(rots[k], centers[k]), ob.geom, ob.tf, self.request, res))
                )
        return best

    def _cloud_distance(self, centers: Array, rots: Array) -> float:
        """Distance from the point clouds (each point a sphere of its cloud's point radius)
        to the parts, in closed form."""
        p = self.robot.parts
        pts = _to3(self.points)
        best = math.inf
        for k in range(len(self.geoms)):
            local = (pts - centers[k]) @ rots[k]
            if k < len(p.sphere_radii):
                d = np.linalg.norm(local, axis=-1) - p.sphere_radii[k]
            else:
                h = _to3(p.box_halfs[k - len(p.sphere_radii)])
                if len(p.box_halfs[0]) == 2:
                    h[2] = _TALL / 2
                out = np.maximum(np.abs(local) - h, 0.0)
                d = np.where(np.any(out > 0, -1), np.linalg.norm(out, axis=-1), -np.min(h - np.abs(local), -1))
            best = min(best, float((d - self.point_r).min()))
        return best

    def buried(self, q: Array) -> bool:
        """Is a body part inside a solid mesh, or a mesh inside a part? (A body that never
        touches a mesh's surface stays on one side of it, so this is asked once per
        stretch of motion.)"""
        centers, rots = self._parts(q)
        for ob in self.items:
            if ob.mesh is None or not len(ob.mesh.vertices):
                continue
            if any(_winding_inside(ob.mesh, c) for c in centers):
                return True
            for k in range(len(self.geoms)):
                x = (ob.mesh.vertices[0] - centers[k]) @ rots[k]
                if k < len(self.robot.parts.sphere_radii):
                    inside = np.linalg.norm(x) <= self.robot.parts.sphere_radii[k]
                else:
                    inside = bool(
                        np.all(np.abs(x) <= self.robot.parts.box_halfs[k - len(self.robot.parts.sphere_radii)])
                    )
                if inside:
                    return True
        return False


def speed_bound(robot: Robot, twist: Array) -> float:
    """Largest distance any body point moves per unit of ``s`` along ``q exp(s twist)``:
    the body-frame velocity of point ``p`` is ``v + w x p`` (constant along a geodesic of
    SE(3)), a convex function of ``p`` whose maximum over a box is at a corner; for a
    robot that only translates it is ``|v|``."""
    twist = np.asarray(twist, np.float64)
    if robot.twist_dim == robot.dim:
        return float(np.linalg.norm(twist))
    if robot.twist_dim != 6:
        raise NotImplementedError(f"no speed bound for {type(robot).__name__}")
    v, w = twist[:3], twist[3:]
    p = robot.parts
    signs = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], np.float64)
    corners = (
        p.box_centers[:, None, :] + np.einsum("pij,pkj->pki", p.box_rotations, signs[None] * p.box_halfs[:, None, :])
    ).reshape(-1, 3)
    speeds = np.linalg.norm(v + np.cross(w, corners), axis=-1) if len(corners) else np.zeros(0)
    balls = np.linalg.norm(v + np.cross(w, p.sphere_centers), axis=-1) + np.linalg.norm(w) * p.sphere_radii
    return float(max(speeds.max(initial=0.0), balls.max(initial=0.0)))


def advance(clearance: Clearance, robot: Robot, q0: Array, q1: Array) -> tuple[bool, float]:
    """Conservative advancement along the geodesic ``q0 -> q1``, both ends included.
    Returns whether no configuration comes within :data:`TOUCH` of an obstacle, and the
    smallest clearance met."""
    own = getattr(clearance, "advance", None)  # an arm's clearance advances pair by pair
    if own is not None:
        return own(q0, q1, TOUCH, MAX_STEPS)  # type: ignore[no-any-return]
    v = robot.log(q0, q1)
    return advance_along(clearance, lambda s: q0 if s == 0.0 else robot.integrate(q0, v * s), speed_bound(robot, v))


def advance_along(clearance: Clearance, pose: Callable[[float], Array], speed: float) -> tuple[bool, float]:
    """Conservative advancement along any motion ``pose(s)``, ``s`` in ``[0, 1]``, no body
    point of which moves faster than ``speed`` per unit of ``s``: from a configuration with
    clearance ``d`` the next ``d / speed`` of ``s`` cannot touch. Returns whether no
    configuration comes within :data:`TOUCH` of an obstacle, and the smallest clearance met."""
    s, low = 0.0, math.inf
    for _ in range(MAX_STEPS):
        d = clearance(pose(s))
        low = min(low, d)
        if d < TOUCH:
            return False, low
        if s >= 1.0 or speed <= 0.0:
            return True, low
        s = min(1.0, s + d / speed)
    return False, low
