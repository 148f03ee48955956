"""pointplan: neural motion planning from point clouds.

Rigid robots move among obstacles they see as points with normals; a PointNet encodes
the points and a policy trained with it outputs the next motion. See the README.
"""

from __future__ import annotations

__version__ = "0.1.0"

from .envs import register_envs

register_envs()

__all__ = ["__version__", "register_envs"]
