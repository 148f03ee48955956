"""Robots: body geometry and configuration space."""

from .base import BodyParts, Robot
from .point import Disc2D, Sphere3D
from .sshape import OrientedSShape, SShape

ROBOTS: dict[str, type[Robot]] = {
    "disc2d": Disc2D,
    "sphere3d": Sphere3D,
    "sshape": SShape,
    "sshape-oriented": OrientedSShape,
}


def make_robot(name: str) -> Robot:
    """A robot by name (``disc2d``, ``sphere3d``, ``sshape``, ``sshape-oriented``, or a shipped arm: ``panda``, ``ur5``)."""
    from .arm import ARMS, make_arm

    if name in ARMS:
        return make_arm(name)
    try:
        return ROBOTS[name]()
    except KeyError:
        raise ValueError(f"unknown robot {name!r}; known: {', '.join([*ROBOTS, *ARMS])}") from None


__all__ = ["ROBOTS", "BodyParts", "Disc2D", "OrientedSShape", "Robot", "SShape", "Sphere3D", "make_robot"]
