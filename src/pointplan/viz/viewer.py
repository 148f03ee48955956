"""An interactive 3D viewer of planning problems in the browser, built on ``viser``.

``viser`` is optional (``pip install 'pointplan[viewer]'``) and imported only when a
viewer is started; :func:`scene_meshes` and :func:`robot_mesh` need only ``trimesh``.

The viewer shows the workspace bounds as a wireframe, the obstacles as translucent
meshes, the robot at the start (green) and the goal (red), the path as a polyline of the
robot's positions, and a moving robot placed by a time slider (one step per
configuration of :func:`~pointplan.evaluation.evaluate.timed_path`) with a play/pause
checkbox. Moving obstacles (:class:`~pointplan.scenes.scene.DynamicScene`) and observed
points (``points_at``) follow the slider. Colours are those of :mod:`.plot3d`.

Scene tree (the names are stable, tests and scripts may look them up):

``/bounds``, ``/obstacles/<k>``, ``/obstacle_points/<k>`` (point-cloud obstacles),
``/start``, ``/goal`` (frames placed at the configurations, with ``.../body`` meshes),
``/path``, ``/robot`` (a frame whose pose is the robot's pose at the slider's step) with
``/robot/body``, and ``/points`` (the observed points).
"""

from __future__ import annotations

import atexit
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from matplotlib.colors import to_rgb
from numpy.typing import NDArray

from ..geometry import lie
from ..geometry.sampling import shape_to_trimesh
from ..geometry.shapes import Capsule, Mesh, PointCloud, Shape, Sphere
from ..robots.base import Robot
from ..scenes.scene import Problem
from .plot3d import (
    C_BOUNDS,
    C_GOAL,
    C_OBSTACLE,
    C_OBSTACLE_EDGE,
    C_PATH,
    C_POINTS,
    C_START,
)

Array = NDArray[np.float64]

VIEWER_MISSING = "the interactive viewer needs viser: pip install 'pointplan[viewer]'"

#: opacity of the obstacles and of the start/goal robots
OBSTACLE_OPACITY = 0.45
ENDPOINT_OPACITY = 0.6
#: time steps per second when playing
PLAY_FPS = 10.0
#: facets around the axis of tessellated capsules, cylinders and cones
SECTIONS = 32


def _rgb255(color: str) -> tuple[int, int, int]:
    r, g, b = to_rgb(color)
    return round(255 * r), round(255 * g), round(255 * b)


# ---------------------------------------------------------------------------- meshes
def _solid_mesh(shape: Shape) -> Any:
    """A closed triangle mesh of one solid 3D shape in the world frame, wound outwards."""
    import trimesh

    if shape.dim != 3:
        raise ValueError(f"the viewer shows 3D shapes, got a {shape.dim}D {type(shape).__name__}")
    if isinstance(shape, Capsule) and float(np.linalg.norm(shape.b - shape.a)) < 1e-12:
        shape = Sphere((shape.a + shape.b) / 2.0, shape.radius)  # a degenerate capsule is a ball
    m = shape_to_trimesh(shape, sections=SECTIONS)
    if isinstance(shape, Mesh):
        m = trimesh.Trimesh(np.array(m.vertices), np.array(m.faces), process=True)
        if m.is_watertight and m.volume < 0:  # a closed mesh wound inwards
            m.invert()
    return m


def scene_meshes(obstacles: Sequence[Shape]) -> list[Any]:
    """One world-frame :class:`trimesh.Trimesh` per solid obstacle, in order.

    Boxes are exact; spheres, capsules, cylinders and cones are tessellated (their
    vertices lie on the surface, so the meshes sit just inside the shapes); meshes are
    copied with duplicate vertices merged and wound outwards. Point clouds have no
    surface and are skipped (the viewer draws them as dots)."""
    return [_solid_mesh(s) for s in obstacles if not isinstance(s, PointCloud)]


def robot_mesh(robot: Robot) -> Any:
    """The robot's body as one :class:`trimesh.Trimesh` in the *body* frame (its parts
    concatenated: spheres as icospheres, boxes as boxes)."""
    import trimesh

    if robot.dim != 3:
        raise ValueError(f"the viewer needs a 3D robot, {robot.name} is {robot.dim}D")
    p = robot.parts
    parts = []
    for c, r in zip(p.sphere_centers, p.sphere_radii):
        parts.append(trimesh.creation.icosphere(subdivisions=3, radius=float(r)).apply_translation(c))
    for c, rot, h in zip(p.box_centers, p.box_rotations, p.box_halfs):
        tf = np.eye(4)
        tf[:3, :3], tf[:3, 3] = rot, c
        parts.append(trimesh.creation.box(extents=2.0 * np.asarray(h), transform=tf))
    if not parts:
        raise ValueError(f"{robot.name} has no body parts to show")
    return trimesh.util.concatenate(parts)


def robot_pose(robot: Robot, q: Any) -> tuple[Array, Array]:
    """``(position (3,), quaternion wxyz (4,))`` of the body frame at ``q`` (viser's
    convention), taken from ``robot.rotations`` so any orientation coordinates work."""
    q = np.asarray(q, np.float64).reshape(-1)
    if q.shape != (robot.config_dim,):
        raise ValueError(f"a configuration of {robot.name} has {robot.config_dim} numbers, got {q.shape[0]}")
    xyzw = lie.matrix_to_quat(robot.rotations(q))
    return np.asarray(robot.positions(q), np.float64), np.roll(xyzw, 1)


def _bounds_segments(low: Array, high: Array) -> Array:
    corners = np.array([[x, y, z] for x in (low[0], high[0]) for y in (low[1], high[1]) for z in (low[2], high[2])])
    edges = [(i, j) for i in range(8) for j in range(i + 1, 8) if (i ^ j).bit_count() == 1]
    return corners[np.array(edges)]


def _as_points(points: Any) -> Array:
    if points is None:
        return np.zeros((0, 3))
    p = np.asarray(points, np.float64)
    if p.size == 0:
        return np.zeros((0, 3))
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"points_at(t) must give an (N, 3) array in the world frame, got shape {p.shape}")
    return p


# ---------------------------------------------------------------------------- viewer
def view_problem(
    problem: Problem,
    robot: Robot,
    path: Any = None,
    points_at: Callable[[int], Any] | None = None,
    port: int = 8080,
    block: bool = True,
    host: str = "127.0.0.1",
) -> Any:
    """Show ``problem`` in the browser and return the :class:`viser.ViserServer`.

    ``path`` ``(K, config_dim)`` is cut into time steps with
    :func:`~pointplan.evaluation.evaluate.timed_path`; the slider runs over them (without a
    path it has the single step 0 at the start). For a dynamic scene the obstacles are
    drawn at the slider's step (``problem.scene.obstacles_at(t)``). ``points_at(t)`` gives
    observed points ``(N, 3)`` in the world frame at step ``t``, drawn in orange.

    ``block=True`` serves until Ctrl-C (then stops the server); ``block=False`` returns at
    once and the caller stops the server with ``server.stop()``. ``host`` is the address
    to listen on (``"0.0.0.0"`` to let other machines connect). The URL is printed; viser
    may pick another port when ``port`` is taken (``server.get_port()`` tells which).

    The returned server carries the viewer's handles as ``server.pointplan``, a dict with
    ``slider``, ``play``, ``robot`` (the moving frame; an arm's batched sphere mesh), ``obstacles`` (the current obstacle
    mesh handles), ``points``, ``timed`` (the configurations per step) and ``show_step``.
    """
    try:
        import viser
    except ImportError:
        raise ImportError(VIEWER_MISSING) from None

    scene = problem.scene
    if scene.dim != 3:
        raise ValueError(f"the viewer shows 3D scenes, this one is {scene.dim}D (use pointplan.viz.plot2d)")
    timed = _timed_configs(problem, robot, path)
    server = viser.ViserServer(host=host, port=port, verbose=False)
    try:  # a failure while filling the scene must not leave the server running
        handles = _fill_scene(server, problem, robot, timed)
        handles.update(_add_controls(server, problem, robot, timed, handles, points_at))
        server.pointplan = handles  # type: ignore[attr-defined]
    except BaseException:
        server.stop()
        raise

    shown = "localhost" if host in ("0.0.0.0", "::", "") else host
    print(
        f"pointplan viewer: open http://{shown}:{server.get_port()}  ({len(timed)} time steps; Ctrl-C to stop)"
        if block
        else f"pointplan viewer: open http://{shown}:{server.get_port()}",
        flush=True,
    )
    if not block:
        return server
    try:
        while True:
            time.sleep(0.5)
    except KeyboardInterrupt:
        print("pointplan viewer: stopped")
    finally:
        server.stop()
    return server


def _timed_configs(problem: Problem, robot: Robot, path: Any) -> Array:
    """The configurations per time step of ``path`` (the start alone without a path)."""
    from ..evaluation.evaluate import timed_path

    if path is not None and len(np.asarray(path)):
        p = np.asarray(path, np.float64)
        if p.ndim != 2 or p.shape[1] != robot.config_dim:
            raise ValueError(f"a path for {robot.name} must be a (K, {robot.config_dim}) array, got shape {p.shape}")
        return timed_path(robot, p)
    return np.asarray(problem.start, np.float64).reshape(1, robot.config_dim)


def _obstacle_drawer(server: Any, handles: dict[str, Any]) -> Callable[[Sequence[Shape]], None]:
    """A function drawing obstacles as meshes (moving ones: only their vertices change)."""
    obstacle_color = _rgb255(C_OBSTACLE)

    def draw_obstacles(obstacles: Sequence[Shape]) -> None:
        meshes = scene_meshes(obstacles)
        old = handles["obstacles"]
        same = len(old) == len(meshes) and all(
            np.array_equal(f, m.faces) for f, m in zip(handles["obstacle_faces"], meshes)
        )
        if same:
            for h, m in zip(old, meshes):
                h.vertices = np.asarray(m.vertices, np.float32)
            return
        for h in old:
            h.remove()
        handles["obstacles"] = [
            server.scene.add_mesh_simple(
                f"/obstacles/{k}",
                np.asarray(m.vertices),
                np.asarray(m.faces),
                color=obstacle_color,
                opacity=OBSTACLE_OPACITY,
                flat_shading=True,
                side="double",
                cast_shadow=False,
                receive_shadow=False,
            )
            for k, m in enumerate(meshes)
        ]
        handles["obstacle_faces"] = [np.array(m.faces) for m in meshes]

    return draw_obstacles


def _is_arm(robot: Robot) -> bool:
    """An articulated arm: its spheres move apart, not as one rigid body."""
    from ..robots.arm import ArmRobot

    return isinstance(robot, ArmRobot)


def _add_arm(server: Any, robot: Robot, name: str, q: Array, color: str, opacity: float | None) -> Any:
    """An arm's spheres at ``q`` as one batched mesh (one unit icosphere per sphere, placed
    and scaled); moving it is setting ``batched_positions`` to the centres at a new ``q``."""
    import trimesh

    ball = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
    centres = robot.sphere_centers(np.asarray(q, np.float64)[None])[0]  # type: ignore[attr-defined]
    radii = np.asarray(robot.parts.sphere_radii, np.float32).reshape(-1)
    return server.scene.add_batched_meshes_simple(
        name,
        np.asarray(ball.vertices, np.float32),
        np.asarray(ball.faces, np.uint32),
        batched_wxyzs=np.tile(np.array([1.0, 0.0, 0.0, 0.0], np.float32), (len(radii), 1)),
        batched_positions=centres.astype(np.float32),
        batched_scales=radii,
        batched_colors=_rgb255(color),
        opacity=opacity,
        flat_shading=True,
    )


def _add_body(server: Any, robot: Robot, name: str, q: Array, color: str, opacity: float | None) -> Any:
    if _is_arm(robot):
        return _add_arm(server, robot, name, q, color, opacity)
    body = robot_mesh(robot)
    pos, wxyz = robot_pose(robot, q)
    frame = server.scene.add_frame(name, show_axes=False, position=pos, wxyz=wxyz)
    server.scene.add_mesh_simple(
        f"{name}/body",
        np.asarray(body.vertices),
        np.asarray(body.faces),
        color=_rgb255(color),
        opacity=opacity,
        flat_shading=True,
    )
    return frame


def _fill_scene(server: Any, problem: Problem, robot: Robot, timed: Array) -> dict[str, Any]:
    """Camera, bounds, obstacles, start, goal, path, the moving robot and its points."""
    scene = problem.scene
    arm = _is_arm(robot)
    # an arm's scene bounds its joints; the workspace it covers is what to frame
    low, high = (scene.workspace_low, scene.workspace_high) if arm else (scene.low, scene.high)  # type: ignore[attr-defined]
    extent = float(np.max(high - low))
    server.scene.set_up_direction("+z")
    centre = (low + high) / 2.0
    server.initial_camera.look_at = tuple(centre)
    # (an arm's workspace box is mostly empty: come closer)
    server.initial_camera.position = tuple(centre + np.array([-1.2, -1.6, 1.1]) * extent * (0.55 if arm else 1.0))
    server.scene.add_line_segments(
        "/bounds", _bounds_segments(low, high), _rgb255(C_BOUNDS), thickness=1.5, thickness_units="screen"
    )
    handles: dict[str, Any] = {"obstacles": [], "obstacle_faces": []}
    handles["draw_obstacles"] = draw_obstacles = _obstacle_drawer(server, handles)
    draw_obstacles(scene.obstacles_at(0))
    clouds = [s for s in scene.obstacles if isinstance(s, PointCloud)]
    for k, s in enumerate(clouds):
        if s.dim == 3 and len(s.points):
            server.scene.add_point_cloud(
                f"/obstacle_points/{k}",
                np.asarray(s.points),
                _rgb255(C_OBSTACLE_EDGE),
                point_size=0.006 * extent,
                precision="float32",
            )
    _add_body(server, robot, "/start", problem.start, C_START, ENDPOINT_OPACITY)
    _add_body(server, robot, "/goal", problem.goal, C_GOAL, ENDPOINT_OPACITY)
    if len(timed) > 1:  # the trace of the body frame, of an arm's hand (its last sphere)
        pos = robot.sphere_centers(timed)[:, -1] if arm else robot.positions(timed)  # type: ignore[attr-defined]
        server.scene.add_line_segments(
            "/path", np.stack([pos[:-1], pos[1:]], 1), _rgb255(C_PATH), thickness=3.0, thickness_units="screen"
        )
    handles["robot"] = _add_body(server, robot, "/robot", timed[0], C_START, None)
    handles["points"] = server.scene.add_point_cloud(
        "/points",
        np.zeros((1, 3)),
        _rgb255(C_POINTS),
        point_size=0.008 * extent,
        precision="float32",
        point_shape="circle",
        visible=False,
    )
    return handles


def _add_controls(
    server: Any,
    problem: Problem,
    robot: Robot,
    timed: Array,
    handles: dict[str, Any],
    points_at: Callable[[int], Any] | None,
) -> dict[str, Any]:
    """The title, the time-step slider and the play box; the step shown follows the slider."""
    scene, n_steps = problem.scene, len(timed)
    robot_frame, points_handle = handles["robot"], handles["points"]
    title = problem.tag or scene.name or "problem"
    server.gui.add_markdown(
        f"**{title}**  \n{robot.name}, {n_steps} time step{'s' if n_steps != 1 else ''}"
        + ("  \nmoving obstacles" if scene.dynamic else "")
    )
    slider = server.gui.add_slider(
        "time step", min=0, max=max(n_steps - 1, 0), step=1, initial_value=0, disabled=n_steps < 2
    )
    play = server.gui.add_checkbox("play", initial_value=False, disabled=n_steps < 2)
    lock = threading.Lock()

    def show_step(t: int) -> None:
        t = int(np.clip(t, 0, n_steps - 1))
        with lock:
            if _is_arm(robot):
                robot_frame.batched_positions = robot.sphere_centers(timed[t][None])[0].astype(np.float32)  # type: ignore[attr-defined]
            else:
                pos, wxyz = robot_pose(robot, timed[t])
                robot_frame.position = pos
                robot_frame.wxyz = wxyz
            if scene.dynamic:
                handles["draw_obstacles"](scene.obstacles_at(t))
            if points_at is not None:
                pts = _as_points(points_at(t))
                if len(pts):
                    points_handle.points = pts.astype(np.float32)
                points_handle.visible = bool(len(pts))

    slider.on_update(lambda _event: show_step(int(slider.value)))
    show_step(0)
    _start_player(server, slider, play, n_steps)
    return {"slider": slider, "play": play, "timed": timed, "show_step": show_step}


def _start_player(server: Any, slider: Any, play: Any, n_steps: int) -> None:
    """A daemon thread advances the slider while ``play`` is ticked; it ends when the server
    is stopped (``server.stop`` is wrapped to tell it)."""
    stopped = threading.Event()

    def player() -> None:
        while not stopped.wait(1.0 / PLAY_FPS):
            if play.value and n_steps > 1:
                slider.value = (int(slider.value) + 1) % n_steps

    thread = threading.Thread(target=player, name="pointplan-viewer-play", daemon=True)
    thread.start()
    viser_stop = server.stop

    def stop() -> None:
        stopped.set()
        # viser registered its own stop with atexit and unregisters ``self.stop``, which
        # is now this function: unregister the original here
        atexit.unregister(viser_stop)
        viser_stop()
        thread.join(timeout=2.0)

    server.stop = stop
