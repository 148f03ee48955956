"""Matplotlib drawings of 2D planning problems: obstacles, observations, trees and paths.

Everything here draws on :class:`matplotlib.figure.Figure` objects attached to an Agg
canvas, so nothing touches pyplot's global state or the user's backend, and nothing
ever opens a window.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection
from matplotlib.colors import to_rgb
from matplotlib.figure import Figure
from matplotlib.layout_engine import ConstrainedLayoutEngine
from matplotlib.lines import Line2D
from matplotlib.patches import Circle, Polygon, Rectangle
from numpy.typing import NDArray

from ..geometry.shapes import Box, Capsule, PointCloud, Sphere
from ..robots.base import Robot
from ..scenes.scene import Problem, Scene

Array = NDArray[np.float64]

#: success radius around the goal (the environments' default ``goal_tolerance``)
GOAL_TOLERANCE = 0.07
#: figure sizes in inches; PNGs are ``figsize * dpi`` pixels
PROBLEM_FIGSIZE = (8.0, 5.0)
IMAGE_FIGSIZE = (11.5, 5.0)
GRID_CELL = 3.0
GRID_LEGEND_HEIGHT = 0.35
RGB_FIGSIZE = (4.0, 4.0)
RGB_DPI = 100

# colours (a muted palette: obstacles dark, trees faint, the path stands out)
C_OBSTACLE = "#4d4d4d"
C_BOUNDS = "black"
C_START = "#1a9641"
C_GOAL = "#d7191c"
C_PATH = "#1f5fbf"
C_RAW = "0.45"
C_OBS_POINTS = "#8e44ad"
C_TREES = ("#66bd63", "#f4a261", "#74add1", "#e78ac3")


# ---------------------------------------------------------------------------- helpers
def _new_figure(figsize: tuple[float, float], dpi: float) -> Figure:
    fig = Figure(figsize=figsize, dpi=dpi, layout="constrained")
    engine = fig.get_layout_engine()
    assert isinstance(engine, ConstrainedLayoutEngine)
    engine.set(w_pad=0.1, h_pad=0.1)  # inches kept free around the edge
    FigureCanvasAgg(fig)
    return fig


def _require_2d(scene: Scene) -> None:
    if scene.dim != 2:
        raise ValueError(f"the 2D drawings need a 2D scene, this one is {scene.dim}D")


def _box_corners(box: Box) -> Array:
    signs = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    return box.center + (signs * box.half) @ box.rotation.T


def _capsule_outline(cap: Capsule, n: int = 24) -> Array:
    """Polygon of a 2D capsule: a half circle around each end joined by straight sides."""
    a, b = cap.a, cap.b
    axis = b - a
    length = float(np.linalg.norm(axis))
    if length < 1e-12:
        t = np.linspace(0.0, 2 * np.pi, 2 * n, endpoint=False)
        return a + cap.radius * np.stack([np.cos(t), np.sin(t)], 1)
    theta = math.atan2(axis[1], axis[0])
    tb = np.linspace(theta - np.pi / 2, theta + np.pi / 2, n)
    ta = tb + np.pi
    arc_b = b + cap.radius * np.stack([np.cos(tb), np.sin(tb)], 1)
    arc_a = a + cap.radius * np.stack([np.cos(ta), np.sin(ta)], 1)
    return np.concatenate([arc_b, arc_a])


def _draw_obstacles(ax: Axes, scene: Scene) -> None:
    first = True

    def label() -> str:
        nonlocal first
        out = "obstacles" if first else "_nolegend_"
        first = False
        return out

    for s in scene.obstacles:
        if isinstance(s, Box):
            ax.add_patch(Polygon(_box_corners(s), closed=True, fc=C_OBSTACLE, ec="none", zorder=1, label=label()))
        elif isinstance(s, Sphere):
            ax.add_patch(Circle(tuple(s.center), s.radius, fc=C_OBSTACLE, ec="none", zorder=1, label=label()))
        elif isinstance(s, Capsule):
            ax.add_patch(Polygon(_capsule_outline(s), closed=True, fc=C_OBSTACLE, ec="none", zorder=1, label=label()))
        elif isinstance(s, PointCloud):
            ax.scatter(s.points[:, 0], s.points[:, 1], s=2, c=C_OBSTACLE, lw=0, zorder=1, label=label())
        else:
            raise TypeError(f"cannot draw a {type(s).__name__} in 2D")


def robot_label(robot: Robot) -> str:
    """``"<name>, radius <r>"`` for a robot made of one disc or sphere, else its name."""
    parts = robot.parts
    if len(parts.sphere_radii) == 1 and len(parts.box_halfs) == 0:
        return f"{robot.name}, radius {float(parts.sphere_radii[0]):g}"
    return robot.name


def _robot_patches(
    ax: Axes, robot: Robot | None, q: Array, color: str, label: str, zorder: float = 6, body_label: str = "_nolegend_"
) -> None:
    """The robot's body at ``q`` at true size, outlined on top of a small marker at its
    centre (which keeps a tiny robot visible without hiding its size)."""
    q = np.asarray(q, np.float64)
    ax.plot(
        q[0],
        q[1],
        "o",
        ms=6 if robot is None else 3.5,
        mfc=color,
        mec="black",
        mew=0.8 if robot is None else 0.4,
        zorder=zorder,
        label=label,
    )
    if robot is None:
        return
    sc, bc, br, bh = robot.world_parts(q[None])
    for c, r in zip(sc[0], robot.parts.sphere_radii):
        ax.add_patch(
            Circle(
                tuple(c[:2]),
                float(r),
                fc=(*to_rgb(color), 0.35),
                ec="black",
                lw=0.8,
                zorder=zorder + 1,
                label=body_label,
            )
        )
        body_label = "_nolegend_"
    for c, rot, h in zip(bc[0], br[0], bh[0]):
        box = Box(center=c[:2], size=2 * h[:2], rotation=rot[:2, :2])
        ax.add_patch(
            Polygon(
                _box_corners(box),
                closed=True,
                fc=(*to_rgb(color), 0.35),
                ec="black",
                lw=0.8,
                zorder=zorder + 1,
                label=body_label,
            )
        )
        body_label = "_nolegend_"


def _observation_to_world(observation: Array, robot: Robot | None, start: Array) -> tuple[Array, Array | None]:
    """Robot-frame points (and normals) ``(N, 2|4)`` back to the world frame."""
    obs = np.asarray(observation, np.float64)
    if obs.ndim != 2 or obs.shape[1] not in (2, 4):
        raise ValueError(f"expected an (N, 2) or (N, 4) observation, got shape {obs.shape}")
    p, n = obs[:, :2], (obs[:, 2:] if obs.shape[1] == 4 else None)
    if robot is not None and robot.config_dim != robot.dim:
        rot = robot.rotations(np.asarray(start, np.float64))[:2, :2]
        p = p @ rot.T
        n = None if n is None else n @ rot.T
    return p + np.asarray(start, np.float64)[:2], n


def _tree_segments(nodes: Array, parents: Array) -> Array:
    """Edges ``(k, 2, 2)`` from every non-root node to its parent."""
    nodes = np.asarray(nodes, np.float64)
    parent_of = np.asarray(parents, np.int64).reshape(-1)
    child = np.flatnonzero(parent_of >= 0)
    return np.stack([nodes[child, :2], nodes[parent_of[child], :2]], 1)


def _result_summary(result: Any) -> str:
    parts = ["solved" if getattr(result, "success", False) else "failed"]
    nodes = getattr(result, "nodes", None)
    if nodes is not None:
        parts.append(f"{int(nodes)} nodes")
    checks = getattr(result, "collision_checks", None)
    if checks is not None:
        parts.append(f"{int(checks)} checks")
    t = getattr(result, "time_s", None)
    if t is not None:
        parts.append(f"{1000 * float(t):.0f} ms" if t < 10 else f"{float(t):.1f} s")
    return ", ".join(parts)


def _path_of(result: Any, path: Array | None) -> Array | None:
    if path is None and result is not None:
        path = getattr(result, "path", None)
    if path is None:
        return None
    path = np.asarray(path, np.float64)
    return path if path.ndim == 2 and len(path) else None


# ---------------------------------------------------------------------------- drawing
def _draw_trees(ax: Axes, trees: Sequence[Any]) -> None:
    """Search trees ``(nodes, parents)``: one LineCollection per tree."""
    names = ("start tree", "goal tree") if len(trees) == 2 else tuple(f"tree {i + 1}" for i in range(len(trees)))
    for i, (nodes, parents) in enumerate(trees):
        segs = _tree_segments(nodes, parents)
        color = C_TREES[i % len(C_TREES)]
        if len(segs):
            ax.add_collection(LineCollection(list(segs), colors=color, linewidths=0.6, alpha=0.8, zorder=2))
        # a proxy line carries the legend entry (LineCollection legends look odd)
        ax.plot([], [], color=color, lw=1.0, label=f"{names[i]} ({len(np.asarray(nodes))} nodes)")


def _draw_observation(ax: Axes, observation: Array, robot: Robot | None, start: Array, size: float) -> None:
    """Observed points (and normals as short arrows), back in the world frame."""
    pts, nrm = _observation_to_world(observation, robot, start)
    what = "observed points + normals" if nrm is not None else "observed points"
    ax.scatter(pts[:, 0], pts[:, 1], s=9, c=C_OBS_POINTS, lw=0, zorder=4, label=f"{what} ({len(pts)})")
    if nrm is not None:
        ax.quiver(
            pts[:, 0],
            pts[:, 1],
            nrm[:, 0],
            nrm[:, 1],
            angles="xy",
            scale_units="xy",
            scale=1.0 / (0.035 * size),
            width=0.003,
            headwidth=3.5,
            headlength=4,
            headaxislength=3.5,
            color=C_OBS_POINTS,
            alpha=0.8,
            zorder=4,
        )


def _draw_paths(ax: Axes, raw: Any, final: Array | None) -> None:
    """The raw (unsmoothed) path when it differs, then the final path with its nodes."""
    if raw is not None and len(raw):
        raw = np.asarray(raw, np.float64)
        if final is None or raw.shape != final.shape or not np.allclose(raw, final):
            ax.plot(raw[:, 0], raw[:, 1], ls="--", lw=1.0, color=C_RAW, zorder=3, label="raw path")
    if final is not None:
        ax.plot(final[:, 0], final[:, 1], "-", lw=2.5, color=C_PATH, zorder=5, solid_capstyle="round", label="path")
        ax.plot(final[:, 0], final[:, 1], "o", ms=3.5, mfc="white", mec=C_PATH, mew=1.0, zorder=5, label="_nolegend_")


def _draw_endpoints(ax: Axes, problem: Problem, robot: Robot | None, goal_tolerance: float) -> None:
    """The start (with the robot's body) and the goal (its body, or a dot, and the dashed
    circle of the goal tolerance), with a legend entry for the goal."""
    ax.add_patch(
        Circle(
            tuple(problem.goal[:2]),
            goal_tolerance,
            fill=False,
            ec=C_GOAL,
            lw=1.0,
            ls="--",
            zorder=6,
            label="_nolegend_",
        )
    )
    body = robot_label(robot) if robot is not None else "_nolegend_"
    _robot_patches(ax, robot, problem.start, C_START, "start", body_label=body)
    if robot is not None and robot.config_dim == robot.dim:
        _robot_patches(ax, robot, problem.goal, C_GOAL, "_nolegend_")
    else:
        ax.plot(
            problem.goal[0], problem.goal[1], "o", ms=6, mfc=C_GOAL, mec="black", mew=0.8, zorder=7, label="_nolegend_"
        )
    ax.plot(
        [],
        [],
        "o",
        ms=6,
        mfc=C_GOAL,
        mec="black",
        mew=0.8,
        ls="--",
        color=C_GOAL,
        lw=1.0,
        label=f"goal (tol. {goal_tolerance:g})",
    )


def draw_problem(
    ax: Axes,
    problem: Problem,
    robot: Robot | None = None,
    observation: Array | None = None,
    result: Any = None,
    path: Array | None = None,
    show_trees: bool = True,
    title: str | None = None,
    goal_tolerance: float = GOAL_TOLERANCE,
    legend: bool = False,
) -> Axes:
    """Draw a 2D problem on ``ax``.

    Draws the workspace bounds, the obstacles, the start (green) and the goal (red) with
    the robot's body and the goal tolerance circle (dashed), the observed points
    (``observation``: ``(N, 2)`` or ``(N, 4)`` in the robot frame at the start, normals as
    short arrows), the search trees of ``result.trees`` (thin lines), ``result.raw_path``
    (grey dashed) and the final path (``path``, or ``result.path``; thick blue with its
    nodes as dots). ``result`` is anything with the attributes of a planner's
    ``PlanResult``; missing attributes are skipped. Every artist is labelled, so
    ``ax.get_legend_handles_labels()`` gives a legend; ``legend=True`` draws it on ``ax``.
    """
    scene = problem.scene
    _require_2d(scene)
    low, high = scene.low, scene.high

    # bounds (drawn unclipped so that the whole frame line shows at the axes limits)
    ax.add_patch(
        Rectangle(
            tuple(low), *(high - low), fill=False, ec=C_BOUNDS, lw=1.5, zorder=8, clip_on=False, label="_nolegend_"
        )
    )
    _draw_obstacles(ax, scene)

    if show_trees and result is not None:
        _draw_trees(ax, getattr(result, "trees", None) or [])

    if observation is not None:
        _draw_observation(ax, observation, robot, problem.start, float(np.max(high - low)))

    _draw_paths(ax, getattr(result, "raw_path", None) if result is not None else None, _path_of(result, path))

    # start and goal on top
    _draw_endpoints(ax, problem, robot, goal_tolerance)

    ax.set_xlim(low[0], high[0])
    ax.set_ylim(low[1], high[1])
    ax.set_aspect("equal")
    ax.tick_params(labelsize=7, length=2)
    if title is None:
        title = problem.tag or scene.name or ""
        if result is not None:
            title = f"{title}\n{_result_summary(result)}" if title else _result_summary(result)
    if title:
        ax.set_title(title, fontsize=9)
    if legend:
        ax.legend(fontsize=7, loc="best", framealpha=0.9)
    return ax


def _observe_start(problem: Problem, robot: Robot, observer_name: str, n_points: int, seed: int) -> np.ndarray:
    from ..observers import make_observer

    kwargs: dict[str, Any] = {} if observer_name == "image" else {"n_points": n_points}
    observer = make_observer(observer_name, robot, **kwargs)
    observer.bind([problem.scene])
    return observer.observe(np.asarray(problem.start, np.float64)[None], np.random.default_rng(seed))[0]


def render_problem(
    problem: Problem,
    out_path: str | Path,
    robot: Robot,
    observer_name: str = "surface-normals",
    n_points: int = 64,
    result: Any = None,
    seed: int = 0,
    title: str | None = None,
    dpi: float = 150,
) -> Path:
    """Save a PNG of ``problem`` with what ``observer_name`` sees at the start.

    Point observers are drawn on the scene; the ``image`` observer's occupancy image is
    shown in a second panel. Returns the written path.
    """
    _require_2d(problem.scene)
    obs = _observe_start(problem, robot, observer_name, n_points, seed)
    is_image = observer_name == "image"
    fig = _new_figure(IMAGE_FIGSIZE if is_image else PROBLEM_FIGSIZE, dpi)
    if is_image:
        ax, ax_img = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1, 1]})
        draw_problem(ax, problem, robot, None, result, show_trees=True, title=title)
        _draw_occupancy(ax_img, obs, robot)
    else:
        ax = fig.subplots()
        draw_problem(ax, problem, robot, obs, result, show_trees=True, title=title)
    handles, labels = ax.get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside right upper", fontsize=8, frameon=False)
    out = Path(out_path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=dpi)
    return out


def _draw_occupancy(ax: Axes, obs: np.ndarray, robot: Robot) -> None:
    """The occupancy image (rows along x, columns along y) in robot-frame coordinates."""
    from ..observers.image import OccupancyImage

    img = np.asarray(obs).reshape(obs.shape[-2], obs.shape[-1])
    extent = OccupancyImage(robot).extent
    ax.imshow(
        img.T,
        origin="lower",
        cmap="Greys",
        vmin=0.0,
        vmax=1.5,
        extent=(-extent, extent, -extent, extent),
        interpolation="nearest",
    )
    ax.plot(0.0, 0.0, "o", ms=6, mfc=C_START, mec="black", mew=0.8)
    ax.set_title(f"occupancy image {img.shape[0]}\u00d7{img.shape[1]} (robot frame)", fontsize=9)
    ax.set_xlabel("x \u2212 x$_{robot}$", fontsize=8)
    ax.set_ylabel("y \u2212 y$_{robot}$", fontsize=8)
    ax.tick_params(labelsize=7, length=2)
    ax.set_aspect("equal")


#: at most this many kinds of artists appear in a grid's legend
_GRID_LEGEND_ENTRIES = 7


def _legend_columns(ncols: int) -> int:
    """Legend entries per row for a grid ``ncols`` cells wide (about 1.5 inches each)."""
    return max(2, min(_GRID_LEGEND_ENTRIES, int(GRID_CELL * ncols / 1.5)))


def grid_figsize(n: int, ncols: int = 4) -> tuple[float, float]:
    """Figure size (inches) of :func:`render_grid` for ``n`` problems."""
    ncols = max(1, min(ncols, n))
    nrows = max(1, math.ceil(n / ncols))
    legend_rows = math.ceil(_GRID_LEGEND_ENTRIES / _legend_columns(ncols))
    return (GRID_CELL * ncols, GRID_CELL * nrows + GRID_LEGEND_HEIGHT * legend_rows)


def render_grid(
    problems: Sequence[Problem],
    results: Sequence[Any] | None,
    out_path: str | Path,
    robot: Robot,
    titles: Sequence[str] | None = None,
    ncols: int = 4,
    dpi: float = 150,
    show_trees: bool = True,
) -> Path:
    """Save a grid of problems with their results (paths, trees); one shared legend."""
    n = len(problems)
    if n == 0:
        raise ValueError("no problems to draw")
    results = list(results) if results is not None else [None] * n
    if len(results) != n or (titles is not None and len(titles) != n):
        raise ValueError("problems, results and titles must have the same length")
    ncols = max(1, min(ncols, n))
    nrows = math.ceil(n / ncols)
    fig = _new_figure(grid_figsize(n, ncols), dpi)
    axes = np.atleast_1d(fig.subplots(nrows, ncols, squeeze=False)).ravel()
    legend: dict[str, Any] = {}
    for i, ax in enumerate(axes):
        if i >= n:
            ax.set_axis_off()
            continue
        res = results[i]
        if titles is not None:
            title = titles[i]
        else:
            title = problems[i].tag or f"problem {i}"
            if res is not None:
                title = f"{title}\n{_result_summary(res)}"
        draw_problem(ax, problems[i], robot, None, res, show_trees=show_trees, title=title)
        ax.set_title(title, fontsize=8)
        ax.set_xticks([])
        ax.set_yticks([])
        for h, lab in zip(*ax.get_legend_handles_labels()):
            key = lab.split(" (")[0]  # one entry per kind, without per-problem counts
            if key not in legend:
                if isinstance(h, Line2D):
                    h = Line2D(
                        [],
                        [],
                        color=h.get_color(),
                        ls=h.get_linestyle(),
                        lw=h.get_linewidth(),
                        marker=h.get_marker(),
                        ms=h.get_markersize(),
                        mfc=h.get_markerfacecolor(),
                        mec=h.get_markeredgecolor(),
                    )
                legend[key] = h
    fig.legend(
        list(legend.values()),
        list(legend.keys()),
        loc="outside lower center",
        ncols=min(len(legend), _legend_columns(ncols)),
        fontsize=8,
        frameon=False,
    )
    out = Path(out_path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=dpi)
    return out


def render_rgb(problem: Problem, robot: Robot, q: Array, goal_tolerance: float = GOAL_TOLERANCE) -> NDArray[np.uint8]:
    """The scene, the goal and the robot at ``q`` as an ``(H, W, 3)`` uint8 image
    (400 x 400 pixels), for ``render_mode="rgb_array"``."""
    scene = problem.scene
    _require_2d(scene)
    fig = Figure(figsize=RGB_FIGSIZE, dpi=RGB_DPI)
    canvas = FigureCanvasAgg(fig)
    ax = fig.add_axes((0.02, 0.02, 0.96, 0.96))
    ax.add_patch(Rectangle(tuple(scene.low), *(scene.high - scene.low), fill=False, ec=C_BOUNDS, lw=1.5, clip_on=False))
    _draw_obstacles(ax, scene)
    ax.add_patch(Circle(tuple(problem.goal[:2]), goal_tolerance, fill=False, ec=C_GOAL, lw=1.0, ls="--"))
    ax.plot(problem.goal[0], problem.goal[1], "o", ms=6, mfc=C_GOAL, mec="black", mew=0.8, zorder=6)
    _robot_patches(ax, robot, np.asarray(q, np.float64), C_PATH, "_nolegend_", zorder=7)
    ax.set_xlim(scene.low[0], scene.high[0])
    ax.set_ylim(scene.low[1], scene.high[1])
    ax.set_aspect("equal")
    ax.set_axis_off()
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[..., :3].copy()
