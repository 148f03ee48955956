"""The evaluator's own certificate for arms: pinocchio's kinematics, coal's distances.

A second method, sharing no code with the arm's motion check (:mod:`pointplan.robots.arm`
and its compiled kernels): the arm is rebuilt from its URDF by pinocchio, its spheres and
the obstacles are coal objects, and :func:`pinocchio.computeDistances` gives every
robot-obstacle and self-collision distance at a configuration (point clouds in closed
form). The speed bound is derived here again from pinocchio's joint placements, and more
coarsely than the planners': a sphere's centre moves at most at ``sum_j R[i, j] |dq_j|``,
``R[i, j]`` the length of the kinematic chain from joint ``j``'s origin to the centre, and
the distance of any pair (sphere-obstacle or sphere-sphere) changes at most at the sum of
its spheres' bounds (no credit for joints that move both spheres together). Conservative
advancement (:meth:`ArmClearance.advance`) then certifies each joint-space segment: from a
configuration whose pair distances are ``d_k``, the next ``min_k d_k / rate_k`` of the
segment cannot bring any pair into contact.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from ..geometry.shapes import PointCloud, Shape
from .clearance import _obstacle, _winding_inside

Array = NDArray[np.float64]


def _chain_reach(model: Any, geom: Any) -> Array:
    """``R: (spheres, nq)``: the longest distance from joint ``j``'s origin to sphere ``i``'s
    centre over all configurations (the sphere's offset plus the joint-to-joint offsets
    from its joint up to and including joint ``j + 1``'s); 0 where joint ``j`` does not
    carry the sphere."""
    out = np.zeros((len(geom.geometryObjects), model.nq))
    for i, o in enumerate(geom.geometryObjects):
        total, j = float(np.linalg.norm(o.placement.translation)), int(o.parentJoint)
        while j > 0:
            out[i, model.joints[j].idx_q] = total
            total += float(np.linalg.norm(model.jointPlacements[j].translation))
            j = int(model.parents[j])
    return out


class ArmClearance:
    """Distances from an arm (spheres of its URDF, self-collision pairs of ``robot``) to a
    set of obstacles, through pinocchio and coal; ``__call__(q)`` is the smallest of the
    obstacle distances and half the self-collision distances, which together with
    :meth:`speed_bound` (the most any sphere moves) makes one advancement step safe for both."""

    def __init__(self, robot: Any, obstacles: Sequence[Shape]) -> None:
        import pinocchio as pin

        if not getattr(robot, "urdf", None):
            raise ValueError("the arm's evaluator needs the URDF it was loaded from (robot.urdf)")
        if np.any(robot.model.prismatic):
            raise NotImplementedError("the arm's evaluator bounds revolute joints only")
        self.robot = robot
        self.model = pin.buildModelFromUrdf(robot.urdf)
        self.geom = pin.buildGeomFromUrdf(
            self.model, robot.urdf, pin.GeometryType.COLLISION, package_dirs=[robot.urdf_dir]
        )
        n_arm = len(self.geom.geometryObjects)
        self.reach = _chain_reach(self.model, self.geom)  # (rows of the arm's spheres only)
        self.items = [_obstacle(s) for s in obstacles if not isinstance(s, PointCloud)]
        self.meshes = [it.mesh for it in self.items if it.mesh is not None]
        for k, it in enumerate(self.items):
            tf = it.tf
            placement = pin.SE3(np.asarray(tf.getRotation()), np.asarray(tf.getTranslation()))
            self.geom.addGeometryObject(pin.GeometryObject(f"obstacle{k}", 0, 0, placement, it.geom))
            for i in range(n_arm):
                self.geom.addCollisionPair(pin.CollisionPair(i, n_arm + k))
        self.n_world = len(self.geom.collisionPairs)
        for a, b in robot.model.self_pairs:
            self.geom.addCollisionPair(pin.CollisionPair(int(a), int(b)))
        pairs = [(p.first, p.second) for p in self.geom.collisionPairs]
        # per pair, the robot spheres it involves (an obstacle is index n_arm.., weight 0)
        self.pair_a = np.array([a for a, _ in pairs], np.int64)
        self.pair_b = np.array([b if b < n_arm else -1 for _, b in pairs], np.int64)
        clouds = [s for s in obstacles if isinstance(s, PointCloud)]
        self.tree = cKDTree(np.concatenate([s.points for s in clouds])) if clouds else None
        self.point_r = max((s.point_radius() for s in clouds), default=0.0)
        self.radii = np.array([o.geometry.radius for o in self.geom.geometryObjects[:n_arm]])
        self.data = self.model.createData()
        self.gdata = pin.GeometryData(self.geom)
        self._pin = pin

    def centers(self, q: Array) -> Array:
        """World centres of the arm's spheres at ``q`` (pinocchio's placements)."""
        pin = self._pin
        pin.forwardKinematics(self.model, self.data, np.asarray(q, np.float64))
        pin.updateGeometryPlacements(self.model, self.data, self.geom, self.gdata)
        return np.array([self.gdata.oMg[i].translation for i in range(len(self.radii))])

    def distances(self, q: Array) -> Array:
        """Every pair's distance at ``q`` (robot-obstacle pairs, then self-collision pairs),
        then, with point clouds, each sphere's distance to the nearest cloud point's sphere."""
        pin = self._pin
        pin.computeDistances(self.model, self.data, self.geom, self.gdata, np.asarray(q, np.float64))
        d = (
            np.array([r.min_distance for r in self.gdata.distanceResults])
            if len(self.geom.collisionPairs)
            else np.zeros(0)
        )
        if self.tree is not None:
            dist, _ = self.tree.query(self.centers(q))
            d = np.concatenate([d, dist - self.radii - self.point_r])
        return d

    def __call__(self, q: Array) -> float:
        """The smallest distance at ``q``, self-collision pairs included."""
        return float(self.distances(q).min(initial=math.inf))

    def rates(self, twist: Array) -> Array:
        """Per distance of :meth:`distances`: the most it changes per unit of ``s`` along
        ``q + s twist``."""
        speed = self.reach @ np.abs(np.asarray(twist, np.float64))  # per sphere
        rate = speed[self.pair_a] + np.where(self.pair_b >= 0, speed[np.maximum(self.pair_b, 0)], 0.0)
        return np.concatenate([rate, speed]) if self.tree is not None else rate

    def advance(self, q0: Array, q1: Array, touch: float, max_steps: int) -> tuple[bool, float]:
        """Conservative advancement along ``q0 -> q1``, both ends included: whether no
        distance falls below ``touch``, and the smallest distance met."""
        q0, q1 = np.asarray(q0, np.float64), np.asarray(q1, np.float64)
        rate = self.rates(q1 - q0)
        s, low = 0.0, math.inf
        for _ in range(max_steps):
            d = self.distances(q0 + s * (q1 - q0))
            low = min(low, float(d.min(initial=math.inf)))
            if low < touch:
                return False, low
            moving = rate > 0
            if s >= 1.0 or not moving.any():
                return True, low
            s = min(1.0, s + float(np.min(d[moving] / rate[moving])))
        return False, low

    def buried(self, q: Array) -> bool:
        """Is a sphere's centre inside a solid mesh obstacle?"""
        if not self.meshes:
            return False
        return any(_winding_inside(m, c) for m in self.meshes for c in self.centers(q))
