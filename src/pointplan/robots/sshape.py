"""The S-shaped free-flying body (6 DoF): five square bars."""

from __future__ import annotations

import numpy as np

from ..geometry import lie
from .base import Array, BodyParts, Robot

#: centreline corners of the S-shape, body frame (from the paper's release)
S_CORNERS = np.array(
    [
        [-0.155, -0.082, 0.009],
        [0.009, -0.082, 0.009],
        [0.009, 0.082, 0.009],
        [0.009, 0.082, 0.173],
        [0.173, 0.082, 0.173],
        [0.173, 0.082, 0.009],
    ]
)
BAR_THICKNESS = 0.036
BAR_LENGTH = 0.2


def _bars() -> BodyParts:
    centers, rots, halfs = [], [], []
    for a, b in zip(S_CORNERS[:-1], S_CORNERS[1:]):
        axis = int(np.argmax(np.abs(b - a)))
        centers.append((a + b) / 2)
        rots.append(np.eye(3))
        h = np.full(3, BAR_THICKNESS / 2)
        # each bar is 0.2 long: the centreline segment (0.164) plus half a thickness each end
        h[axis] = BAR_LENGTH / 2
        halfs.append(h)
    return BodyParts(
        sphere_centers=np.zeros((0, 3)),
        sphere_radii=np.zeros(0),
        box_centers=np.array(centers),
        box_rotations=np.array(rots),
        box_halfs=np.array(halfs),
    )


class SShape(Robot):
    """Configuration ``(x, y, z, qx, qy, qz, qw)``; twists ``(vx, vy, vz, wx, wy, wz)`` in the
    body frame, scaled by 0.07 per translation axis and 0.2 rad per rotation axis."""

    name = "sshape"
    dim = 3
    config_dim = 7
    twist_dim = 6

    def __init__(self, step: float = 0.07, rot_step: float = 0.2) -> None:
        self.action_scale = np.array([step] * 3 + [rot_step] * 3)
        self.parts = _bars()

    @staticmethod
    def to_matrix(q: Array) -> Array:
        """Homogeneous matrices ``(..., 4, 4)`` of configurations."""
        q = np.asarray(q, np.float64)
        out = np.zeros(q.shape[:-1] + (4, 4))
        out[..., :3, :3] = lie.quat_to_matrix(q[..., 3:])
        out[..., :3, 3] = q[..., :3]
        out[..., 3, 3] = 1.0
        return out

    @staticmethod
    def from_matrix(t: Array) -> Array:
        t = np.asarray(t, np.float64)
        return np.concatenate([t[..., :3, 3], lie.matrix_to_quat(t[..., :3, :3])], -1)

    def integrate(self, q: Array, v: Array) -> Array:
        return self.from_matrix(self.to_matrix(q) @ lie.se3_exp(v))

    def log(self, q0: Array, q1: Array) -> Array:
        return lie.relative_twist(self.to_matrix(q0), self.to_matrix(q1))

    def rotations(self, q: Array) -> Array:
        return lie.quat_to_matrix(np.asarray(q, np.float64)[..., 3:])

    def sample_orientation(self, rng: np.random.Generator, n: int) -> Array:
        return lie.matrix_to_quat(lie.random_rotations(rng, n))
