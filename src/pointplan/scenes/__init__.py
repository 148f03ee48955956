"""Scenes: obstacles, bounds, problems, generators and the scene file format."""

from .scene import Problem, Scene

__all__ = ["Problem", "Scene"]
