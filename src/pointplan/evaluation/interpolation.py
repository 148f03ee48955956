"""Paths as other systems follow them: translation linear, rotation by slerp.

pointplan joins two S-shape configurations by the screw motion ``q0 exp(s log(q0, q1))``
(rotation and translation coupled). OMPL's SE(3) space, MoveIt and most controllers
interpolate the position linearly and the orientation by spherical linear interpolation
(slerp) instead; read that way, an edge that is free as a screw motion may cut an
obstacle. :func:`linear_slerp_free` certifies an edge under that reading (conservative
advancement on the evaluator's exact clearances), and :func:`for_linear_slerp` makes a
path free under both readings by splitting the edges that are not at their screw
midpoints (the screw path stays the same curve; its shorter edges bend less from it).

Why the advancement is safe: along ``p(s) = p0 + s (p1 - p0)``, ``R(s) = slerp(R0, R1,
s)`` the orientation turns at the constant rate ``theta`` (the angle between ``R0`` and
``R1``) about a fixed axis, so a body point ``x`` moves at ``|p1 - p0 + omega x R(s) x| <=
|p1 - p0| + theta |x|``; no point of the body moves faster than ``|p1 - p0| + theta rho``
(``rho``: the largest distance of a body point from the body origin), so from a
configuration with clearance ``d`` the next ``d / speed`` of ``s`` cannot touch.

For the robots that only translate (the disc, the sphere) both readings are the straight
line and paths come back unchanged.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ..robots.base import Robot
from ..scenes.scene import Problem
from .clearance import Clearance, advance_along

Array = NDArray[np.float64]


def _translates_only(robot: Robot) -> bool:
    return robot.twist_dim == robot.dim


def slerp_pose(q0: Array, q1: Array, s: float) -> Array:
    """The S-shape configuration ``(x, y, z, qx, qy, qz, qw)`` at ``s`` in ``[0, 1]`` of the
    linear + slerp interpolation from ``q0`` to ``q1`` (the shorter arc of rotations)."""
    q0, q1 = np.asarray(q0, np.float64), np.asarray(q1, np.float64)
    a, b = q0[3:] / np.linalg.norm(q0[3:]), q1[3:] / np.linalg.norm(q1[3:])
    dot = float(np.dot(a, b))
    if dot < 0.0:  # q and -q are one rotation: take the shorter way
        b, dot = -b, -dot
    half = math.acos(min(1.0, dot))
    rot = a + s * (b - a) if half < 1e-9 else (math.sin((1 - s) * half) * a + math.sin(s * half) * b) / math.sin(half)
    return np.concatenate([q0[:3] + s * (q1[:3] - q0[:3]), rot / np.linalg.norm(rot)])


def body_radius(robot: Robot) -> float:
    """The largest distance of a point of the robot's body from its origin (box corners,
    sphere parts' far sides)."""
    p = robot.parts
    out = 0.0
    if len(p.box_halfs):
        signs = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], np.float64)[:, : robot.dim]
        corners = p.box_centers[:, None, :] + np.einsum(
            "pij,pkj->pki", p.box_rotations, signs[None] * p.box_halfs[:, None, :]
        )
        out = float(np.linalg.norm(corners, axis=-1).max())
    if len(p.sphere_radii):
        out = max(out, float((np.linalg.norm(p.sphere_centers, axis=-1) + p.sphere_radii).max()))
    return out


def linear_slerp_free(clearance: Clearance, robot: Robot, q0: Array, q1: Array) -> tuple[bool, float]:
    """Conservative advancement along the linear + slerp interpolation ``q0 -> q1`` (both
    ends included): whether no configuration comes within
    :data:`~pointplan.evaluation.clearance.TOUCH` of an obstacle, and the smallest
    clearance met (see the module's docstring for the speed bound)."""
    q0, q1 = np.asarray(q0, np.float64), np.asarray(q1, np.float64)
    a, b = q0[3:] / np.linalg.norm(q0[3:]), q1[3:] / np.linalg.norm(q1[3:])
    theta = 2.0 * math.acos(min(1.0, abs(float(np.dot(a, b)))))
    speed = float(np.linalg.norm(q1[:3] - q0[:3])) + theta * body_radius(robot)
    return advance_along(clearance, lambda s: slerp_pose(q0, q1, s), speed)


def check_linear_slerp(robot: Robot, problem: Problem, path: Array) -> tuple[bool, int]:
    """Is every edge of ``path`` free when followed by linear + slerp interpolation (static
    scenes)? Returns the answer and the index of the first edge that is not (-1)."""
    path = np.asarray(path, np.float64)
    if _translates_only(robot):
        raise ValueError(f"{robot.name} only translates: its paths are straight lines under both readings")
    clear = Clearance(robot, problem.scene.obstacles)
    for j in range(len(path) - 1):
        if not linear_slerp_free(clear, robot, path[j], path[j + 1])[0]:
            return False, j
    return True, -1


def for_linear_slerp(robot: Robot, problem: Problem, path: Array, max_depth: int = 12) -> Array:
    """``path`` (free as screw motions) with every edge that is not free under linear +
    slerp interpolation split at its screw midpoint, recursively, until every edge is free
    under both readings. Static scenes. Raises ``ValueError`` when an edge still is not
    after ``max_depth`` halvings (the screw path grazes an obstacle there)."""
    path = np.asarray(path, np.float64)
    if _translates_only(robot) or len(path) < 2:
        return path
    if problem.scene.dynamic:
        raise ValueError("for_linear_slerp plans for static scenes only")
    clear = Clearance(robot, problem.scene.obstacles)
    out = [path[0]]
    for j in range(len(path) - 1):
        stack = [(path[j], path[j + 1], 0)]
        while stack:  # depth first, so the pieces come out in order
            a, b, depth = stack.pop()
            if linear_slerp_free(clear, robot, a, b)[0]:
                out.append(b)
                continue
            if depth >= max_depth:
                raise ValueError(
                    f"edge {j} of the path is not free under linear + slerp interpolation even split {2**depth} times"
                )
            mid = robot.integrate(a, 0.5 * robot.log(a, b))
            stack += [(mid, b, depth + 1), (a, mid, depth + 1)]
    return np.stack(out)


__all__ = ["body_radius", "check_linear_slerp", "for_linear_slerp", "linear_slerp_free", "slerp_pose"]
