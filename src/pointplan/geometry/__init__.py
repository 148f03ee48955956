"""Geometry: Lie groups, shapes and batched collision."""

from . import lie
from .collision import CollisionWorld
from .shapes import Box, Capsule, Cylinder, Mesh, PointCloud, Shape, Sphere

__all__ = ["Box", "Capsule", "CollisionWorld", "Cylinder", "Mesh", "PointCloud", "Shape", "Sphere", "lie"]
