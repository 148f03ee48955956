"""Observers: obstacle observations in the robot frame."""

from __future__ import annotations

from typing import Any

from ..robots.base import Robot
from .base import Observer, PointSetObserver
from .image import OccupancyImage
from .rays import LocalRays
from .points import GlobalPoints, InteriorPoints, SurfaceNormals, SurfacePoints

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


__all__ = ["Observer", "PointSetObserver", "GlobalPoints", "LocalRays", "OccupancyImage", "InteriorPoints", "SurfaceNormals", "SurfacePoints", "OBSERVERS", "make_observer"]
