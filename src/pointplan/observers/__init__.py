"""Observers: obstacle observations in the robot frame."""

from __future__ import annotations

from typing import Any

from ..robots.base import Robot
from .base import Observer, PointSetObserver
from .image import OccupancyImage
from .points import GlobalPoints, InteriorPoints, SurfaceNormals, SurfacePoints
from .rays import LocalRays

OBSERVERS: dict[str, type[Observer]] = {
    "surface": SurfacePoints,
    "surface-normals": SurfaceNormals,
    "interior": InteriorPoints,
    "image": OccupancyImage,
    "global": GlobalPoints,
    "local": LocalRays,
}


def make_observer(name: str, robot: Robot, **kwargs: Any) -> Observer:
    """An observer by name: ``surface``, ``surface-normals``, ``interior``, ``image`` (2D) or
    ``global``, ``local`` (3D)."""
    try:
        cls = OBSERVERS[name]
    except KeyError:
        raise ValueError(f"unknown observation {name!r}; known: {', '.join(OBSERVERS)}") from None
    return cls(robot, **kwargs)  # type: ignore[call-arg]


__all__ = ["OBSERVERS", "GlobalPoints", "InteriorPoints", "LocalRays", "Observer", "OccupancyImage", "PointSetObserver", "SurfaceNormals", "SurfacePoints", "make_observer"]
