"""The interactive viewer: obstacle meshes are closed, outward and where the shapes are;
with viser installed, the server starts and stops, and the time slider places the robot,
the moving obstacles and the observed points where the time step says."""

from __future__ import annotations

import sys
import time
from collections.abc import Callable

import numpy as np
import pytest
import trimesh

from pointplan.evaluation.evaluate import timed_path
from pointplan.geometry import lie
from pointplan.geometry.lie import random_rotations
from pointplan.geometry.shapes import (
    Box,
    Capsule,
    Cone,
    Cylinder,
    Mesh,
    PointCloud,
    Sphere,
)
from pointplan.robots import make_robot
from pointplan.scenes import Problem, Scene
from pointplan.scenes.scene import DynamicScene
from pointplan.viz.viewer import VIEWER_MISSING, robot_mesh, scene_meshes

ROT = random_rotations(np.random.default_rng(3), 4)
SIGNS = np.array([[x, y, z] for x in (-1.0, 1.0) for y in (-1.0, 1.0) for z in (-1.0, 1.0)])


def _disc_extent(axis: np.ndarray, r: float) -> np.ndarray:
    """Half extents along the world axes of a disc of radius ``r`` normal to ``axis``."""
    return r * np.sqrt(np.clip(1.0 - axis**2, 0.0, None))


def _expected(shape) -> tuple[np.ndarray, np.ndarray, float, float]:
    """``(low, high, volume, tolerance)`` of a shape, worked out by hand."""
    if isinstance(shape, Box):
        c = shape.center + (SIGNS * shape.half) @ shape.rotation.T
        return c.min(0), c.max(0), float(np.prod(shape.size)), 1e-9
    if isinstance(shape, Sphere):
        r = shape.radius
        return shape.center - r, shape.center + r, 4 / 3 * np.pi * r**3, 0.01 * r
    if isinstance(shape, Capsule):
        r, length = shape.radius, float(np.linalg.norm(shape.b - shape.a))
        lo, hi = np.minimum(shape.a, shape.b) - r, np.maximum(shape.a, shape.b) + r
        return lo, hi, np.pi * r**2 * length + 4 / 3 * np.pi * r**3, 0.01 * r
    if isinstance(shape, Cylinder):
        u, r, h = shape.rotation[:, 2], shape.radius, shape.length / 2
        e = np.abs(u) * h + _disc_extent(u, r)
        return shape.center - e, shape.center + e, np.pi * r**2 * shape.length, 0.01 * r
    if isinstance(shape, Cone):  # base disc at local z = -length/2, apex at +length/2
        u, r, h = shape.rotation[:, 2], shape.radius, shape.length / 2
        apex, base = shape.center + h * u, shape.center - h * u
        e = _disc_extent(u, r)
        return np.minimum(apex, base - e), np.maximum(apex, base + e), np.pi * r**2 * shape.length / 3, 0.01 * r
    if isinstance(shape, Mesh):
        m = trimesh.Trimesh(shape.vertices, shape.faces)
        return shape.vertices.min(0), shape.vertices.max(0), abs(float(m.volume)), 1e-9
    raise TypeError(shape)


_ICO = trimesh.creation.icosphere(subdivisions=2, radius=0.15)
SHAPES = {
    "box": Box([0.1, -0.2, 0.3], [0.3, 0.2, 0.5], ROT[0]),
    "box-axis-aligned": Box([0.0, 0.0, 0.0], [1.0, 0.5, 0.25]),
    "sphere": Sphere([0.2, 0.1, -0.3], 0.12),
    "capsule": Capsule([-0.3, -0.2, 0.1], [0.2, 0.25, -0.15], 0.08),
    "capsule-degenerate": Capsule([0.1, 0.1, 0.1], [0.1, 0.1, 0.1], 0.1),
    "cylinder": Cylinder([0.3, -0.1, 0.2], 0.1, 0.4, ROT[1]),
    "cone": Cone([-0.2, 0.3, 0.0], 0.15, 0.35, ROT[2]),
    "cone-upright": Cone([0.0, 0.0, 0.5], 0.2, 0.6),
    "mesh": Mesh(_ICO.vertices + [0.3, 0.3, 0.3], _ICO.faces),
    # wound inwards: the viewer's mesh must be turned outwards
    "mesh-inward": Mesh(_ICO.vertices - 0.2, _ICO.faces[:, ::-1]),
    # a triangle soup (every triangle with its own vertices): merged into a closed mesh
    "mesh-soup": Mesh(
        (_ICO.vertices @ ROT[3].T)[_ICO.faces].reshape(-1, 3), np.arange(3 * len(_ICO.faces)).reshape(-1, 3)
    ),
}


@pytest.mark.parametrize("name", list(SHAPES))
def test_scene_mesh_is_closed_outward_and_where_the_shape_is(name: str) -> None:
    shape = SHAPES[name]
    (m,) = scene_meshes([shape])
    lo, hi, volume, tol = _expected(shape)
    assert m.is_watertight, f"{name}: mesh is not closed"
    assert m.is_winding_consistent
    assert m.volume > 0, f"{name}: mesh is wound inwards"
    assert m.volume == pytest.approx(volume, rel=0.03)
    b = np.asarray(m.bounds)
    # tessellated surfaces are inscribed: never outside the shape, at most ``tol`` inside
    np.testing.assert_allclose(b[0], lo, atol=tol, err_msg=f"{name}: low corner")
    np.testing.assert_allclose(b[1], hi, atol=tol, err_msg=f"{name}: high corner")
    assert np.all(b[0] >= lo - 1e-9) and np.all(b[1] <= hi + 1e-9), f"{name}: mesh sticks out of the shape"


def test_box_mesh_vertices_are_its_corners() -> None:
    box = SHAPES["box"]
    (m,) = scene_meshes([box])
    corners = box.center + (SIGNS * box.half) @ box.rotation.T
    v = np.asarray(m.vertices)
    assert len(v) == 8
    d = np.linalg.norm(v[:, None] - corners[None], axis=-1)
    assert np.all(d.min(1) < 1e-12) and np.all(d.min(0) < 1e-12)


def test_scene_meshes_keep_order_and_skip_point_clouds() -> None:
    cloud = PointCloud(np.zeros((4, 3)), np.ones((4, 3)))
    shapes = [SHAPES["sphere"], cloud, SHAPES["box"], SHAPES["cone"]]
    meshes = scene_meshes(shapes)
    assert len(meshes) == 3
    for m, s in zip(meshes, [SHAPES["sphere"], SHAPES["box"], SHAPES["cone"]]):
        lo, hi, _, tol = _expected(s)
        np.testing.assert_allclose(np.asarray(m.bounds), [lo, hi], atol=tol)
    assert scene_meshes([]) == []


def test_scene_meshes_refuse_2d_shapes() -> None:
    with pytest.raises(ValueError, match="3D"):
        scene_meshes([Box([0.0, 0.0], [1.0, 1.0])])


def test_robot_mesh_is_the_body_in_its_own_frame() -> None:
    robot = make_robot("sshape")
    p = robot.parts
    corners = (
        p.box_centers[:, None] + np.einsum("pij,pkj->pki", p.box_rotations, SIGNS[None] * p.box_halfs[:, None])
    ).reshape(-1, 3)
    np.testing.assert_allclose(np.asarray(robot_mesh(robot).bounds), [corners.min(0), corners.max(0)], atol=1e-12)
    ball = make_robot("sphere3d")
    r = float(ball.parts.sphere_radii[0])
    np.testing.assert_allclose(
        np.asarray(robot_mesh(ball).bounds),
        [ball.parts.sphere_centers[0] - r, ball.parts.sphere_centers[0] + r],
        atol=1e-9,
    )


# ---------------------------------------------------------------------------- the server
def test_missing_viser_gives_the_install_hint(monkeypatch: pytest.MonkeyPatch) -> None:
    from pointplan.viz.viewer import view_problem

    monkeypatch.setitem(sys.modules, "viser", None)  # import viser -> ImportError
    robot = make_robot("sphere3d")
    problem = Problem(Scene([], np.full(3, -1.0), np.full(3, 1.0)), np.zeros(3), np.ones(3) * 0.5)
    with pytest.raises(ImportError) as e:
        view_problem(problem, robot, block=False)
    assert str(e.value) == VIEWER_MISSING == "the interactive viewer needs viser: pip install 'pointplan[viewer]'"


def _quat(angle: float, axis) -> np.ndarray:
    axis = np.asarray(axis, np.float64) / np.linalg.norm(axis)
    return np.concatenate([np.sin(angle / 2) * axis, [np.cos(angle / 2)]])  # (x, y, z, w)


def _wxyz_to_matrix(wxyz: np.ndarray) -> np.ndarray:
    return lie.quat_to_matrix(np.roll(np.asarray(wxyz, np.float64), -1))


@pytest.fixture
def dynamic_problem() -> Problem:
    low, high = np.full(3, -1.0), np.full(3, 1.0)
    boxes = [Box([0.4, 0.4, 0.0], [0.2, 0.3, 0.4]), Box([-0.5, 0.5, 0.5], [0.3, 0.3, 0.3], ROT[0])]
    targets = [Box([0.4, -0.4, 0.2], [0.2, 0.3, 0.4], ROT[1]), Box([-0.5, -0.2, -0.3], [0.3, 0.3, 0.3], ROT[2])]
    scene = DynamicScene(boxes, targets, low, high, period=16, name="moving")
    start = np.concatenate([[-0.7, -0.7, -0.6], _quat(0.3, [1, 2, 3])])
    goal = np.concatenate([[0.7, 0.6, 0.6], _quat(2.0, [-1, 0.5, 1])])
    return Problem(scene, start, goal, tag="viewer/test")


def test_viewer_starts_moves_and_stops(
    dynamic_problem: Problem, capsys: pytest.CaptureFixture[str], free_port: Callable[[], int]
) -> None:
    pytest.importorskip("viser")
    from pointplan.viz.viewer import view_problem

    robot = make_robot("sshape")
    scene = dynamic_problem.scene
    mid = np.concatenate([[0.0, -0.5, 0.1], _quat(1.0, [0, 1, 0])])
    path = np.stack([dynamic_problem.start, mid, dynamic_problem.goal])
    expected_timed = timed_path(robot, path)
    assert len(expected_timed) > 10  # several time steps, so the slider test means something

    def points_at(t: int) -> np.ndarray:
        return robot.positions(expected_timed[t])[None] + np.linspace(-0.1, 0.1, 3 + t)[:, None] * np.array(
            [1.0, 0.5, -0.25]
        )

    port = free_port()
    server = view_problem(dynamic_problem, robot, path=path, points_at=points_at, port=port, block=False)
    try:
        assert f":{server.get_port()}" in capsys.readouterr().out  # the URL is printed
        h = server.pointplan
        slider = h["slider"]
        assert (slider.min, slider.max, slider.step, slider.value) == (0, len(expected_timed) - 1, 1, 0)
        np.testing.assert_allclose(h["timed"], expected_timed)

        for t in [0, 3, len(expected_timed) - 1, 7]:
            slider.value = t
            q = expected_timed[t]
            np.testing.assert_allclose(
                h["robot"].position, robot.positions(q), atol=1e-6, err_msg=f"robot position at step {t}"
            )
            np.testing.assert_allclose(
                _wxyz_to_matrix(h["robot"].wxyz), robot.rotations(q), atol=1e-6, err_msg=f"robot rotation at step {t}"
            )
            # the moving boxes are drawn where the scene has them at step t
            obstacles = h["obstacles"]
            assert len(obstacles) == len(scene.obstacles)
            for handle, box in zip(obstacles, scene.obstacles_at(t)):
                corners = box.center + (SIGNS * box.half) @ box.rotation.T
                v = np.asarray(handle.vertices, np.float64)
                np.testing.assert_allclose(
                    np.sort(v, 0), np.sort(corners, 0), atol=1e-5, err_msg=f"obstacle at step {t}"
                )
            assert h["points"].visible
            np.testing.assert_allclose(np.asarray(h["points"].points, np.float64), points_at(t), atol=1e-5)

        # playing advances the slider by itself
        slider.value = 0
        h["play"].value = True
        deadline = time.monotonic() + 3.0
        while slider.value == 0 and time.monotonic() < deadline:
            time.sleep(0.05)
        h["play"].value = False
        assert int(slider.value) > 0, "play did not move the slider"

        # the player thread sets the slider and then places the robot: on a loaded machine
        # the test can read between the two, so it waits (a while) for the pair to agree
        def shown() -> bool:
            want = robot.positions(expected_timed[int(slider.value)])
            return bool(np.allclose(h["robot"].position, want, atol=1e-6))

        deadline = time.monotonic() + 3.0
        while not shown() and time.monotonic() < deadline:
            time.sleep(0.05)
        t = int(slider.value)
        np.testing.assert_allclose(h["robot"].position, robot.positions(expected_timed[t]), atol=1e-6)
    finally:
        server.stop()


def test_viewer_without_a_path_shows_the_start(
    capsys: pytest.CaptureFixture[str], free_port: Callable[[], int]
) -> None:
    pytest.importorskip("viser")
    from pointplan.viz.viewer import view_problem

    robot = make_robot("sphere3d")
    obstacles = [
        SHAPES["cone"],
        SHAPES["cylinder"],
        SHAPES["mesh"],
        PointCloud(np.zeros((3, 3)) + 0.5, np.ones((3, 3))),
    ]
    problem = Problem(Scene(obstacles, np.full(3, -1.0), np.full(3, 1.0)), [-0.8, -0.8, -0.8], [0.8, 0.8, 0.8])
    server = view_problem(problem, robot, port=free_port(), block=False)
    try:
        h = server.pointplan
        assert h["slider"].max == 0 and len(h["timed"]) == 1
        np.testing.assert_allclose(h["robot"].position, problem.start, atol=1e-6)
        assert len(h["obstacles"]) == 3  # the point cloud is drawn as dots, not a mesh
        assert not h["points"].visible
    finally:
        server.stop()


def test_viewer_refuses_2d_problems() -> None:
    pytest.importorskip("viser")
    from pointplan.viz.viewer import view_problem

    problem = Problem(Scene([], np.zeros(2), np.ones(2)), [0.1, 0.1], [0.9, 0.9])
    with pytest.raises(ValueError, match="3D"):
        view_problem(problem, make_robot("disc2d"), block=False)


def test_a_failing_viewer_releases_its_port(free_port: Callable[[], int]) -> None:
    pytest.importorskip("viser")
    from pointplan.viz.viewer import view_problem

    robot = make_robot("sphere3d")
    problem = Problem(Scene([SHAPES["sphere"]], np.full(3, -1.0), np.full(3, 1.0)), [-0.8, -0.8, -0.8], [0.8, 0.8, 0.8])
    port = free_port()
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        view_problem(problem, robot, points_at=lambda t: np.zeros((4, 2)), port=port, block=False)
    server = view_problem(problem, robot, port=port, block=False)
    try:
        assert server.get_port() == port  # viser moves to another port when one is taken
    finally:
        server.stop()


def test_viewer_moves_an_arms_spheres_along_its_path(free_port: Callable[[], int]) -> None:
    """An arm is drawn sphere by sphere: at every slider step the batched spheres sit at
    the sphere centres of that step's configuration (pinocchio's placements, through
    ``sphere_centers``, tested against pinocchio in test_arm), scaled by the radii; the
    camera frames the workspace, not the joint limits."""
    pytest.importorskip("viser")
    from pointplan.scenes.mbm import load_problem, make_arm
    from pointplan.viz.viewer import view_problem

    robot = make_arm("panda")
    problem = load_problem("panda", "box", 1)
    path = np.stack([problem.start, (problem.start + problem.goal) / 2, problem.goal])
    server = view_problem(problem, robot, path=path, port=free_port(), block=False)
    try:
        h = server.pointplan
        n = len(h["timed"])
        assert n > 3
        for t in (0, n // 2, n - 1):
            h["show_step"](t)
            want = robot.sphere_centers(h["timed"][t][None])[0]
            np.testing.assert_allclose(h["robot"].batched_positions, want, atol=1e-5)
        np.testing.assert_allclose(h["robot"].batched_scales, robot.model.sphere_radius, atol=1e-6)
        assert not np.allclose(h["timed"][0], h["timed"][-1])
    finally:
        server.stop()
