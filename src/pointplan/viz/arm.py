"""Pictures of an arm and its path: the obstacles, the arm's spheres at the start, the goal
and a few configurations between, and the trace of its last link (PNG), or the arm moving
along the path (GIF)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.animation import PillowWriter
from numpy.typing import NDArray

from ..robots.arm import ArmRobot
from ..scenes.scene import Problem
from .plot3d import _draw_obstacles, _new_figure, _setup_axes, _sphere_faces

Array = NDArray[np.float64]

C_START, C_GOAL, C_PATH = "#2a9d3f", "#d1495b", "#4c72b0"


def _view_box(problem: Problem, robot: ArmRobot, path: Array) -> tuple[Array, Array]:
    """A cube around the obstacles and every sphere along the path."""
    pts = [robot.sphere_centers(np.asarray(path, np.float64)).reshape(-1, 3)]
    for s in problem.scene.obstacles:
        c = getattr(s, "center", None)
        if c is not None:
            pts.append(np.asarray(c, np.float64)[None])
    allp = np.concatenate(pts)
    mid = (allp.min(0) + allp.max(0)) / 2
    half = float((allp.max(0) - allp.min(0)).max()) / 2 + 0.15
    return mid - half, mid + half


def _draw_arm(ax: Any, robot: ArmRobot, q: Array, color: str, alpha: float) -> Any:
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    c = robot.sphere_centers(np.asarray(q, np.float64)[None])[0]
    faces = np.concatenate([_sphere_faces(ci, r) for ci, r in zip(c, robot.model.sphere_radius, strict=True)])
    coll = Poly3DCollection(faces, facecolors=color, edgecolors="none", alpha=alpha)
    ax.add_collection3d(coll)
    return coll


def _densify(path: Array, step: float = 0.05) -> Array:
    out = [path[:1]]
    for a, b in zip(path[:-1], path[1:], strict=True):
        k = max(1, int(np.ceil(np.linalg.norm(b - a) / step)))
        out.append(a + (b - a) * (np.arange(1, k + 1) / k)[:, None])
    return np.concatenate(out)


def render_arm_path(
    problem: Problem, robot: ArmRobot, path: Array | None, output: str | Path, title: str = "", between: int = 3
) -> None:
    """A PNG of ``problem`` with ``robot`` at its start (green) and goal (red) and, with a
    ``path``, ``between`` configurations along it (blue, faint) and the trace of the last
    sphere's centre."""
    fig = _new_figure((6.0, 5.5))
    ax = fig.add_subplot(projection="3d")
    q = np.stack([problem.start, problem.goal]) if path is None or not len(path) else np.asarray(path, np.float64)
    low, high = _view_box(problem, robot, q)
    _setup_axes(ax, low, high)
    _draw_obstacles(ax, problem.scene.obstacles, 0.25)
    _draw_arm(ax, robot, problem.start, C_START, 0.35)
    _draw_arm(ax, robot, problem.goal, C_GOAL, 0.35)
    if path is not None and len(path) > 1:
        dense = _densify(np.asarray(path, np.float64))
        for k in np.linspace(0, len(dense) - 1, between + 2)[1:-1].astype(int):
            _draw_arm(ax, robot, dense[k], C_PATH, 0.12)
        tip = robot.sphere_centers(dense)[:, -1]
        ax.plot(tip[:, 0], tip[:, 1], tip[:, 2], color=C_PATH, lw=1.5)
    ax.set_title(title or problem.tag, fontsize=9)
    fig.savefig(output, dpi=110, bbox_inches="tight")


def render_arm_gif(
    problem: Problem, robot: ArmRobot, path: Array, output: str | Path, frames: int = 40, fps: float = 12
) -> None:
    """A GIF of ``robot`` moving along ``path`` (``frames`` configurations evenly spaced in
    joint space) among the obstacles of ``problem``."""
    path = np.asarray(path, np.float64)
    if len(path) < 2:
        raise ValueError("a GIF needs a path of at least two configurations")
    dense = _densify(path)
    pick = dense[np.linspace(0, len(dense) - 1, frames).astype(int)]
    fig = _new_figure((5.0, 4.6))
    ax = fig.add_subplot(projection="3d")
    low, high = _view_box(problem, robot, path)
    _setup_axes(ax, low, high)
    _draw_obstacles(ax, problem.scene.obstacles, 0.25)
    tip = robot.sphere_centers(dense)[:, -1]
    ax.plot(tip[:, 0], tip[:, 1], tip[:, 2], color=C_PATH, lw=1.0, alpha=0.6)
    ax.set_title(problem.tag, fontsize=9)
    writer = PillowWriter(fps=fps)  # type: ignore[arg-type]  # (any number works; the stubs say int)
    with writer.saving(fig, str(output), dpi=90):
        for q in pick:
            art = _draw_arm(ax, robot, q, C_PATH, 0.55)
            writer.grab_frame()
            art.remove()
