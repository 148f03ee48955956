"""Observers: obstacle observations in the robot frame."""

from __future__ import annotations

from typing import Any

from ..robots.base import Robot
from .base import Observer, PointSetObserver
from .image import OccupancyImage
from .points import InteriorPoints, SurfaceNormals, SurfacePoints

OBSERVERS: dict[str, type[Observer]] = {
    "surface": SurfacePoints,
    "surface-normals": SurfaceNormals,
    "interior": InteriorPoints,
    "image": OccupancyImage,
}


def make_observer(name: str, robot: Robot, **kwargs: Any) -> Observer:
    """An observer by name: ``surface``, ``surface-normals``, ``interior`` or ``image``."""
    try:
        cls = OBSERVERS[name]
    except KeyError:
        raise ValueError(f"unknown observation {name!r}; known: {', '.join(OBSERVERS)}") from None
    return cls(robot, **kwargs)  # type: ignore[call-arg]


__all__ = ["Observer", "PointSetObserver", "OccupancyImage", "InteriorPoints", "SurfaceNormals", "SurfacePoints", "OBSERVERS", "make_observer"]
