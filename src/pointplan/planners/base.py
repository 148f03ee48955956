"""What every planner returns, and the interface it implements.

A planner takes a :class:`~pointplan.scenes.scene.Problem` and returns a
:class:`PlanResult`. Paths are sequences of configurations joined by the robot's
geodesics (``robot.interpolate``); the evaluator re-checks them independently.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from ..robots.base import Robot
from ..scenes.scene import Problem

Array = NDArray[np.float64]


@dataclass
class PlanResult:
    """The outcome of one planning query."""

    #: ``(K, config_dim)`` configurations joined by geodesics; ``(0, config_dim)`` on failure
    path: Array
    #: what the planner claims (the evaluator checks the path itself)
    success: bool
    #: configurations explored / added to the search trees (straight line: number of steps)
    nodes: int
    #: configurations checked for collision
    collision_checks: int
    #: wall time of the query, seconds
    time_s: float
    #: per search tree: node configurations ``(n, config_dim)`` and parent indices ``(n,)``
    #: (``-1`` for a root), for drawing
    trees: list[tuple[Array, NDArray[np.int64]]] = field(default_factory=list)
    #: the path before shortcutting, if the planner smooths it
    raw_path: Array | None = None
    #: planner-specific details (e.g. the policy's ``end`` and ``goal_connection``, OMPL's
    #: ``status``, the hybrid planner's split of nodes)
    info: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def failure(cls, config_dim: int, nodes: int, collision_checks: int, time_s: float, **kw: object) -> PlanResult:
        """A failed query: empty path, ``success=False``."""
        return cls(np.zeros((0, config_dim)), False, int(nodes), int(collision_checks), float(time_s), **kw)  # type: ignore[arg-type]


@runtime_checkable
class Planner(Protocol):
    """Anything with a ``name`` and a ``plan(problem) -> PlanResult`` method."""

    name: str

    def plan(self, problem: Problem) -> PlanResult: ...


def path_length(robot: Robot, path: Array) -> float:
    """Sum of the geodesic distances between consecutive configurations of ``path``."""
    path = np.asarray(path, np.float64)
    if len(path) < 2:
        return 0.0
    return float(np.sum(robot.distance(path[:-1], path[1:])))


def in_bounds(robot: Robot, q: Array, low: Array, high: Array, eps: float = 1e-9) -> NDArray[np.bool_]:
    """Are the positions of configurations ``q: (..., config_dim)`` inside ``[low, high]``?"""
    pos = robot.positions(q)
    return np.all((pos >= np.asarray(low) - eps) & (pos <= np.asarray(high) + eps), axis=-1)


@dataclass
class March:
    """Outcome of :func:`march`: how far a geodesic could be followed in steps."""

    #: configurations at the end of each free step, ``(n_free, config_dim)``
    nodes: Array
    #: whether the last free step ends at the target (the whole geodesic is free)
    reached: bool
    #: configurations an edge-by-edge check evaluates (through the first blocked edge)
    checks: int


#: slack on ``length / resolution`` before rounding up, so that an edge of exactly ``step``
#: gets the same number of intervals whatever the round-off of its length
GRID_SLACK = 1e-9


def intervals(length: Array, resolution: float) -> NDArray[np.int64]:
    """Intervals of a checked edge: ``max(1, ceil(length / resolution - GRID_SLACK))``."""
    return np.maximum(1, np.ceil(np.asarray(length) / resolution - GRID_SLACK).astype(np.int64))


def _grid(m: NDArray[np.int64]) -> tuple[NDArray[np.int64], Array]:
    """For edges of ``m`` intervals: edge index and fraction ``j / m`` of every grid point,
    ``j = 0..m`` (both ends included), edge after edge."""
    counts = m + 1
    starts = np.cumsum(counts) - counts
    idx = np.repeat(np.arange(len(m)), counts)
    return idx, (np.arange(int(counts.sum())) - starts[idx]) / m[idx]


def march(
    robot: Robot,
    problem_or_world: object,
    q0: Array,
    q1: Array,
    step: float,
    resolution: float,
    max_steps: int | None = None,
    low: Array | None = None,
    high: Array | None = None,
    twist: Array | None = None,
) -> March:
    """Follow the geodesic ``q0 -> q1`` in edges of length ``step`` (the last one shorter),
    each edge checked at ``intervals(length, resolution) + 1`` evenly spaced configurations,
    both ends included.

    Stops at the first edge that collides or leaves the bounds, or after ``max_steps``
    edges. All edges are checked in one ``robot.collides`` call; ``checks`` counts what an
    edge-by-edge check would evaluate (every configuration of every edge up to and
    including the first blocked one), so it does not depend on the batching. ``twist``
    may pass ``robot.log(q0, q1)`` if it is already known.

    ``problem_or_world`` is a :class:`Problem` or a scene (bounds taken from it) or a
    ``CollisionWorld`` together with ``low`` and ``high``.
    """
    world, low, high = _world_and_bounds(problem_or_world, low, high)
    q0 = np.asarray(q0, np.float64)
    q1 = np.asarray(q1, np.float64)
    v = robot.log(q0, q1) if twist is None else np.asarray(twist, np.float64)
    d = float(np.linalg.norm(v))
    cdim = q0.shape[-1]
    if d <= 1e-12:
        return March(np.zeros((0, cdim)), True, 0)
    total = max(1, int(np.ceil(d / step - GRID_SLACK)))
    n = total if max_steps is None else min(total, int(max_steps))
    if n <= 0:
        return March(np.zeros((0, cdim)), False, 0)
    # Edge ends at fractions ``ends`` of the geodesic. It is a one-parameter subgroup, so the
    # geodesic between two edge ends is the matching piece of the whole one: every grid
    # point is ``q0 exp(s v)``, one exponential for all of them.
    ends = np.minimum(np.arange(n + 1) * (step / d), 1.0)
    reached = n == total
    if reached:
        ends[-1] = 1.0
    m = intervals((ends[1:] - ends[:-1]) * d, resolution)
    idx, frac = _grid(m)
    s = ends[idx] + (ends[idx + 1] - ends[idx]) * frac
    qs = robot.integrate(q0[None], v[None] * s[:, None])
    offsets = np.cumsum(m + 1)
    bad = robot.collides(world, qs) | ~in_bounds(robot, qs, low, high)  # type: ignore[arg-type]
    if bad.any():
        n_free = int(np.searchsorted(offsets, int(np.argmax(bad)), side="right"))  # first bad edge
        checks = int(offsets[n_free])
        reached = False
    else:
        n_free = n
        checks = int(offsets[-1])
    nodes = qs[offsets[:n_free] - 1]  # the far end of each free edge
    if reached:
        nodes[-1] = q1  # exactly the target, not its round-off through exp
    return March(nodes, reached, checks)


def edge_configs(robot: Robot, a: Array, b: Array, resolution: float) -> tuple[Array, NDArray[np.int64]]:
    """Configurations along the geodesics ``a[e] -> b[e]`` (``a, b: (E, config_dim)``),
    ``m_e = intervals(length_e, resolution)`` intervals each, both ends included: all the
    configurations ``(sum(m_e + 1), config_dim)``, edge after edge, and ``m_e + 1`` per edge.

    Planners check edges on this grid, the one :func:`pointplan.evaluation.check_path`
    uses too, so a grazing contact cannot pass one check and fail the other."""
    a = np.asarray(a, np.float64)
    b = np.asarray(b, np.float64)
    v = robot.log(a, b)
    m = intervals(np.linalg.norm(v, axis=-1), resolution)
    idx, frac = _grid(m)
    return robot.integrate(a[idx], v[idx] * frac[:, None]), m + 1


def check_free(robot: Robot, world: object, qs: Array, low: Array, high: Array) -> NDArray[np.bool_]:
    """Per configuration: collision-free and inside the bounds (one collision call)."""
    return ~robot.collides(world, qs) & in_bounds(robot, qs, low, high)  # type: ignore[arg-type]


def _world_and_bounds(obj: object, low: Array | None, high: Array | None) -> tuple[object, Array, Array]:
    from ..scenes.scene import Scene

    if isinstance(obj, Problem):
        obj = obj.scene
    if isinstance(obj, Scene):
        return obj.world, obj.low if low is None else low, obj.high if high is None else high
    if low is None or high is None:
        raise ValueError("pass low and high with a bare collision world")
    return obj, np.asarray(low, np.float64), np.asarray(high, np.float64)
