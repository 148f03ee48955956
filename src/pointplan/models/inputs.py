"""What the networks are fed: observations and goals in units of one policy step.

Networks learn slowly when the structure they must resolve is small against their input's
scale: in 2D-Narrow a step is 0.07 and the success region is 0.07 wide, while raw goal
vectors and point positions span a metre. So goal vectors are divided by the action scale
(translations by 0.07, rotations by 0.2 rad) and point positions by the translation scale;
normals and occupancy images are left as they are. Training and inference both go through
these two functions.
"""

from __future__ import annotations

import numpy as np

from ..robots.base import Robot


def goal_input(robot: Robot, q: np.ndarray, goal: np.ndarray) -> np.ndarray:
    """``log(q^-1 goal) / action_scale``: the goal in steps, then the robot's
    :meth:`~pointplan.robots.base.Robot.state_features` (none for rigid robots),
    ``(..., goal_dim(robot))`` float32."""
    g = (robot.goal_vector(q, goal) / robot.action_scale).astype(np.float32)
    if not robot.state_feature_dim:
        return g
    return np.concatenate([g, robot.state_features(q, goal).astype(np.float32)], -1)


def goal_dim(robot: Robot) -> int:
    """The width of :func:`goal_input`: the twist's, plus the robot's state features."""
    return int(robot.twist_dim + robot.state_feature_dim)


def obs_input(robot: Robot, obs: np.ndarray, copy: bool = True) -> np.ndarray:
    """Point observations ``(..., N, F)`` with positions in steps; images unchanged.
    ``copy=False`` scales a float32 ``obs`` in place (for arrays too large to copy)."""
    obs = np.asarray(obs, np.float32)
    if obs.ndim >= 3 and obs.shape[-1] in (robot.dim, 2 * robot.dim) and obs.shape[-2] != obs.shape[-1]:
        out = obs.copy() if copy else obs
        out[..., : robot.dim] /= np.float32(robot.action_scale[0])
        return out
    return obs
