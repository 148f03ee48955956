"""Observers: obstacle observations in the robot frame."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ..robots.base import Robot
from ..scenes.scene import Problem
from .base import Observer, PointSetObserver
from .image import OccupancyImage
from .points import GlobalPoints, InteriorPoints, SurfaceNormals, SurfacePoints
from .rays import LocalRays, NearestRays, WideRays

OBSERVERS: dict[str, type[Observer]] = {
    "surface": SurfacePoints,
    "surface-normals": SurfaceNormals,
    "interior": InteriorPoints,
    "image": OccupancyImage,
    "global": GlobalPoints,
    "local": LocalRays,
    "local-near": NearestRays,
    "local-wide": WideRays,
}


def make_observer(name: str, robot: Robot, **kwargs: Any) -> Observer:
    """An observer by name: ``surface``, ``surface-normals``, ``interior``, ``image`` (2D) or
    ``global``, ``local``, ``local-near``, ``local-wide`` (3D)."""
    try:
        cls = OBSERVERS[name]
    except KeyError:
        raise ValueError(f"unknown observation {name!r}; known: {', '.join(OBSERVERS)}") from None
    return cls(robot, **kwargs)  # type: ignore[call-arg]


def world_observation(
    problem: Problem, robot: Robot, observation: str, n_points: int | None, q: ArrayLike, t: int, seed: int
) -> tuple[np.ndarray, np.ndarray]:
    """What the robot at ``q`` (time ``t``) observes, back in the world frame: the points
    and their normals (3D; padding rows dropped)."""
    observer = make_observer(observation, robot, **({"n_points": n_points} if n_points else {}))
    observer.bind([problem.scene])
    q = np.asarray(q, np.float64)
    obs = observer.observe(q[None], np.random.default_rng(seed), np.array([t]))[0]
    rot, pos = robot.rotations(q), robot.positions(q)
    keep = np.any(obs != 0.0, axis=1)
    return obs[keep, :3] @ rot.T + pos, obs[keep, 3:6] @ rot.T


__all__ = [
    "OBSERVERS",
    "GlobalPoints",
    "InteriorPoints",
    "LocalRays",
    "NearestRays",
    "WideRays",
    "Observer",
    "OccupancyImage",
    "PointSetObserver",
    "SurfaceNormals",
    "SurfacePoints",
    "make_observer",
    "world_observation",
]
