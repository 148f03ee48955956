"""OMPL's geometric planners behind the :class:`~pointplan.planners.base.Planner` protocol.

``OMPLPlanner(robot, "RRTConnect")`` (or ``make_planner("ompl:RRTConnect", robot)``, or
``--planner ompl:RRTConnect`` on the command line) plans with any planner of
``ompl.geometric`` (RRTConnect, RRT, RRTstar, PRM, BITstar, KPIECE1, ...) from the ``ompl``
wheel (OMPL 2, nanobind bindings: ``from ompl import base as ob, geometric as og``). It is an
optional dependency: ``pip install 'pointplan[ompl]'``.

The search runs in C++; what a configuration costs is answered by pointplan:

- the state space is ``RealVectorStateSpace(2)`` for the disc, ``(3)`` for the sphere,
  ``SE3StateSpace`` for the S-shape, bounded by the scene's workspace bounds, and
  ``RealVectorStateSpace(n)`` for an arm's ``n`` joints, bounded by the joint limits;
- the state validity checker is ``robot.collides`` plus the bounds test (one configuration);
- the motion validator (``motion_check="pointplan"``, the default) checks the robot's own
  geodesic between two states with :func:`~pointplan.planners.edges.edge_free`, the edge
  check of Bi-RRT, so every edge OMPL keeps is one the evaluator accepts.
  ``motion_check="ompl"`` leaves motions to OMPL's ``DiscreteMotionValidator`` (its own
  interpolation, states ``resolution`` apart, each through the Python validity checker):
  closer to how OMPL is usually driven from Python, but its grid is not the evaluator's.

``nodes`` are the vertices of OMPL's planner data (the states the planner added, roots
included); ``collision_checks`` every configuration pointplan checked for it. The S-shape's
OMPL distance (translation plus rotation angle) and interpolation (linear + slerp) differ
from pointplan's screw geodesic; the path's consecutive states are still joined, and
checked, by pointplan's geodesics.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from ..robots.base import Robot
from ..scenes.scene import Problem
from .base import PlanResult, check_free
from .edges import edge_free

OMPL_MISSING = "the OMPL planners need the ompl package: pip install 'pointplan[ompl]'"

_quiet = False


def _ompl() -> tuple[Any, Any, Any]:
    """``(ompl.base, ompl.geometric, ompl.util)``, with OMPL's console output cut to errors."""
    global _quiet
    try:
        from ompl import base as ob
        from ompl import geometric as og
        from ompl import util as ou
    except ImportError:
        raise ImportError(OMPL_MISSING) from None
    if not _quiet:
        ou.setLogLevel(ou.LOG_ERROR)
        _quiet = True
    return ob, og, ou


_MOTION_VALIDATOR: Any = None


def _motion_validator_class(ob: Any) -> Any:
    """An ``ob.MotionValidator`` whose ``checkMotion(s1, s2)`` calls a Python function
    (one subclass for the process: OMPL's bindings register every subclass made)."""
    global _MOTION_VALIDATOR
    if _MOTION_VALIDATOR is None:

        class PythonMotionValidator(ob.MotionValidator):  # type: ignore[misc, name-defined]
            def __init__(self, si: Any, check: Any) -> None:
                super().__init__(si)
                self.check = check

            def checkMotion(self, s1: Any, s2: Any, *rest: Any) -> bool:
                return bool(self.check(s1, s2))

        _MOTION_VALIDATOR = PythonMotionValidator
    return _MOTION_VALIDATOR


def have_ompl() -> bool:
    """Is the optional ``ompl`` package installed?"""
    try:
        _ompl()
    except ImportError:
        return False
    return True


def ompl_planner_names() -> list[str]:
    """The geometric planners of the installed OMPL (class names of ``ompl.geometric``)."""
    ob, og, _ = _ompl()
    return sorted(n for n in dir(og) if isinstance(getattr(og, n), type) and issubclass(getattr(og, n), ob.Planner))


def resolve_planner_name(name: str) -> str:
    """OMPL's spelling of a planner name given in any case (``rrtconnect`` -> ``RRTConnect``)."""
    names = ompl_planner_names()
    by_lower = {n.lower(): n for n in names}
    try:
        return by_lower[name.lower()]
    except KeyError:
        raise ValueError(f"unknown OMPL planner {name!r}; the installed OMPL has: {', '.join(names)}") from None


class OMPLPlanner:
    """An OMPL geometric planner with pointplan's collision checks.

    ``time_limit`` (seconds) bounds each query; ``range`` is the planner's maximum edge
    length where it has one (``setRange``: RRTConnect, RRT, RRTstar, KPIECE, ...), 0.07 like
    our Bi-RRT's step; ``resolution`` the spacing of checked configurations along a motion.
    ``simplify`` runs OMPL's path simplifier (shortcuts, B-spline smoothing; off by default:
    Bi-RRT's shortcutting is its own). ``seed`` seeds OMPL's global random generator, which
    OMPL allows once per process, before its first use.
    """

    def __init__(
        self,
        robot: Robot,
        planner: str = "RRTConnect",
        time_limit: float = 1.0,
        range: float = 0.07,  # noqa: A002 (OMPL's name)
        resolution: float = 0.01,
        simplify: bool = False,
        motion_check: str = "pointplan",
        seed: int | None = None,
    ) -> None:
        _ompl()
        if not (robot.euclidean or robot.body == "sshape"):
            raise ValueError(f"no OMPL state space for robot {robot.name!r}")
        if motion_check not in ("pointplan", "ompl"):
            raise ValueError(f"motion_check must be 'pointplan' or 'ompl', not {motion_check!r}")
        if time_limit <= 0 or range <= 0 or resolution <= 0:
            raise ValueError("time_limit, range and resolution must be positive")
        self.robot = robot
        self.planner_name = resolve_planner_name(planner)
        self.name = f"ompl:{self.planner_name}"
        self.time_limit = float(time_limit)
        self.range = float(range)
        self.resolution = float(resolution)
        self.simplify = bool(simplify)
        self.motion_check = motion_check
        #: kinds of world whose checks this planner has made once (see ``_warm_up``)
        self._warm: set[tuple[object, ...]] = set()
        if seed is not None:
            _ompl()[2].RNG.setSeed(int(seed))

    def __repr__(self) -> str:
        return f"OMPLPlanner({self.planner_name!r}, time_limit={self.time_limit}, range={self.range}, resolution={self.resolution}, simplify={self.simplify}, motion_check={self.motion_check!r})"

    # ------------------------------------------------------------------ states
    def _space(self, ob: Any, low: np.ndarray, high: np.ndarray) -> Any:
        d = self.robot.dim if self.robot.body == "sshape" else self.robot.config_dim
        bounds = ob.RealVectorBounds(d)
        for i in range(d):
            bounds.setLow(i, float(low[i]))
            bounds.setHigh(i, float(high[i]))
        space = ob.SE3StateSpace() if self.robot.body == "sshape" else ob.RealVectorStateSpace(d)
        space.setBounds(bounds)
        return space

    def _reader(self) -> Any:
        """``state -> configuration`` (a float64 array)."""
        if self.robot.body == "sshape":

            def read(s: Any) -> np.ndarray:
                r = s.rotation()
                return np.array([s.getX(), s.getY(), s.getZ(), r.x, r.y, r.z, r.w])

            return read
        d = self.robot.config_dim
        if d == 2:
            return lambda s: np.array([s[0], s[1]])
        return lambda s: np.array([s[i] for i in range(d)])

    def _write(self, s: Any, q: np.ndarray) -> None:
        if self.robot.body == "sshape":
            s.setXYZ(float(q[0]), float(q[1]), float(q[2]))
            quat = np.asarray(q[3:7], np.float64)
            quat = quat / np.linalg.norm(quat)
            r = s.rotation()
            r.x, r.y, r.z, r.w = (float(v) for v in quat)
            return
        for i in range(self.robot.config_dim):
            s[i] = float(q[i])

    # ------------------------------------------------------------------ planning
    def _warm_up(self, problem: Problem, low: np.ndarray, high: np.ndarray) -> None:
        """The planner's first query on a kind of world makes one state check and one short
        edge before the time budget starts (not counted among the query's checks): the
        first checks in a process load or compile the robot's kernels (the Panda's in a
        fresh install: seconds, more than the default 1 s budget; from numba's disk cache
        0.4 s), which is not planning time. The query's ``time_s`` includes them."""
        world = problem.scene.world
        kind = tuple(
            [type(world).__name__] + [bool(getattr(world, k, False)) for k in ("boxes_only", "primitives_only")]
        )
        if kind in self._warm:
            return
        self._warm.add(kind)
        q0 = np.asarray(problem.start, np.float64)
        toward = np.asarray(problem.goal, np.float64) - q0
        norm = float(np.linalg.norm(toward))
        q1 = q0 + toward * min(1.0, 2 * self.resolution / norm) if norm > 0 else q0
        check_free(self.robot, world, q0[None], low, high)
        if self.motion_check == "pointplan":
            edge_free(self.robot, world, q0, q1, self.resolution, low, high)
        else:
            check_free(self.robot, world, q1[None], low, high)

    def plan(self, problem: Problem) -> PlanResult:
        t0 = time.perf_counter()
        ob, og, _ = _ompl()
        robot, scene = self.robot, problem.scene
        world, low, high = scene.world, np.asarray(scene.low, np.float64), np.asarray(scene.high, np.float64)
        cdim = robot.config_dim
        read = self._reader()
        checks = [0]

        def valid(s: Any) -> bool:
            checks[0] += 1
            return bool(check_free(robot, world, read(s)[None], low, high)[0])

        space = self._space(ob, low, high)
        si = ob.SpaceInformation(space)
        si.setStateValidityChecker(valid)
        if self.motion_check == "pointplan":
            resolution = self.resolution

            def motion(s1: Any, s2: Any) -> bool:
                ok, n = edge_free(robot, world, read(s1), read(s2), resolution, low, high)
                checks[0] += n
                return ok

            si.setMotionValidator(_motion_validator_class(ob)(si, motion))
        else:
            si.setStateValidityCheckingResolution(self.resolution / si.getMaximumExtent())
        si.setup()
        ss = og.SimpleSetup(si)
        start, goal = si.allocState(), si.allocState()
        self._write(start, problem.start)
        self._write(goal, problem.goal)
        ss.setStartAndGoalStates(start, goal)
        planner = getattr(og, self.planner_name)(si)
        if hasattr(planner, "setRange"):
            planner.setRange(self.range)
        ss.setPlanner(planner)
        self._warm_up(problem, low, high)
        # a termination condition that checks the clock itself: ``solve(seconds)`` with 1 s
        # or more starts a watcher thread per query, which costs a loaded machine
        # milliseconds of wall time
        status = ss.solve(ob.timedPlannerTerminationCondition(self.time_limit))
        exact = bool(status) and ss.haveExactSolutionPath()
        path = None
        if exact:
            if self.simplify:
                ss.simplifySolution(self.time_limit)
            states = ss.getSolutionPath().getStates()
            path = np.stack([read(s) for s in states])
            path[0], path[-1] = problem.start, problem.goal  # exactly, not their float copies
        data = ob.PlannerData(si)
        ss.getPlannerData(data)
        nodes = int(data.numVertices())
        info = {"status": status.asString()}
        del ss, planner, data, si, space  # OMPL's objects go before the closures they hold
        dt = time.perf_counter() - t0
        if path is None:
            return PlanResult.failure(cdim, nodes, checks[0], dt, info=info)
        return PlanResult(path=path, success=True, nodes=nodes, collision_checks=checks[0], time_s=dt, info=info)


def make_ompl_planner(robot: Robot, planner: str = "RRTConnect", **kw: Any) -> OMPLPlanner:
    """``make_planner("ompl:NAME", robot, **kw)``."""
    return OMPLPlanner(robot, planner, **kw)


__all__ = [
    "OMPL_MISSING",
    "OMPLPlanner",
    "have_ompl",
    "make_ompl_planner",
    "ompl_planner_names",
    "resolve_planner_name",
]
