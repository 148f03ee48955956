"""One edge, checked the way Bi-RRT checks its edges.

The OMPL motion validator, the policy's final connection to the goal and the hybrid
planner's repairs all ask the same question: is the geodesic ``a -> b`` free and inside the
bounds? They ask it here, through :func:`~pointplan.planners.base.march` (the check Bi-RRT's
extend and connect steps use), so every planner's edges follow one rule and pass
:func:`~pointplan.evaluation.check_path`.
"""

from __future__ import annotations

import numpy as np

from ..robots.base import Robot
from .base import Array, march

#: a step longer than any edge: ``march`` then checks the geodesic as one edge
_ONE_EDGE = 1e12


def edge_free(
    robot: Robot,
    problem_or_world: object,
    a: Array,
    b: Array,
    resolution: float = 0.01,
    low: Array | None = None,
    high: Array | None = None,
) -> tuple[bool, int]:
    """Is the geodesic ``a -> b`` collision-free and inside the bounds (checked as one edge
    on the evaluator's grid, both ends included)? Returns the answer and the number of
    configurations checked. ``problem_or_world`` is what :func:`march` takes."""
    m = march(
        robot,
        problem_or_world,
        np.asarray(a, np.float64),
        np.asarray(b, np.float64),
        _ONE_EDGE,
        resolution,
        1,
        low,
        high,
    )
    if m.checks == 0:  # a == b: march checks nothing, so check the configuration itself
        from .base import _world_and_bounds, check_free

        world, lo, hi = _world_and_bounds(problem_or_world, low, high)
        return bool(check_free(robot, world, np.asarray(a, np.float64)[None], lo, hi)[0]), 1
    return bool(m.reached), int(m.checks)


__all__ = ["edge_free"]
