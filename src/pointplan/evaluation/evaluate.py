"""Run a planner on a set of problems and score it.

Success is decided here by :func:`check_path`, an independent re-check of the returned
path (its own method and code: exact distances and conservative advancement), not by what
the planner says; the two are both recorded and disagreements counted.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..geometry.shapes import Shape
from ..parallel import Interrupted, WorkerPool, backend, wants_workers
from ..planners.base import Planner, path_length
from ..robots.base import Robot
from ..robots.motion import intervals
from ..scenes.scene import Problem
from .arm_clearance import ArmClearance
from .clearance import Clearance, advance

Array = NDArray[np.float64]

_BOUNDS_EPS = 1e-9


@dataclass(frozen=True)
class PathCheck:
    """Verdict of :func:`check_path`: true when the path is a valid solution; otherwise
    ``reason`` says why (malformed input, wrong start, goal not reached, out of bounds,
    touching an obstacle)."""

    ok: bool
    reason: str = ""
    #: the smallest clearance met by the certificate (``inf`` when not computed)
    clearance: float = math.inf

    def __bool__(self) -> bool:
        return self.ok


def _malformed(robot: Robot, problem: Problem, path: Array, tolerance: float) -> str:
    """Why ``path`` cannot be a solution before any collision check, or ``""``."""
    if path.ndim != 2 or path.shape[-1] != robot.config_dim:
        return f"a path must be a (K, {robot.config_dim}) array of {robot.name} configurations, got shape {path.shape}"
    if path.shape[0] < 1:
        return "the path is empty"
    if not np.all(np.isfinite(path)):
        rows = np.flatnonzero(~np.all(np.isfinite(path), axis=1))
        return f"the path has non-finite values (NaN or inf) at configurations {rows[:5].tolist()}"
    gap = float(robot.distance(path[0], problem.start))
    if gap >= 1e-6:
        return f"the path does not start at the problem's start (distance {gap:.3g})"
    miss = float(robot.distance(path[-1], problem.goal))
    if not miss < tolerance:
        return f"the path ends {miss:.3g} from the goal (tolerance {tolerance})"
    return ""


def check_path(
    robot: Robot, problem: Problem, path: Array, resolution: float = 0.01, tolerance: float = 0.07
) -> PathCheck:
    """Is ``path`` a valid solution of ``problem``? Returns a :class:`PathCheck` (true or
    false, with the reason).

    It must be a finite ``(K, config_dim)`` array with ``K >= 1`` that starts at the start
    (geodesic distance below 1e-6) and ends within ``tolerance`` of the goal (strictly, as
    in the environment); the positions along every geodesic segment, at most
    ``resolution`` apart (both ends included), must lie inside the scene bounds; and no
    configuration of any segment, its ends included, may come within
    :data:`~pointplan.evaluation.clearance.TOUCH` of an obstacle. That last part is
    certified by conservative advancement on exact distances
    (:mod:`pointplan.evaluation.clearance`), independently of the planners' own check.

    In a scene whose obstacles move, the path is executed in time: it is cut into moves one
    action can make (:func:`timed_path`), move ``j`` takes the robot from time ``j`` to
    ``j + 1`` and is checked, its start pose included, against the obstacles at time
    ``j + 1``, as in the environment.
    """
    path = np.asarray(path, np.float64)
    reason = _malformed(robot, problem, path, tolerance)
    if reason:
        return PathCheck(False, reason)
    scene = problem.scene
    pos = robot.positions(densify(robot, path, resolution))
    if np.any(pos < scene.low - _BOUNDS_EPS) or np.any(pos > scene.high + _BOUNDS_EPS):
        return PathCheck(False, "the path leaves the workspace bounds")
    if scene.dynamic:
        steps = timed_path(robot, path)
        pieces = [
            (clearance_for(robot, scene.obstacles_at(j + 1)), steps[j], steps[j + 1]) for j in range(len(steps) - 1)
        ]
        if len(steps) == 1:
            pieces = [(clearance_for(robot, scene.obstacles_at(0)), steps[0], steps[0])]
    else:
        world = clearance_for(robot, scene.obstacles)
        pieces = [(world, a, b) for a, b in zip(path[:-1], path[1:])] or [(world, path[0], path[0])]
    low = math.inf
    for j, (clear, a, b) in enumerate(pieces):
        if (j == 0 or scene.dynamic) and clear.buried(a):
            return PathCheck(False, f"segment {j} starts inside a mesh obstacle", 0.0)
        free, d = advance(clear, robot, a, b)
        low = min(low, d)
        if not free:
            what = "move" if scene.dynamic else "segment"
            return PathCheck(False, f"{what} {j} touches an obstacle (clearance {d:.3g})", low)
    return PathCheck(True, "", low)


def clearance_for(robot: Robot, obstacles: Sequence[Shape]) -> Clearance:
    """The evaluator's distance for ``robot``: :class:`Clearance` for rigid bodies, the
    pinocchio + coal one (:class:`~pointplan.evaluation.arm_clearance.ArmClearance`) for an
    arm loaded from a URDF."""
    if getattr(robot, "urdf", None):
        return ArmClearance(robot, obstacles)  # type: ignore[return-value]
    return Clearance(robot, obstacles)


def timed_path(robot: Robot, path: Array) -> Array:
    """``path`` with every segment cut into equal pieces that one action can make (each
    twist coordinate within the robot's ``action_scale``): one piece per time step."""
    path = np.asarray(path, np.float64)
    if len(path) < 2:
        return path.copy()
    out = [path[:1]]
    for q0, q1 in zip(path[:-1], path[1:]):
        v = robot.log(q0, q1)
        k = max(1, int(np.ceil(float(np.max(np.abs(v) / robot.action_scale)) - 1e-9)))
        out.append(robot.integrate(np.broadcast_to(q0, (k, len(q0))), v[None] * (np.arange(1, k + 1) / k)[:, None]))
    return np.concatenate(out)


def densify(robot: Robot, path: Array, resolution: float) -> Array:
    """Configurations along every segment of ``path``, both ends of each segment included:
    ``(N, config_dim)``. A segment of geodesic length ``l`` gets
    ``max(1, ceil(l / resolution - 1e-9)) + 1`` evenly spaced configurations (the planners' grid; the slack keeps an edge
    of exactly ``step`` from getting an extra interval through round-off). A
    one-configuration path is returned as is."""
    path = np.asarray(path, np.float64)
    if len(path) < 2:
        return path.copy()
    q0, q1 = path[:-1], path[1:]
    v = robot.log(q0, q1)
    m = intervals(np.linalg.norm(v, axis=-1), resolution)  # intervals per segment
    counts = m + 1
    offsets = np.concatenate([[0], np.cumsum(counts)])
    idx = np.repeat(np.arange(len(m)), counts)
    s = (np.arange(offsets[-1]) - offsets[idx]) / m[idx]
    return robot.integrate(q0[idx], v[idx] * s[:, None])


@dataclass
class EpisodeRecord:
    """One problem of an evaluation."""

    tag: str
    #: decided by :func:`check_path`
    success: bool
    #: what the planner reported
    claimed_success: bool
    nodes: int
    collision_checks: int
    #: geodesic length of the path plus the distance from its end to the goal (NaN when
    #: the path failed the check)
    path_length: float
    #: wall time of ``planner.plan``, seconds (measured by the evaluator)
    time_s: float
    path: Array = field(repr=False)
    #: why the problem cannot be solved as posed ("start in collision", ...), or ""
    invalid: str = ""
    #: the problem's start and goal configurations
    start: Array | None = field(default=None, repr=False)
    goal: Array | None = field(default=None, repr=False)

    def to_json(self) -> dict[str, Any]:
        """The record as JSON values: tag, start, goal, verdicts and counts (no path or
        time; a NaN path length is None)."""
        return {
            "tag": self.tag,
            "start": None if self.start is None else np.asarray(self.start, np.float64).tolist(),
            "goal": None if self.goal is None else np.asarray(self.goal, np.float64).tolist(),
            "success": bool(self.success),
            "claimed_success": bool(self.claimed_success),
            "invalid": self.invalid,
            "nodes": int(self.nodes),
            "collision_checks": int(self.collision_checks),
            "path_length": None if math.isnan(self.path_length) else float(self.path_length),
        }


def _mean(xs: Sequence[float]) -> float:
    return float(np.mean(xs)) if len(xs) else math.nan


def _median(xs: Sequence[float]) -> float:
    return float(np.median(xs)) if len(xs) else math.nan


@dataclass
class EvalReport:
    """Per-problem records of one planner on a problem set."""

    planner: str
    records: list[EpisodeRecord] = field(default_factory=list)
    #: stopped by Ctrl-C: ``(finished, total)`` problems (the records are the finished ones)
    interrupted: tuple[int, int] | None = None

    def metrics(self) -> dict[str, Any]:
        """Success rate; nodes, collision checks and time over *all* problems (and nodes over
        the solved ones); path length over the successful ones; and how often the planner's claim disagreed with the check."""
        r = self.records
        ok = [x for x in r if x.success]
        nodes = [float(x.nodes) for x in r]
        checks = [float(x.collision_checks) for x in r]
        times = [x.time_s for x in r]
        lengths = [x.path_length for x in ok]
        return {
            "success_rate": len(ok) / len(r) if r else math.nan,
            "episodes": len(r),
            "nodes_mean": _mean(nodes),
            "nodes_median": _median(nodes),
            "nodes_mean_solved": _mean([float(x.nodes) for x in ok]),
            "collision_checks_mean": _mean(checks),
            "collision_checks_median": _median(checks),
            "path_length_mean": _mean(lengths),
            "path_length_median": _median(lengths),
            "time_mean_s": _mean(times),
            "time_median_s": _median(times),
            "planner_claims_disagree": sum(1 for x in r if x.success != x.claimed_success),
            "invalid_problems": sum(1 for x in r if x.invalid),
        }


def evaluate(
    planner: Planner,
    problems: Sequence[Problem],
    robot: Robot,
    progress: bool = True,
    resolution: float = 0.01,
    tolerance: float = 0.07,
    workers: int | None = None,
    address: str | None = None,
    pool: WorkerPool | None = None,
) -> EvalReport:
    """Plan every problem with ``planner`` and re-check each returned path.

    With a worker ``pool`` (e.g. :class:`pointplan.distributed.RayPool`), or ``workers > 1``
    or a cluster ``address`` (a pool of the default back end, Ray), the problems are
    planned by the workers: the same records in the same order, wall times aside."""
    own = pool is None and wants_workers(workers, address)
    if own:
        pool = backend().pool(workers, address)
    if pool is not None:
        try:
            return _evaluate_in(pool, planner, problems, robot, progress, resolution, tolerance)
        finally:
            if own:
                pool.shutdown()
    report = EvalReport(planner=str(getattr(planner, "name", type(planner).__name__)))
    it: Any = problems
    if progress:
        from ..progress import progress_bar

        it = progress_bar(problems, desc=report.planner, unit="problem")
    n_ok = 0
    try:
        for problem in it:
            report.records.append(plan_and_check(planner, problem, robot, resolution, tolerance))
            n_ok += report.records[-1].success
            if progress:
                it.set_postfix(success=f"{n_ok / len(report.records):.1%}", refresh=False)
    except KeyboardInterrupt:  # keep what finished, as the pool path does
        if progress:
            it.close()
        report.interrupted = (len(report.records), len(problems))
        print(
            f"\ninterrupted: kept the {len(report.records)} of {len(problems)} problems that finished", file=sys.stderr
        )
    return report


def set_call_number(planner: Any, number: int) -> None:
    """Make ``planner``'s next ``plan`` call the ``number``-th one (counted from 0), for a
    planner that numbers its calls in ``calls`` (Bi-RRT seeds each call with
    ``(seed, call number)``); others are left alone."""
    if isinstance(getattr(planner, "calls", None), int):
        planner.calls = int(number)


def _plan_and_check_at(
    pos: int,
    planner: Planner,
    problems: Sequence[Problem],
    robot: Robot,
    first_call: int,
    resolution: float,
    tolerance: float,
) -> EpisodeRecord:
    """Problem ``pos`` of an evaluation, in a worker: what the serial loop does for it."""
    set_call_number(planner, first_call + pos)
    return plan_and_check(planner, problems[pos], robot, resolution, tolerance)


def _evaluate_in(
    pool: WorkerPool,
    planner: Planner,
    problems: Sequence[Problem],
    robot: Robot,
    progress: bool,
    resolution: float,
    tolerance: float,
) -> EvalReport:
    """:func:`evaluate` on ``pool``'s workers. Each worker plans with its own copy of
    ``planner``, set to the call number a serial run would have; afterwards ``planner``
    here counts the calls as if it had planned them all. On Ctrl-C the report holds the
    problems that finished (in problem order) and ``interrupted`` says how many."""
    report = EvalReport(planner=str(getattr(planner, "name", type(planner).__name__)))
    n = len(problems)
    first_call = int(getattr(planner, "calls", 0) or 0)
    bar = None
    solved = [0, 0]
    if progress:
        from ..progress import progress_bar

        bar = progress_bar(total=n, desc=report.planner, unit="problem")

    def tick(_: int, rec: EpisodeRecord) -> None:
        solved[0] += bool(rec.success)
        solved[1] += 1
        if bar is not None:
            bar.set_postfix(success=f"{solved[0] / solved[1]:.1%}", refresh=False)  # first: the update may draw
            bar.update()

    try:
        records = pool.map(
            _plan_and_check_at,
            range(n),
            shared=(planner, problems, robot, first_call, resolution, tolerance),
            on_result=tick,
        )
    except Interrupted as stop:
        records = [stop.results[i] for i in sorted(stop.results)]
        report.interrupted = (len(records), n)
        print(f"\ninterrupted: kept the {len(records)} of {n} problems that finished", file=sys.stderr)
    finally:
        if bar is not None:
            bar.close()
    report.records.extend(records)
    set_call_number(planner, first_call + n)
    return report


def endpoint_fault(robot: Robot, problem: Problem) -> str:
    """ "start in collision", "goal in collision", "start and goal in collision" (against
    the obstacles at time 0), or "" when both are free."""
    hit = np.asarray(robot.collides(problem.scene.world, np.stack([problem.start, problem.goal])), bool)
    which = [name for name, h in zip(("start", "goal"), hit) if h]
    return f"{' and '.join(which)} in collision" if which else ""


def plan_and_check(
    planner: Planner, problem: Problem, robot: Robot, resolution: float = 0.01, tolerance: float = 0.07
) -> EpisodeRecord:
    """One problem planned and its path re-checked."""
    t0 = time.perf_counter()
    result = planner.plan(problem)
    elapsed = time.perf_counter() - t0
    path = np.asarray(result.path, np.float64)
    ok = len(path) > 0 and bool(check_path(robot, problem, path, resolution, tolerance))
    return EpisodeRecord(
        invalid=endpoint_fault(robot, problem),
        tag=problem.tag,
        success=bool(ok),
        claimed_success=bool(result.success),
        nodes=int(result.nodes),
        collision_checks=int(result.collision_checks),
        # counted to the goal: a path that stops within the tolerance is charged the rest
        path_length=path_length(robot, path) + float(robot.distance(path[-1], problem.goal)) if ok else math.nan,
        time_s=elapsed,
        path=path,
        start=np.asarray(problem.start, np.float64).copy(),
        goal=np.asarray(problem.goal, np.float64).copy(),
    )


_ROWS = [
    ("success_rate", "success"),
    ("episodes", "episodes"),
    ("nodes_mean", "nodes (mean)"),
    ("nodes_median", "nodes (median)"),
    ("nodes_mean_solved", "nodes (mean, solved)"),
    ("collision_checks_mean", "collision checks (mean)"),
    ("collision_checks_median", "collision checks (median)"),
    ("path_length_mean", "path length (mean)"),
    ("path_length_median", "path length (median)"),
    ("time_mean_s", "time s (mean)"),
    ("time_median_s", "time s (median)"),
    ("planner_claims_disagree", "claims disagree"),
    ("invalid_problems", "start/goal in collision"),
]


def _fmt(key: str, v: Any) -> str:
    if v is None:
        return "-"
    if isinstance(v, (bool, np.bool_)):
        return str(bool(v))
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        if math.isnan(v):
            return "-"
        if key == "success_rate":
            return f"{100 * v:.1f}%"
        if key.startswith("time"):
            return f"{v:.4f}"
        if key.startswith("path_length"):
            return f"{v:.3f}"
        return f"{v:.1f}"
    return str(v)


def format_table(metrics_by_name: dict[str, dict[str, Any]]) -> str:
    """An aligned text table: one row per metric, one column per planner. Metrics not in
    the standard set are appended as extra rows."""
    names = list(metrics_by_name)
    keys = [(k, label) for k, label in _ROWS if any(k in m for m in metrics_by_name.values())]
    known = {k for k, _ in _ROWS}
    for m in metrics_by_name.values():
        for k in m:
            if k not in known and k not in [x for x, _ in keys]:
                keys.append((k, k))
    header = ["metric"] + names
    rows = [[label] + [_fmt(k, metrics_by_name[n].get(k)) for n in names] for k, label in keys]
    widths = [max(len(r[i]) for r in [header] + rows) for i in range(len(header))]

    def line(cells: list[str]) -> str:
        return "  ".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(cells, widths)))

    out = [line(header), "  ".join("-" * w for w in widths)]
    out += [line(r) for r in rows]
    return "\n".join(out)
