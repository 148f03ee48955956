"""3D drawings: every renderer writes a readable image, the robot is drawn where ``q`` says,
GIFs have one frame per path configuration, and 2D input is refused."""

from __future__ import annotations

from pathlib import Path

import matplotlib.image as mpimg
import numpy as np
import pytest
import trimesh
from matplotlib.figure import Figure
from mpl_toolkits.mplot3d import proj3d
from PIL import Image

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
from pointplan.viz import plot3d
from pointplan.viz.plot3d import (
    draw_robot_3d,
    draw_scene_3d,
    render_grid_3d,
    render_problem_3d,
    render_rollout_gif,
)

LOW, HIGH = np.full(3, -0.6), np.full(3, 0.6)
SIGNS = np.array([[x, y, z] for x in (-1.0, 1.0) for y in (-1.0, 1.0) for z in (-1.0, 1.0)])


def _quat(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=4)
    return q / np.linalg.norm(q)


@pytest.fixture(scope="module")
def scene() -> Scene:
    rng = np.random.default_rng(0)
    rot = random_rotations(rng, 3)
    ico = trimesh.creation.icosphere(subdivisions=1, radius=0.1)
    big = trimesh.creation.icosphere(subdivisions=4, radius=0.08)  # 5120 faces: decimated
    obstacles = [
        Box([0.3, 0.3, -0.25], [0.3, 0.2, 0.4], rot[0]),
        Sphere([-0.3, 0.35, 0.2], 0.12),
        Capsule([-0.35, -0.3, -0.35], [-0.1, -0.35, 0.1], 0.07),
        Cylinder([0.35, -0.3, 0.25], 0.1, 0.3, rot[1]),
        Cone([0.0, 0.1, 0.35], 0.12, 0.25, rot[2]),
        Mesh(ico.vertices + [0.05, -0.05, -0.3], ico.faces),
        Mesh(big.vertices + [-0.3, 0.3, -0.35], big.faces),
        PointCloud(rng.normal(size=(30, 3)) * 0.03 + [-0.35, 0.0, -0.3], rng.normal(size=(30, 3))),
    ]
    return Scene(obstacles, LOW, HIGH, name="all-shapes")


def _problem(scene: Scene, robot_name: str) -> tuple[Problem, object, np.ndarray]:
    robot = make_robot(robot_name)
    rng = np.random.default_rng(1)
    pos = np.stack([np.linspace(-0.4, 0.4, 6), np.linspace(0.4, -0.3, 6), np.linspace(0.3, -0.2, 6)], 1)
    path = np.concatenate([pos, np.stack([_quat(rng) for _ in pos])], 1) if robot.config_dim == 7 else pos
    return Problem(scene, path[0], path[-1], tag=f"test/{robot_name}"), robot, path


def _check_png(path: Path, size: tuple[int, int]) -> np.ndarray:
    assert path.is_file() and path.stat().st_size > 0
    img = mpimg.imread(path)
    assert img.shape[:2] == size
    # not blank: many distinct colours, and some of each of the scheme's colours
    rgb = (img[..., :3] * 255).round().astype(int)
    assert len(np.unique(rgb.reshape(-1, 3), axis=0)) > 50
    return img


def _has_colour(img: np.ndarray, colour: str, tol: float = 0.12) -> bool:
    from matplotlib.colors import to_rgb

    return bool((np.abs(img[..., :3] - np.array(to_rgb(colour))).max(-1) < tol).any())


@pytest.mark.parametrize("robot_name", ["sphere3d", "sshape"])
def test_render_problem_3d_writes_png(scene: Scene, robot_name: str, tmp_path: Path) -> None:
    problem, robot, path = _problem(scene, robot_name)
    pts = np.random.default_rng(2).uniform(-0.5, 0.5, (40, 3))
    nrm = pts / np.linalg.norm(pts, axis=1, keepdims=True)
    out = tmp_path / "sub" / "problem.png"
    fig = render_problem_3d(problem, robot, path, pts, nrm, output=out, title="a title")
    assert isinstance(fig, Figure)
    img = _check_png(out, (900, 900))
    for colour in (plot3d.C_START, plot3d.C_GOAL, plot3d.C_PATH, plot3d.C_POINTS):
        assert _has_colour(img, colour), colour
    assert fig.axes[0].get_title() == "a title"


def test_render_problem_3d_limits_and_aspect(scene: Scene) -> None:
    problem, robot, path = _problem(scene, "sphere3d")
    fig = render_problem_3d(problem, robot, path)
    ax = fig.axes[0]
    for get, lo, hi in zip((ax.get_xlim, ax.get_ylim, ax.get_zlim), LOW, HIGH):
        assert get() == pytest.approx((lo, hi))
    aspect = ax.get_box_aspect()
    assert aspect[0] == pytest.approx(aspect[1]) and aspect[1] == pytest.approx(aspect[2])


def test_obstacles_override_and_every_shape(scene: Scene) -> None:
    problem, robot, _ = _problem(scene, "sphere3d")
    fig = render_problem_3d(problem, robot, obstacles=[Box([0.0, 0.0, 0.0], [0.2, 0.2, 0.2])])
    fig.canvas.draw()
    (coll,) = [c for c in fig.axes[0].collections if c.get_gid() == plot3d.GID_OBSTACLES]
    assert len(coll.get_paths()) == 6  # just the one box
    # the full scene: one polygon collection with the faces of every solid, big mesh decimated
    fig = render_problem_3d(problem, robot)
    fig.canvas.draw()
    (coll,) = [c for c in fig.axes[0].collections if c.get_gid() == plot3d.GID_OBSTACLES]
    n_faces = len(coll.get_paths())
    assert 6 + 4 * 20 + 2 * plot3d.MAX_MESH_FACES > n_faces > plot3d.MAX_MESH_FACES + 80
    assert len(plot3d._mesh_faces(scene.obstacles[6])) == plot3d.MAX_MESH_FACES


def test_mesh_normals_point_outwards() -> None:
    ico = trimesh.creation.icosphere(subdivisions=1, radius=0.1)
    for faces in (ico.faces, ico.faces[:, ::-1]):  # wound outwards, then inwards
        f = plot3d._mesh_faces(Mesh(ico.vertices, faces))
        n = plot3d._normals(f)
        assert (np.einsum("ij,ij->i", n, f.mean(1)) > 0).all()


def _drawn_vertices(ax, gid: str) -> np.ndarray:  # type: ignore[no-untyped-def]
    ax.figure.canvas.draw()
    colls = [c for c in ax.collections if c.get_gid() == gid]
    assert len(colls) == 1
    return np.concatenate([p.vertices for p in colls[0].get_paths()])


def _projected(ax, pts: np.ndarray) -> np.ndarray:  # type: ignore[no-untyped-def]
    x, y, _ = proj3d.proj_transform(pts[:, 0], pts[:, 1], pts[:, 2], ax.M)
    return np.stack([x, y], 1)


def _axes() -> object:
    fig = plot3d._new_figure((4, 4), 50)
    ax = fig.add_axes((0, 0, 1, 1), projection="3d")
    draw_scene_3d(ax, [], LOW, HIGH)
    return ax


def test_box_robot_drawn_at_q() -> None:
    """The S-shape's drawn polygons have exactly the world corners of its bars at q."""
    robot = make_robot("sshape")
    rng = np.random.default_rng(3)
    q = np.concatenate([[0.1, -0.2, 0.15], _quat(rng)])
    _, bc, br, bh = robot.world_parts(q[None])
    corners = np.concatenate([c + (SIGNS * h) @ r.T for c, r, h in zip(bc[0], br[0], bh[0])])
    ax = _axes()
    draw_robot_3d(ax, robot, q, "green", 0.9)
    drawn = _drawn_vertices(ax, plot3d.GID_ROBOT)
    expected = _projected(ax, corners)
    tol = 1e-6 * np.ptp(expected, 0).max()
    d = np.linalg.norm(drawn[:, None] - expected[None], axis=-1)
    assert d.min(1).max() < tol  # every drawn vertex is a bar corner
    assert d.min(0).max() < tol  # every bar corner is drawn
    # a slightly different pose is told apart
    other = _projected(ax, corners + [0.005, 0.0, 0.0])
    assert np.linalg.norm(drawn[:, None] - other[None], axis=-1).min(1).max() > 100 * tol


def test_sphere_robot_drawn_at_q() -> None:
    """With an orthographic (affine) projection the drawn sphere is centred on the
    projected q and no bigger than its bounding cube, no smaller than its axis points."""
    robot = make_robot("sphere3d")
    q = np.array([0.3, -0.1, 0.2])
    ax = _axes()
    ax.set_proj_type("ortho")
    draw_robot_3d(ax, robot, q, "green", 0.9)
    ax.figure.canvas.draw()
    (coll,) = [c for c in ax.collections if c.get_gid() == plot3d.GID_ROBOT]
    drawn = np.concatenate([p.vertices[:4] for p in coll.get_paths()])  # without the closing vertex
    centre = _projected(ax, q[None])[0]
    scale = np.linalg.norm(_projected(ax, q[None] + robot.radius * SIGNS) - centre, axis=1).max()
    assert np.abs(drawn.mean(0) - centre).max() < 1e-6 * scale
    axis_pts = _projected(ax, q[None] + robot.radius * np.concatenate([np.eye(3), -np.eye(3)]))
    dist = np.linalg.norm(drawn - centre, axis=1).max()
    assert np.linalg.norm(axis_pts - centre, axis=1).max() * (1 - 1e-9) <= dist <= scale * (1 + 1e-9)
    # and the sphere of another configuration is not where this one is drawn
    assert np.abs(_projected(ax, q[None] + 0.01)[0] - drawn.mean(0)).max() > 1e-3 * scale


def test_render_grid_3d(scene: Scene, tmp_path: Path) -> None:
    probs, paths = [], []
    for name in ("sphere3d", "sphere3d", "sphere3d", "sphere3d"):
        p, robot, path = _problem(scene, name)
        probs.append(p)
        paths.append(path)
    paths[1] = None
    out = tmp_path / "grid.png"
    fig = render_grid_3d(probs, robot, paths, output=out, cols=3, titles=list("abcd"))
    assert [ax.get_title() for ax in fig.axes] == list("abcd")
    h, w = _check_png(out, (round(150 * (2 * plot3d.GRID_CELL + 0.35)), round(150 * 3 * plot3d.GRID_CELL))).shape[:2]
    assert w > h
    with pytest.raises(ValueError, match="paths"):
        render_grid_3d(probs, robot, paths[:2])


@pytest.mark.parametrize("robot_name", ["sphere3d", "sshape"])
def test_rollout_gif_frames(scene: Scene, robot_name: str, tmp_path: Path) -> None:
    problem, robot, path = _problem(scene, robot_name)
    out = tmp_path / "rollout.gif"
    seen: list[int] = []

    def obstacles_at(t: int) -> list:
        seen.append(t)
        return [Box([0.0, 0.0, -0.4 + 0.1 * t], [0.2, 0.2, 0.1]), *scene.obstacles[1:3]]

    def points_at(t: int) -> np.ndarray:
        return np.random.default_rng(t).uniform(-0.5, 0.5, (20, 3))

    render_rollout_gif(problem, robot, path, out, obstacles_at=obstacles_at, points_at=points_at, fps=10)
    assert out.stat().st_size > 0
    with Image.open(out) as im:
        assert im.n_frames == len(path)
    assert seen == list(range(len(path)))


def test_rollout_gif_repeated_configurations(scene: Scene, tmp_path: Path) -> None:
    """A robot standing still still gets one frame per configuration."""
    problem, robot, path = _problem(scene, "sphere3d")
    still = np.repeat(path[:1], 3, axis=0)
    out = tmp_path / "still.gif"
    render_rollout_gif(problem, robot, still, out)
    with Image.open(out) as im:
        assert im.n_frames == 3


def test_2d_input_is_refused(tmp_path: Path) -> None:
    from pointplan.scenes.scenarios import Narrow2DScenario

    problem = Narrow2DScenario().problems("test", 1)[0]
    disc = make_robot("disc2d")
    with pytest.raises(ValueError, match="3D scene, this one is 2D"):
        render_problem_3d(problem, disc)
    with pytest.raises(ValueError, match="3D scene"):
        render_grid_3d([problem], disc)
    with pytest.raises(ValueError, match="3D scene"):
        render_rollout_gif(problem, disc, np.zeros((3, 2)), tmp_path / "x.gif")
    ax = _axes()
    with pytest.raises(ValueError, match="3D workspace bounds"):
        draw_scene_3d(ax, [], [0, 0], [1, 1])
    with pytest.raises(ValueError, match="3D shapes"):
        draw_scene_3d(ax, [Box([0.5, 0.5], [0.1, 0.1])], LOW, HIGH)
    with pytest.raises(ValueError, match="3D robot"):
        draw_robot_3d(ax, disc, [0.5, 0.5], "green", 1.0)


def test_bad_path_and_points_are_refused(scene: Scene) -> None:
    problem, robot, path = _problem(scene, "sshape")
    with pytest.raises(ValueError, match=r"\(K, 7\)"):
        render_problem_3d(problem, robot, path[:, :3])
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        render_problem_3d(problem, robot, points=np.zeros((5, 2)))


@pytest.mark.parametrize("n", [2, 3, 4, 12])
def test_ghosts_only_between_start_and_goal(scene: Scene, n: int) -> None:
    problem, robot, path = _problem(scene, "sshape")
    path = np.concatenate([path, path])[:n]
    fig = render_problem_3d(problem, robot, path)
    robots = [c for c in fig.axes[0].collections if c.get_gid() == plot3d.GID_ROBOT]
    assert len(robots) == 2 + min(plot3d.N_GHOSTS, n - 2)
