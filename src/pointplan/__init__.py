"""pointplan: neural motion planning from point clouds.

Rigid robots move among obstacles they see as points with normals; a PointNet encodes
the points and a policy trained with it outputs the next motion. See the README.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from . import parallel
from ._version import __version__
from .envs import register_envs, set_renderer

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import NDArray

    from .robots.base import Robot
    from .scenes.scene import Problem

# The package root sits above every subpackage and wires them together: the Gymnasium ids,
# the drawing behind ``render()``, and the default back end for ``workers`` / ``address``
# (the modules that draw and that run Ray are imported only when used).


def _render_rgb(problem: Problem, robot: Robot, q: NDArray[np.float64]) -> NDArray[np.uint8]:
    from .viz.plot2d import render_rgb

    return render_rgb(problem, robot, q)


def _ray_backend() -> parallel.Backend:
    from .distributed import RayBackend

    return RayBackend()


register_envs()
set_renderer(_render_rgb)
parallel.set_backend(_ray_backend)

__all__ = ["__version__", "register_envs"]
