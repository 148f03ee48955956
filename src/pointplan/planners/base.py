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
from ..robots.motion import GRID_SLACK, intervals
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

    def plan(self, problem: Problem) -> PlanResult:
        """A path from ``problem.start`` to ``problem.goal``, with the query's statistics."""
        ...


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
    each certified by the robot's motion validator in ``intervals(length, resolution)``
    sub-steps (:func:`pointplan.robots.motion.check_motions`).

    Stops at the first edge that is not certified free or leaves the bounds, or after
    ``max_steps`` edges. The edges are checked in validator calls of 1, 2, 4, ... edges
    until one holds a blocked edge; ``checks`` counts what an edge-by-edge check would
    evaluate (every configuration of every edge up to and including the first blocked one),
    so it does not depend on the batching. ``twist``
    may pass ``robot.log(q0, q1)`` if it is already known.

    ``problem_or_world`` is a :class:`Problem` or a scene (bounds taken from it) or a
    ``CollisionWorld`` together with ``low`` and ``high``.
    """
    world, low, high = _world_and_bounds(problem_or_world, low, high)
    q0 = np.asarray(q0, np.float64)
    q1 = np.asarray(q1, np.float64)
    v = robot.log(q0, q1) if twist is None else np.asarray(twist, np.float64)
    fast = robot.march_compiled(world, q0, q1, v, step, resolution, max_steps, low, high)  # type: ignore[arg-type]
    if fast is not None:
        return March(*fast)
    d = float(np.linalg.norm(v))
    cdim = q0.shape[-1]
    if d <= 1e-12:
        return March(np.zeros((0, cdim)), True, 0)
    total = max(1, int(np.ceil(d / step - GRID_SLACK)))
    n = total if max_steps is None else min(total, int(max_steps))
    if n <= 0:
        return March(np.zeros((0, cdim)), False, 0)
    # Edge ends at fractions ``ends`` of the geodesic. It is a one-parameter subgroup, so the
    # geodesic between two edge ends is the matching piece of the whole one.
    ends = np.minimum(np.arange(n + 1) * (step / d), 1.0)
    reached = n == total
    if reached:
        ends[-1] = 1.0
    frac = ends[1:] - ends[:-1]
    m = intervals(frac * d, resolution)
    starts = robot.integrate(q0[None], v[None] * ends[:, None])  # (n + 1, cdim): edge ends
    first_only = np.arange(n) == 0  # later edges start where a certified one ends
    # the edges in chunks of 1, 2, 4, ... up to the first chunk with a blocked edge: a
    # blocked connect costs at most about twice its free prefix, not all of its edges
    n_free, checks, a, size = n, 0, 0, 1
    while a < n:
        b = min(n, a + size)
        chk = robot.check_motions(
            world,  # type: ignore[arg-type]
            starts[a:b],
            v[None] * frac[a:b, None],
            m[a:b],
            low,
            high,
            fallback=first_only[a:b],  # type: ignore[arg-type]
        )
        bad = chk.free < m[a:b]
        if bad.any():
            k = int(np.argmax(bad))
            n_free, checks = a + k, checks + int(np.sum(chk.checks[: k + 1]))
            break
        checks += int(np.sum(chk.checks))
        a, size = b, 2 * size
    reached = reached and n_free == n
    nodes = starts[1 : n_free + 1]
    if reached:
        nodes[-1] = q1  # exactly the target, not its round-off through exp
    return March(nodes, reached, checks)


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
