"""pointplan: neural motion planning from point clouds.

Rigid robots move among obstacles they see as points with normals; a PointNet encodes
the points and a policy trained with it outputs the next motion. See the README.
"""

from __future__ import annotations

from typing import Any

from . import parallel
from ._version import __version__
from .envs import register_envs, set_renderer

# The package root sits above every subpackage and wires them together: the Gymnasium ids,
# the drawing behind ``render()``, and the default back end for ``workers`` / ``address``
# (the modules that draw and that run Ray are imported only when used).


def _render_rgb(problem: Any, robot: Any, q: Any) -> Any:
    from .viz.plot2d import render_rgb

    return render_rgb(problem, robot, q)


def _ray_backend() -> parallel.Backend:
    from .distributed import RayBackend

    return RayBackend()


register_envs()
set_renderer(_render_rgb)
parallel.set_backend(_ray_backend)

__all__ = ["__version__", "register_envs"]
