"""Matplotlib drawings of 3D planning problems: obstacles, observed points, robots and paths.

Like :mod:`.plot2d`, everything draws on :class:`~matplotlib.figure.Figure` objects with
an Agg canvas: no pyplot state, no window. Every shape is drawn as flat polygons in one
:class:`~mpl_toolkits.mplot3d.art3d.Poly3DCollection` per call (so faces of overlapping
obstacles are depth-sorted together), shaded by a fixed light from above.

Layering: matplotlib can only depth-sort whole collections against each other, which
goes wrong for interlocking shapes. The axes therefore stack artists in a fixed order
(``computed_zorder = False``): bounds, obstacles, observed points, path, ghost robots,
start and goal robots. The robot is never hidden behind a (translucent) obstacle.

Colours: obstacles grey-blue, observed points orange, start green, goal red, path blue.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, cast

import numpy as np
from matplotlib.animation import PillowWriter
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import to_rgba
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from matplotlib.ticker import MaxNLocator
from mpl_toolkits.mplot3d import Axes3D
from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection
from numpy.typing import NDArray

from ..geometry.shapes import (
    Box,
    Capsule,
    Cone,
    Cylinder,
    Mesh,
    PointCloud,
    Shape,
    Sphere,
)
from ..robots.base import Robot
from ..scenes.scene import Problem
from .plot2d import robot_label

Array = NDArray[np.float64]

# colours (start, goal and path as in the 2D drawings)
C_OBSTACLE = "#7b93ad"
C_OBSTACLE_EDGE = "#3b4f66"
C_POINTS = "#f28e2b"
C_START = "#1a9641"
C_GOAL = "#d7191c"
C_PATH = "#1f5fbf"
C_BOUNDS = "0.35"

#: unit vector towards the light (world frame): above, slightly left of and in front of
#: the default view
LIGHT = np.array([-0.35, -0.55, 1.0]) / np.linalg.norm([-0.35, -0.55, 1.0])
#: facets of curved surfaces: around the axis, and along it per half turn
N_AROUND = 24
N_ALONG = 10
#: meshes are drawn with at most this many faces (evenly subsampled)
MAX_MESH_FACES = 3000
#: ghost robot poses drawn along a path (besides start and goal)
N_GHOSTS = 4
#: gids of the collections, to find them in ``ax.collections``
GID_OBSTACLES = "obstacles"
GID_ROBOT = "robot"

DPI = 150
GIF_DPI = 100
GRID_CELL = 4.0

_Z = {"bounds": 0.5, "obstacles": 1, "points": 3, "path": 4, "ghost": 5, "robot": 6, "marker": 7}


# ---------------------------------------------------------------------------- checks
def _bounds_3d(low: Any, high: Any) -> tuple[Array, Array]:
    low = np.asarray(low, np.float64).reshape(-1)
    high = np.asarray(high, np.float64).reshape(-1)
    if low.shape != (3,) or high.shape != (3,):
        raise ValueError(f"the 3D drawings need 3D workspace bounds, got {low.shape[0]}D low and {high.shape[0]}D high")
    if np.any(high <= low):
        raise ValueError("workspace bounds need low < high in every axis")
    return low, high


def _require_3d_problem(problem: Problem, robot: Robot) -> None:
    if problem.scene.dim != 3:
        raise ValueError(
            f"the 3D drawings need a 3D scene, this one is {problem.scene.dim}D (use pointplan.viz.plot2d)"
        )
    _require_3d_robot(robot)


def _require_3d_robot(robot: Robot) -> None:
    if robot.dim != 3:
        raise ValueError(f"the 3D drawings need a 3D robot, {robot.name} is {robot.dim}D (use sphere3d or sshape)")


def _as_path(path: Any, robot: Robot) -> Array | None:
    if path is None:
        return None
    p = np.asarray(path, np.float64)
    if p.ndim != 2 or p.shape[1] != robot.config_dim:
        raise ValueError(f"a path for {robot.name} must be a (K, {robot.config_dim}) array, got shape {p.shape}")
    return p if len(p) else None


def _as_points(points: Any, what: str = "points") -> Array:
    p = np.asarray(points, np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"{what} must be an (N, 3) array in the world frame, got shape {p.shape}")
    return p


# ---------------------------------------------------------------------------- geometry
def _box_faces(center: Array, rotation: Array, half: Array) -> Array:
    """The 6 quads ``(6, 4, 3)`` of an oriented box given by its half sides."""
    signs = np.array([[x, y, z] for x in (-1.0, 1.0) for y in (-1.0, 1.0) for z in (-1.0, 1.0)])
    corners = center + (signs * half) @ np.asarray(rotation).T
    idx = np.array([[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]])
    return corners[idx]


def _revolution(
    radii: Sequence[float] | Array, zs: Sequence[float] | Array, center: Array, rotation: Array, n: int = N_AROUND
) -> Array:
    """Quads ``(F, 4, 3)`` of the surface swept by the profile ``(radius, z)`` (rows, in
    order) around the local z axis, placed in the world by ``rotation`` and ``center``.
    A row of radius 0 collapses to a point (caps, apexes and poles)."""
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    ring = np.stack([np.cos(t), np.sin(t), np.zeros(n)], 1)
    r = np.asarray(radii, np.float64)[:, None, None]
    z = np.asarray(zs, np.float64)[:, None, None]
    grid = r * ring[None] + z * np.array([0.0, 0.0, 1.0])  # (rows, n, 3)
    nxt = np.roll(np.arange(n), -1)
    quads = np.stack([grid[:-1], grid[:-1][:, nxt], grid[1:][:, nxt], grid[1:]], 2)  # (rows-1, n, 4, 3)
    quads = quads.reshape(-1, 4, 3)
    return quads @ np.asarray(rotation).T + center


def _sphere_faces(center: Array, radius: float) -> Array:
    theta = np.linspace(0.0, np.pi, N_ALONG + 1)
    return _revolution(radius * np.sin(theta), radius * np.cos(theta), center, np.eye(3))


def _frame_along(axis: Array) -> Array:
    """A rotation whose third column is the unit vector along ``axis``."""
    z = axis / np.linalg.norm(axis)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z], 1)


def _capsule_faces(cap: Capsule) -> Array:
    axis = cap.b - cap.a
    length = float(np.linalg.norm(axis))
    center = (cap.a + cap.b) / 2.0
    if length < 1e-12:
        return _sphere_faces(center, cap.radius)
    k = N_ALONG // 2
    top = np.linspace(0.0, np.pi / 2, k + 1)
    bottom = np.linspace(np.pi / 2, np.pi, k + 1)
    theta = np.concatenate([top, bottom])
    zs = cap.radius * np.cos(theta) + np.concatenate([np.full(k + 1, length / 2), np.full(k + 1, -length / 2)])
    return _revolution(cap.radius * np.sin(theta), zs, center, _frame_along(axis))


def _cylinder_faces(cyl: Cylinder) -> Array:
    h, r = cyl.length / 2.0, cyl.radius
    return _revolution([0.0, r, r, 0.0], [h, h, -h, -h], cyl.center, cyl.rotation)


def _cone_faces(cone: Cone) -> Array:
    h, r = cone.length / 2.0, cone.radius
    return _revolution([0.0, r, 0.0], [h, -h, -h], cone.center, cone.rotation)


def _mesh_faces(mesh: Mesh, max_faces: int = MAX_MESH_FACES) -> Array:
    """Triangles as quads (last vertex repeated), oriented outwards, at most ``max_faces``."""
    v, f = mesh.vertices, mesh.faces
    if len(f) and len(v):
        tri = v[f]
        # a closed mesh wound inwards has a negative signed volume: flip it
        vol = np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum()
        if vol < 0:
            f = f[:, ::-1]
    if len(f) > max_faces:
        f = f[np.linspace(0, len(f) - 1, max_faces).round().astype(np.int64)]
    tri = v[f]
    return np.concatenate([tri, tri[:, 2:]], 1) if len(tri) else np.zeros((0, 4, 3))


def _normals(faces: Array) -> Array:
    """Unit normals of planar polygons ``(F, V, 3)`` by Newell's method (winding order)."""
    nxt = np.roll(faces, -1, axis=1)
    n = np.cross(faces, nxt).sum(1)
    norm = np.linalg.norm(n, axis=1, keepdims=True)
    return np.where(norm > 1e-15, n / np.where(norm > 1e-15, norm, 1.0), 0.0)


def _outward(faces: Array, inside: Array) -> Array:
    """Normals flipped to point away from the points ``inside`` (one per face)."""
    n = _normals(faces)
    away = faces.mean(1) - inside
    return np.where((np.einsum("ij,ij->i", n, away) < 0)[:, None], -n, n)


def _shape_faces(shape: Shape) -> tuple[Array, Array, bool]:
    """``(faces (F, 4, 3), outward normals (F, 3), has_edges)`` of a solid shape."""
    if shape.dim != 3:
        raise ValueError(f"the 3D drawings need 3D shapes, got a {shape.dim}D {type(shape).__name__}")
    if isinstance(shape, Box):
        f = _box_faces(shape.center, shape.rotation, shape.half)
        return f, _outward(f, shape.center), True
    if isinstance(shape, Sphere):
        f = _sphere_faces(shape.center, shape.radius)
        return f, _outward(f, shape.center), False
    if isinstance(shape, Capsule):
        f = _capsule_faces(shape)
        # outwards from the nearest point of the segment a -> b
        ab = shape.b - shape.a
        den = max(float(ab @ ab), 1e-24)
        s = np.clip((f.mean(1) - shape.a) @ ab / den, 0.0, 1.0)
        return f, _outward(f, shape.a + s[:, None] * ab), False
    if isinstance(shape, Cylinder):
        f = _cylinder_faces(shape)
        return f, _outward(f, shape.center), False
    if isinstance(shape, Cone):
        f = _cone_faces(shape)
        return f, _outward(f, shape.center), False
    if isinstance(shape, Mesh):
        f = _mesh_faces(shape)
        return f, _normals(f), False
    raise TypeError(f"cannot draw a {type(shape).__name__} in 3D")


def _shade(color: Any, normals: Array, alpha: float) -> Array:
    """Per-face RGBA: ``color`` lit by :data:`LIGHT` (ambient plus diffuse)."""
    rgb = np.asarray(to_rgba(color)[:3])
    lit = 0.62 + 0.38 * (normals @ LIGHT)
    out = np.empty((len(normals), 4))
    out[:, :3] = np.clip(rgb * lit[:, None], 0.0, 1.0)
    out[:, 3] = alpha
    return out


def _polys(
    ax: Axes3D, faces: Array, facecolors: Array, edgecolors: Array, lw: float, zorder: float, gid: str, label: str
) -> Poly3DCollection:
    coll = Poly3DCollection(
        faces, facecolors=facecolors, edgecolors=edgecolors, linewidths=lw, zorder=zorder, label=label
    )
    coll.set_gid(gid)
    ax.add_collection3d(coll)
    return coll


# ---------------------------------------------------------------------------- artists
def _setup_axes(ax: Axes3D, low: Array, high: Array) -> None:
    """Limits = the workspace bounds, equal aspect, quiet panes and few ticks."""
    ax.computed_zorder = False
    ax.set_xlim(low[0], high[0])
    ax.set_ylim(low[1], high[1])
    ax.set_zlim(low[2], high[2])
    ax.set_box_aspect(tuple(high - low), zoom=1.12)
    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
        axis.set_major_locator(MaxNLocator(3))
        axis.set_pane_color((0.96, 0.96, 0.97, 1.0))
        info = getattr(axis, "_axinfo", {})  # no public setter for the 3D grid style
        if "grid" in info:
            info["grid"].update(color=(0.85, 0.85, 0.87, 1.0), linewidth=0.5)
    ax.set_xlabel("x", fontsize=8, labelpad=-5)
    ax.set_ylabel("y", fontsize=8, labelpad=-5)
    ax.set_zlabel("z", fontsize=8, labelpad=-5)
    ax.tick_params(labelsize=6, pad=-0.5)


def _draw_bounds(ax: Axes3D, low: Array, high: Array) -> Line3DCollection:
    corners = np.array([[x, y, z] for x in (low[0], high[0]) for y in (low[1], high[1]) for z in (low[2], high[2])])
    edges = [(i, j) for i in range(8) for j in range(i + 1, 8) if (i ^ j).bit_count() == 1]
    lines = Line3DCollection(corners[np.array(edges)], colors=C_BOUNDS, linewidths=0.7, zorder=_Z["bounds"])
    lines.set_gid("bounds")
    ax.add_collection3d(lines)
    return lines


def _draw_obstacles(ax: Axes3D, obstacles: Sequence[Shape], alpha: float) -> list[Any]:
    artists: list[Any] = []
    faces, fcs, ecs = [], [], []
    edge_rgba = np.array(to_rgba(C_OBSTACLE_EDGE, min(1.0, alpha + 0.3)))
    for s in obstacles:
        if isinstance(s, PointCloud):
            if s.dim != 3:
                raise ValueError(f"the 3D drawings need 3D shapes, got a {s.dim}D PointCloud")
            p = s.points
            artists.append(
                ax.scatter(
                    p[:, 0], p[:, 1], p[:, 2], s=3, c=C_OBSTACLE_EDGE, lw=0, depthshade=False, zorder=_Z["obstacles"]
                )
            )
            continue
        f, n, edges = _shape_faces(s)
        faces.append(f)
        fcs.append(_shade(C_OBSTACLE, n, alpha))
        e = np.broadcast_to(edge_rgba if edges else np.zeros(4), (len(f), 4))
        ecs.append(e)
    if faces:
        artists.append(
            _polys(
                ax,
                np.concatenate(faces),
                np.concatenate(fcs),
                np.concatenate(ecs),
                0.5,
                _Z["obstacles"],
                GID_OBSTACLES,
                "obstacles",
            )
        )
    return artists


def _robot_faces(robot: Robot, q: Array) -> tuple[Array, Array, Array]:
    """``(faces, outward normals, is_box_face)`` of the robot's body at ``q``."""
    q = np.asarray(q, np.float64).reshape(-1)
    if q.shape != (robot.config_dim,):
        raise ValueError(f"a configuration of {robot.name} has {robot.config_dim} numbers, got {q.shape[0]}")
    sc, bc, br, bh = robot.world_parts(q[None])
    faces, normals, boxy = [], [], []
    for c, r in zip(sc[0], robot.parts.sphere_radii):
        f = _sphere_faces(c, float(r))
        faces.append(f)
        normals.append(_outward(f, c))
        boxy.append(np.zeros(len(f), bool))
    for c, rot, h in zip(bc[0], br[0], bh[0]):
        f = _box_faces(c, rot, h)
        faces.append(f)
        normals.append(_outward(f, c))
        boxy.append(np.ones(len(f), bool))
    if not faces:
        return np.zeros((0, 4, 3)), np.zeros((0, 3)), np.zeros(0, bool)
    return np.concatenate(faces), np.concatenate(normals), np.concatenate(boxy)


def _draw_robot(
    ax: Axes3D,
    robot: Robot,
    q: Array,
    color: Any,
    alpha: float,
    zorder: float = _Z["robot"],
    edge: Any = "black",
    label: str = "_nolegend_",
) -> Poly3DCollection:
    faces, normals, boxy = _robot_faces(robot, q)
    fc = _shade(color, normals, alpha)
    ec = np.zeros((len(faces), 4))
    ec[boxy] = to_rgba(edge, min(1.0, alpha + 0.2))
    return _polys(ax, faces, fc, ec, 0.5, zorder, GID_ROBOT, label)


def _draw_points(ax: Axes3D, points: Array, normals: Array | None, low: Array, high: Array) -> list[Any]:
    points = _as_points(points)
    out: list[Any] = []
    if normals is not None:
        normals = _as_points(normals, "normals")
        if normals.shape != points.shape:
            raise ValueError(f"normals {normals.shape} must match points {points.shape}")
        length = 0.04 * float(np.max(high - low))
        segs = np.stack([points, points + length * normals], 1)
        lines = Line3DCollection(segs, colors=C_POINTS, linewidths=0.8, alpha=0.9, zorder=_Z["points"])
        ax.add_collection3d(lines)
        out.append(lines)
    out.append(
        ax.scatter(
            points[:, 0],
            points[:, 1],
            points[:, 2],
            s=7,
            c=C_POINTS,
            edgecolors="#8a4a0b",
            linewidths=0.3,
            depthshade=False,
            zorder=_Z["points"],
        )
    )
    return out


def _draw_path(
    ax: Axes3D, robot: Robot, path: Array, ghosts: int = N_GHOSTS, upto: int | None = None, floor: float | None = None
) -> list[Any]:
    """Polyline of the robot's centres, its nodes as dots and ``ghosts`` faint robots;
    with ``floor``, its shadow on the plane ``z = floor``."""
    pos = robot.positions(path)
    out: list[Any] = []
    if floor is not None:  # the path's shadow on the floor, a depth cue
        out += ax.plot(
            pos[:, 0], pos[:, 1], np.full(len(pos), floor), "-", color="0.55", lw=1.0, alpha=0.6, zorder=_Z["bounds"]
        )
    if upto is None:
        out += ax.plot(
            pos[:, 0], pos[:, 1], pos[:, 2], "-", color=C_PATH, lw=2.0, zorder=_Z["path"], solid_capstyle="round"
        )
        out += ax.plot(
            pos[:, 0], pos[:, 1], pos[:, 2], "o", ms=2.5, mfc="white", mec=C_PATH, mew=0.8, zorder=_Z["path"]
        )
    else:  # a rollout frame: travelled part solid, the rest faint
        out += ax.plot(pos[:, 0], pos[:, 1], pos[:, 2], "--", color=C_PATH, lw=1.0, alpha=0.5, zorder=_Z["path"])
        out += ax.plot(
            pos[: upto + 1, 0], pos[: upto + 1, 1], pos[: upto + 1, 2], "-", color=C_PATH, lw=2.0, zorder=_Z["path"]
        )
    if ghosts > 0 and len(path) > 2:
        idx = np.unique(np.linspace(0, len(path) - 1, ghosts + 2).round().astype(int))
        idx = idx[(idx > 0) & (idx < len(path) - 1)]  # start and goal are drawn apart
        for i in idx:
            out.append(_draw_robot(ax, robot, path[i], C_PATH, 0.18, zorder=_Z["ghost"], edge=C_PATH))
    return out


def _sphere_rings(ax: Axes3D, robot: Robot, q: Array) -> list[Any]:
    """The outline of each sphere of the robot's body at ``q`` as seen from the axes' view
    direction: a circle of the sphere's radius, so its size shows whatever covers it."""
    elev, azim = np.radians(float(ax.elev)), np.radians(float(ax.azim))
    w = np.array([np.cos(elev) * np.cos(azim), np.cos(elev) * np.sin(azim), np.sin(elev)])
    u = np.cross(w, [0.0, 0.0, 1.0])
    u = u / np.linalg.norm(u) if np.linalg.norm(u) > 1e-9 else np.array([1.0, 0.0, 0.0])
    v = np.cross(w, u)
    t = np.linspace(0.0, 2 * np.pi, 49)
    ring = np.cos(t)[:, None] * u + np.sin(t)[:, None] * v
    centres = robot.world_parts(np.asarray(q, np.float64)[None])[0][0]
    out: list[Any] = []
    for c, r in zip(centres, robot.parts.sphere_radii):
        pts = c + float(r) * ring
        out += ax.plot(pts[:, 0], pts[:, 1], pts[:, 2], "-", color="black", lw=0.8, zorder=_Z["marker"])
    return out


def _draw_endpoints(ax: Axes3D, robot: Robot, start: Array | None, goal: Array | None) -> list[Any]:
    """The robot at ``start`` and ``goal`` (with its spheres outlined) and a small marker at
    each centre (for the axes' current view)."""
    out: list[Any] = []
    for q, color in ((goal, C_GOAL), (start, C_START)):
        if q is None:
            continue
        out.append(_draw_robot(ax, robot, q, color, 0.9))
        out += _sphere_rings(ax, robot, q)
        p = robot.positions(np.asarray(q, np.float64))
        # a marker keeps a small robot visible
        out += ax.plot([p[0]], [p[1]], [p[2]], "o", ms=2.5, mfc=color, mec="black", mew=0.4, zorder=_Z["marker"])
    return out


def _legend_handles(points: bool, path: bool, start: str = "start", robot: Robot | None = None) -> list[Any]:
    h: list[Any] = [Patch(fc=C_OBSTACLE, ec=C_OBSTACLE_EDGE, alpha=0.6, label="obstacles")]
    if robot is not None:
        h.append(
            Line2D([], [], ls="none", marker="o", ms=7, mfc="none", mec="black", mew=0.8, label=robot_label(robot))
        )
    if points:
        h.append(
            Line2D([], [], ls="none", marker="o", ms=4, mfc=C_POINTS, mec="#8a4a0b", mew=0.3, label="observed points")
        )
    h.append(Line2D([], [], ls="none", marker="o", ms=6, mfc=C_START, mec="black", mew=0.7, label=start))
    h.append(Line2D([], [], ls="none", marker="o", ms=6, mfc=C_GOAL, mec="black", mew=0.7, label="goal"))
    if path:
        h.append(Line2D([], [], color=C_PATH, lw=2.0, label="path"))
    return h


def _new_figure(figsize: tuple[float, float], dpi: float = DPI) -> Figure:
    fig = Figure(figsize=figsize, dpi=dpi)
    FigureCanvasAgg(fig)
    return fig


def _title_of(problem: Problem) -> str:
    return problem.tag or problem.scene.name or ""


def _save(fig: Figure, output: str | Path | None, dpi: float = DPI) -> None:
    if output is None:
        return
    out = Path(output)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=dpi)


# ---------------------------------------------------------------------------- public API
def draw_scene_3d(ax: Axes3D, obstacles: Sequence[Shape], low: Any, high: Any, alpha: float = 0.35) -> None:
    """Draw ``obstacles`` (any :data:`~pointplan.geometry.shapes.Shape`; meshes with at
    most :data:`MAX_MESH_FACES` faces, point clouds as dots) and the workspace bounds as a
    thin wireframe box on the 3D axes ``ax``. Sets the limits to the bounds, an equal
    aspect and a fixed artist order (see the module docstring)."""
    low, high = _bounds_3d(low, high)
    _setup_axes(ax, low, high)
    _draw_bounds(ax, low, high)
    _draw_obstacles(ax, obstacles, alpha)


def draw_robot_3d(ax: Axes3D, robot: Robot, q: Any, color: Any, alpha: float) -> None:
    """Draw the body of ``robot`` at configuration ``q`` (spheres as spheres, boxes as
    boxes with dark edges) as one collection with gid ``"robot"``."""
    _require_3d_robot(robot)
    _draw_robot(ax, robot, np.asarray(q, np.float64), color, alpha)


def _draw_problem(
    ax: Axes3D,
    problem: Problem,
    robot: Robot,
    path: Array | None,
    points: Any,
    normals: Any,
    title: str | None,
    obstacles: Sequence[Shape] | None,
    elev: float,
    azim: float,
    fontsize: float = 9,
) -> None:
    scene = problem.scene
    draw_scene_3d(ax, scene.obstacles if obstacles is None else obstacles, scene.low, scene.high)
    if points is not None:
        _draw_points(ax, points, normals, scene.low, scene.high)
    if path is not None:
        _draw_path(ax, robot, path, floor=float(scene.low[2]))
    ax.view_init(elev=elev, azim=azim)
    _draw_endpoints(ax, robot, problem.start, problem.goal)
    title = _title_of(problem) if title is None else title
    if title:
        ax.set_title(title, fontsize=fontsize, pad=0)


def render_problem_3d(
    problem: Problem,
    robot: Robot,
    path: Any = None,
    points: Any = None,
    normals: Any = None,
    output: str | Path | None = None,
    title: str | None = None,
    obstacles: Sequence[Shape] | None = None,
    elev: float = 25,
    azim: float = -60,
    figsize: tuple[float, float] = (6, 6),
) -> Figure:
    """A figure of a 3D problem: obstacles (``obstacles`` overrides the scene's, e.g.
    moving obstacles at some time), observed ``points`` ``(N, 3)`` in the world frame
    (with ``normals`` as short segments), the robot at the start (green) and the goal
    (red), and ``path`` ``(K, config_dim)`` as a polyline of the robot's centres with a
    few faint robot poses along it. Saves a PNG to ``output`` if given."""
    _require_3d_problem(problem, robot)
    p = _as_path(path, robot)
    fig = _new_figure(figsize)
    ax = fig.add_axes((0.0, 0.07, 1.0, 0.88), projection="3d")
    _draw_problem(ax, problem, robot, p, points, normals, title, obstacles, elev, azim)
    fig.legend(
        handles=_legend_handles(points is not None, p is not None, robot=robot),
        loc="lower center",
        ncols=6,
        fontsize=8,
        frameon=False,
        handlelength=1.5,
        columnspacing=1.2,
    )
    _save(fig, output)
    return fig


def render_grid_3d(
    problems: Sequence[Problem],
    robot: Robot,
    paths: Sequence[Any] | None = None,
    output: str | Path | None = None,
    cols: int = 3,
    titles: Sequence[str] | None = None,
    azim: float = -60,
) -> Figure:
    """Several problems (with their paths; ``None`` entries allowed) in a grid of 3D
    subplots with one shared legend, seen from azimuth ``azim`` (degrees). Saves a PNG to
    ``output`` if given."""
    n = len(problems)
    if n == 0:
        raise ValueError("no problems to draw")
    if paths is not None and len(paths) != n:
        raise ValueError(f"got {len(paths)} paths for {n} problems")
    if titles is not None and len(titles) != n:
        raise ValueError(f"got {len(titles)} titles for {n} problems")
    for pr in problems:
        _require_3d_problem(pr, robot)
    cols = max(1, min(int(cols), n))
    rows = math.ceil(n / cols)
    legend_h = 0.35
    fig = _new_figure((GRID_CELL * cols, GRID_CELL * rows + legend_h))
    height = GRID_CELL * rows + legend_h
    any_path = False
    for i, pr in enumerate(problems):
        r, c = divmod(i, cols)
        rect = (c / cols, (legend_h + (rows - 1 - r) * GRID_CELL) / height, 1.0 / cols, 0.94 * GRID_CELL / height)
        ax = cast(Axes3D, fig.add_axes(rect, projection="3d"))
        p = _as_path(paths[i], robot) if paths is not None else None
        any_path |= p is not None
        title = titles[i] if titles is not None else (_title_of(pr) or f"problem {i}")
        _draw_problem(ax, pr, robot, p, None, None, title, None, 25, azim, fontsize=8)
        ax.set_box_aspect(tuple(pr.scene.high - pr.scene.low), zoom=1.0)  # room for the tick labels
    fig.legend(
        handles=_legend_handles(False, any_path, robot=robot), loc="lower center", ncols=5, fontsize=8, frameon=False
    )
    _save(fig, output)
    return fig


def render_rollout_gif(
    problem: Problem,
    robot: Robot,
    path: Any,
    output: str | Path,
    obstacles_at: Callable[[int], Sequence[Shape]] | None = None,
    points_at: Callable[[int], Any] | None = None,
    fps: float = 8,
    elev: float = 25,
    azim: float = -60,
) -> None:
    """An animated GIF of the robot moving along ``path``, one frame per configuration.

    ``obstacles_at(t)`` gives the obstacles at frame ``t`` (moving obstacles, e.g.
    ``scene.obstacles_at``) and ``points_at(t)`` the observed points ``(N, 3)`` (world
    frame) at frame ``t``; without them the scene's obstacles and no points are drawn.
    The figure is built once; only the moving artists are redrawn per frame."""
    _require_3d_problem(problem, robot)
    p = _as_path(path, robot)
    if p is None:
        raise ValueError("a rollout needs a path with at least one configuration")
    scene = problem.scene
    low, high = scene.low, scene.high
    fig = _new_figure((5.0, 5.0), GIF_DPI)
    ax = cast(Axes3D, fig.add_axes((0.0, 0.07, 1.0, 0.86), projection="3d"))
    draw_scene_3d(ax, [] if obstacles_at is not None else scene.obstacles, low, high)
    ax.view_init(elev=elev, azim=azim)
    _draw_endpoints(ax, robot, None, problem.goal)
    fig.legend(
        handles=_legend_handles(points_at is not None, True, "robot"),
        loc="lower center",
        ncols=5,
        fontsize=7,
        frameon=False,
        handlelength=1.5,
    )
    name = _title_of(problem)
    out = Path(output)
    out.parent.mkdir(parents=True, exist_ok=True)
    writer = PillowWriter(fps=fps)  # type: ignore[arg-type]  # (any number works; the stubs say int)
    moving: list[Any] = []
    with writer.saving(fig, str(out), dpi=GIF_DPI):
        for t, q in enumerate(p):
            for a in moving:
                a.remove()
            moving = []
            if obstacles_at is not None:
                moving += _draw_obstacles(ax, list(obstacles_at(t)), 0.35)
            if points_at is not None:
                pts = points_at(t)
                if pts is not None and len(pts):
                    moving += _draw_points(ax, pts, None, low, high)
            moving += _draw_path(ax, robot, p, ghosts=0, upto=t, floor=float(low[2]))
            moving.append(_draw_robot(ax, robot, q, C_START, 0.9))
            pos = robot.positions(q)
            moving += ax.plot(
                [pos[0]], [pos[1]], [pos[2]], "o", ms=4, mfc=C_START, mec="black", mew=0.6, zorder=_Z["marker"]
            )
            # the step counter also keeps every frame distinct (GIF writers merge equal frames)
            ax.set_title(f"{name}   t = {t}/{len(p) - 1}" if name else f"t = {t}/{len(p) - 1}", fontsize=8, pad=0)
            writer.grab_frame()
