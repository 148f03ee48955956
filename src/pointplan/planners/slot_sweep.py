"""The sweep expert for Slot: the S-shape's centreline swept through the opening.

On any path through the wall every point of the S-shape's centreline crosses the wall's
mid-plane inside the slot. The sweep follows that literally: for arc lengths ``s`` from the
tip of one end bar to the tip of the other, it finds a free pose with the centreline point
at ``s`` in the opening (x = 0), each warm-started from the previous pose and kept close to
it, maximising the clearance to the wall (coal's signed distance, capped) with a soft
preference for the part of the centreline before ``s`` to be past the wall and the part
after it before the wall. Consecutive poses are joined by certified straight edges
(:func:`sweep`). :func:`plan` joins a problem's start and goal to a sweep with Bi-RRT;
:func:`simplify` cuts a path to fewer, longer edges.

It reads the slot's width, centre and long axis from the scene (a privileged expert, for
demonstrations and for the threading template of
:mod:`pointplan.planners.slot_threading`), and its paths are certified by
:func:`~pointplan.planners.edges.edge_free` and Bi-RRT; the evaluator's ``check_path`` is
the independent check.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import coal
import numpy as np
from scipy.optimize import minimize
from scipy.spatial.transform import Rotation

from ..geometry.shapes import Box
from ..robots.base import Robot
from ..robots.sshape import S_CORNERS, SShape
from ..scenes.scene import Problem
from .base import path_length
from .birrt import BiRRT
from .edges import edge_free

#: ``log(message)``: where the sweep says why it gave up (``None``: silent)
Log = Callable[[str], None] | None


class WallClearance:
    """Smallest signed distance (coal) between the S-shape's bars at a pose and the scene's
    boxes (the Slot wall)."""

    def __init__(self, robot: SShape, problem: Problem) -> None:
        parts = robot.parts
        boxes = [o for o in problem.scene.obstacles if isinstance(o, Box)]
        if not boxes or len(boxes) != len(problem.scene.obstacles):
            raise ValueError("the wall's clearance needs a scene of boxes (a Slot wall)")
        self.bars = [(coal.Box(*(2 * h)), c) for c, h in zip(parts.box_centers, parts.box_halfs, strict=True)]
        self.wall = [
            (coal.Box(*o.size), coal.Transform3s(np.asarray(o.rotation, np.float64), np.asarray(o.center, np.float64)))
            for o in boxes
        ]
        self.req = coal.DistanceRequest()
        self.req.enable_signed_distance = True
        # the wall: boxes spanning the plane x = plane, half_wall thick; a bar's reach: its half diagonal
        self.plane = float(boxes[0].center[0])
        self.half_wall = max(float(o.size[0]) for o in boxes) / 2
        self.reach = [float(np.linalg.norm(h)) for h in parts.box_halfs]

    def __call__(self, rot: np.ndarray, pos: np.ndarray, above: float = np.inf) -> float:
        """The clearance; with ``above``, a bar whose centre is farther from the wall's
        plane than its reach plus the wall's half thickness plus ``above`` is skipped (its
        distance is more than ``above``), and the answer is exact only up to ``above``."""
        best = np.inf
        for (shape, c), reach in zip(self.bars, self.reach, strict=True):  # the bars are axis-aligned in the body frame
            centre = rot @ c + pos
            if abs(centre[0] - self.plane) > reach + self.half_wall + above:
                best = min(best, abs(centre[0] - self.plane) - reach - self.half_wall)
                continue
            tf = coal.Transform3s(rot, centre)
            for wshape, wtf in self.wall:
                best = min(best, coal.distance(shape, tf, wshape, wtf, self.req, coal.DistanceResult()))
        return float(best)


def centreline(order: str) -> tuple[np.ndarray, np.ndarray]:
    """The centreline's corners from the leading tip (``"A"``: bar A first, ``"E"``: bar E
    first) and their arc lengths."""
    pts = S_CORNERS if order == "A" else S_CORNERS[::-1]
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
    return pts, arc


def point_at(pts: np.ndarray, arc: np.ndarray, s: float) -> np.ndarray:
    """The point at arc length ``s`` of the polyline ``pts`` (arc lengths ``arc``)."""
    k = int(np.clip(np.searchsorted(arc, s, side="right") - 1, 0, len(arc) - 2))
    f = (s - arc[k]) / (arc[k + 1] - arc[k])
    return pts[k] + f * (pts[k + 1] - pts[k])


class Sweep:
    """The sweep of one problem and one leading end (``order``). A pose is a rotation and
    the opening coordinates ``u`` (along the slot's long and thin axes) of the centreline
    point in the opening."""

    def __init__(
        self,
        robot: SShape,
        problem: Problem,
        order: str,
        rng: np.random.Generator,
        min_clearance: float = 0.0015,
        guide: float = 0.0,
    ) -> None:
        slot = problem.scene.__dict__["slot"]
        self.problem, self.rng, self.min_clearance = problem, rng, float(min_clearance)
        #: with ``guide > 0``, the sweep toward a bend is pulled to a free pose of the bend in
        #: the opening found beforehand (weight ``guide`` on the squared angle, rising along
        #: the bar that leads there)
        self.guide, self.w_target = float(guide), 0.0
        self.target: np.ndarray | None = None
        width, self.mid, long_axis = (
            float(slot["width"]),
            np.asarray(slot["center"], np.float64),
            int(slot["long_axis"]),
        )
        self.e_long, self.e_thin = np.eye(3)[long_axis], np.eye(3)[3 - long_axis]
        self.half = np.array([0.2, width / 2])
        self.cap = max((width - 0.036) / 2 * 0.6, 0.002)  # the clearance asked for, below what the slot allows
        self.clear = WallClearance(robot, problem)
        self.pts, self.arc = centreline(order)
        self.samples = np.linspace(0, self.arc[-1], 60)
        self.sample_pts = np.array([point_at(self.pts, self.arc, a) for a in self.samples])

    def pose(self, v: np.ndarray, rot0: np.ndarray, s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Rotation, position and opening coordinates of the search variables ``v`` (a
        rotation vector after ``rot0``, then the opening coordinates before a tanh)."""
        rot = rot0 @ Rotation.from_rotvec(v[:3]).as_matrix()
        u = self.half * np.tanh(v[3:5])
        c = point_at(self.pts, self.arc, s)
        pos = self.mid + u[0] * self.e_long + u[1] * self.e_thin - rot @ c
        return rot, pos, u

    def cost(self, v: np.ndarray, rot0: np.ndarray, u0: np.ndarray, s: float, w_cont: float) -> float:
        """What the search minimises: minus the capped clearance, the centreline on the
        wrong side, the step from ``(rot0, u0)`` (weight ``w_cont``) and the guide's pull."""
        rot, pos, u = self.pose(v, rot0, s)
        cl = self.clear(rot, pos, self.cap)
        x = (self.sample_pts @ rot.T + pos)[:, 0]
        side = np.sum(np.maximum(0.0, -x[self.samples < s - 0.02])) + np.sum(
            np.maximum(0.0, x[self.samples > s + 0.02])
        )
        pull = 0.0
        if self.target is not None and self.w_target > 0:
            pull = self.w_target * float(np.sum(Rotation.from_matrix(self.target.T @ rot).as_rotvec() ** 2))
        return float(
            -20.0 * min(cl, self.cap) + 2.0 * side + w_cont * (np.sum(v[:3] ** 2) + 10.0 * np.sum((u - u0) ** 2)) + pull
        )

    def bend_poses(self, k: int, starts: int = 16) -> list[np.ndarray]:
        """Rotations of free poses with the centreline's corner ``k`` in the opening (the
        part before it past the wall), from random starts."""
        found = []
        target, self.target = self.target, None
        for _ in range(starts):
            rot0 = Rotation.random(random_state=self.rng).as_matrix()
            v0 = np.concatenate([np.zeros(3), self.rng.normal(0, 0.3, 2)])
            r = minimize(
                self.cost,
                v0,
                args=(rot0, np.zeros(2), float(self.arc[k]), 0.0),
                method="Nelder-Mead",
                options={"maxiter": 800},
            )
            rot, pos, _ = self.pose(r.x, rot0, float(self.arc[k]))
            if self.clear(rot, pos) >= self.min_clearance:
                found.append(rot)
        self.target = target
        return found

    def aim(self, rot: np.ndarray, s: float, cache: dict[int, list[np.ndarray]]) -> None:
        """Set the target for arc length ``s``: the free pose of the next bend nearest to
        ``rot`` (chosen once per bar), its weight rising from 0 at the bar's start."""
        if self.guide <= 0:
            return
        k = int(np.searchsorted(self.arc, s, side="left"))  # the corner at or after s
        if k <= 0 or k >= len(self.arc) - 1:
            self.target, self.w_target = None, 0.0
            return
        if k not in cache:
            poses = self.bend_poses(k)
            cache[k] = (
                [min(poses, key=lambda r: float(np.linalg.norm(Rotation.from_matrix(r.T @ rot).as_rotvec())))]
                if poses
                else []
            )
        self.target = cache[k][0] if cache[k] else None
        self.w_target = self.guide * (s - self.arc[k - 1]) / (self.arc[k] - self.arc[k - 1])

    def first(self) -> tuple[np.ndarray, np.ndarray]:
        """The first pose: the leading tip in the opening, the body behind the wall."""
        best = None
        for _ in range(40):
            rot0 = Rotation.random(random_state=self.rng).as_matrix()
            v0 = np.concatenate([np.zeros(3), self.rng.normal(0, 0.3, 2)])
            r = minimize(
                self.cost,
                v0,
                args=(rot0, np.zeros(2), 0.0, 0.0),
                method="Nelder-Mead",
                options={"maxiter": 800, "xatol": 1e-6, "fatol": 1e-9},
            )
            if best is None or r.fun < best[0]:
                best = (r.fun, r.x, rot0)
        assert best is not None
        rot, _, u = self.pose(best[1], best[2], 0.0)
        return rot, u

    def next(self, rot: np.ndarray, u: np.ndarray, s: float) -> tuple[bool, float, np.ndarray, np.ndarray]:
        """A free pose with the centreline point ``s`` in the opening, near ``(rot, u)``:
        ``(found, clearance, rotation, opening coordinates)``."""
        vu = np.arctanh(np.clip(u / self.half, -0.999, 0.999))
        cands = []
        for k in range(8):
            v0 = np.concatenate([np.zeros(3) if k == 0 else self.rng.normal(0, 0.15, 3), vu])
            r = minimize(
                self.cost,
                v0,
                args=(rot, u, s, 0.02),
                method="Nelder-Mead",
                options={"maxiter": 600, "xatol": 1e-6, "fatol": 1e-9},
            )
            nrot, npos, nu = self.pose(r.x, rot, s)
            cl = self.clear(nrot, npos)
            cands.append((cl >= self.min_clearance, -float(np.linalg.norm(r.x[:3])), cl, nrot, nu))
            if k == 0 and cl >= self.min_clearance:
                break
        ok, _, cl, nrot, nu = max(cands, key=lambda c: (c[0], c[1]))
        return ok, max(c[2] for c in cands), nrot, nu

    def config(self, rot: np.ndarray, u: np.ndarray, s: float) -> np.ndarray:
        """The robot's configuration (position, quaternion) of a pose."""
        c = point_at(self.pts, self.arc, s)
        pos = self.mid + u[0] * self.e_long + u[1] * self.e_thin - rot @ c
        return np.concatenate([pos, Rotation.from_matrix(rot).as_quat()])


def sweep(
    robot: SShape,
    problem: Problem,
    order: str,
    ds: float,
    rng: np.random.Generator,
    log: Log = None,
    min_clearance: float = 0.0015,
    guide: float = 0.0,
) -> list[np.ndarray] | None:
    """The sweep's poses (led by bar ``order``, ``ds`` of arc length apart), joined by
    certified straight edges (an edge that collides is split at its middle arc length, up
    to 4 times), or ``None`` where no free pose was found for some ``s``."""
    sw = Sweep(robot, problem, order, rng, min_clearance, guide)
    rot, u = sw.first()
    states = [(0.0, rot, u)]
    s = 0.0
    targets: dict[int, list[np.ndarray]] = {}
    while s < sw.arc[-1]:
        s = min(s + ds, sw.arc[-1])
        sw.aim(rot, s, targets)
        ok, cl, rot, u = sw.next(rot, u, s)
        if not ok:
            if log is not None:
                log(f"  {order}: stuck at s = {s:.3f} (clearance {cl:+.4f})")
            return None
        states.append((s, rot, u))

    def join(a: tuple, b: tuple, depth: int) -> list[np.ndarray] | None:
        qa, qb = sw.config(a[1], a[2], a[0]), sw.config(b[1], b[2], b[0])
        if edge_free(robot, problem, qa, qb)[0]:
            return [qb]
        if depth == 0:
            return None
        ok, _, rot, u = sw.next(a[1], a[2], (a[0] + b[0]) / 2)
        if not ok:
            return None
        m = ((a[0] + b[0]) / 2, rot, u)
        left = join(a, m, depth - 1)
        right = join(m, b, depth - 1) if left is not None else None
        return None if left is None or right is None else left + right

    poses = [sw.config(states[0][1], states[0][2], 0.0)]
    for a, b in zip(states[:-1], states[1:], strict=True):
        more = join(a, b, 4)
        if more is None:
            if log is not None:
                log(f"  {order}: the edge at s = {a[0]:.3f} collides and could not be split")
            return None
        poses += more
    return poses


def simplify(robot: Robot, problem: Problem, path: np.ndarray, seed: int, shortcuts: int = 200) -> np.ndarray:
    """Fewer, longer edges: from each vertex, the farthest later vertex the certified
    straight edge reaches (doubling, then bisection: an edge that collides somewhere
    is taken to collide farther on too, which only keeps more vertices), then Bi-RRT's
    random shortcuts."""
    out, i, n = [path[0]], 0, len(path)
    while i < n - 1:
        step, good = 1, i + 1
        while i + 2 * step < n and edge_free(robot, problem, path[i], path[i + 2 * step])[0]:
            step *= 2
            good = i + step
        lo, hi = good, min(i + 2 * step, n - 1)
        while hi - lo > 1:
            m = (lo + hi) // 2
            if edge_free(robot, problem, path[i], path[m])[0]:
                lo = m
            else:
                hi = m
        if hi > lo and edge_free(robot, problem, path[i], path[hi])[0]:
            lo = hi
        out.append(path[lo])
        i = lo
    short, _ = BiRRT(robot, seed=seed, shortcut_iters=shortcuts).shortcut(
        np.array(out), problem, np.random.default_rng(seed)
    )
    return short


def plan(
    robot: SShape,
    problem: Problem,
    ds: float = 0.004,
    seed: int = 0,
    max_nodes: int = 5000,
    log: Log = None,
    min_clearance: float = 0.0015,
    tries: int = 1,
    guide: float = 0.0,
) -> tuple[np.ndarray | None, dict[str, Any]]:
    """A path of ``problem`` through its slot, or ``None``, and what it took: the sweep led
    by bar A, then by bar E, ``tries`` times (each from another random first pose), the
    first that works; Bi-RRT (``max_nodes`` each) joins the start to the sweep's first
    pose backed off from the wall, and its last pose to the goal; then :func:`simplify`."""
    rng = np.random.default_rng(seed)
    info: dict[str, Any] = {}
    for order in ("A", "E") * max(1, tries):
        t0 = time.perf_counter()
        poses = sweep(robot, problem, order, ds, rng, log, min_clearance, guide)
        info[f"sweep_{order}_s"] = round(info.get(f"sweep_{order}_s", 0.0) + time.perf_counter() - t0, 1)
        if poses is None:
            continue
        pre, post = poses[0].copy(), poses[-1].copy()
        pre[0] -= 0.08
        post[0] += 0.08
        ends = []
        for a, b in ((problem.start, pre), (post, problem.goal)):
            r = BiRRT(robot, seed=seed, max_nodes=max_nodes).plan(Problem(problem.scene, np.asarray(a), np.asarray(b)))
            ends.append(r)
        if not edge_free(robot, problem, pre, poses[0])[0] or not edge_free(robot, problem, poses[-1], post)[0]:
            info[f"sweep_{order}_backoff"] = "collides"
            continue
        if not all(r.success for r in ends):
            info[f"sweep_{order}_ends"] = [bool(r.success) for r in ends]
            continue
        # (Bi-RRT's paths end at pre and start at post)
        raw = np.concatenate([ends[0].path, np.array(poses), ends[1].path])
        info["order"] = order
        info["sweep_poses"] = len(poses)
        t1 = time.perf_counter()
        path = simplify(robot, problem, raw, seed)
        info["simplify_s"] = round(time.perf_counter() - t1, 1)
        info["vertices"] = len(path)
        info["length"] = round(float(path_length(robot, path)), 3)
        info["raw_length"] = round(float(path_length(robot, raw)), 3)
        return path, info
    return None, info
