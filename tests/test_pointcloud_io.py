"""Your own point cloud: point files with or without normals, estimated normals, depth
images, and planning on a bare cloud from the command line."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import trimesh

from pointplan.cli import main
from pointplan.evaluation import check_path
from pointplan.geometry import lie
from pointplan.geometry.clouds import depth_to_points, estimate_normals, read_depth_image, read_point_file
from pointplan.geometry.sampling import area_weighted_points
from pointplan.geometry.shapes import Box, PointCloud, Sphere
from pointplan.observers import make_observer
from pointplan.planners import make_planner
from pointplan.robots import make_robot
from pointplan.scenes.io import SceneFormatError, load_points_scene, load_scene

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "scenes" / "cloud_example.json"


def scene_doc(dim: int, obstacle: dict[str, Any], problems: list[dict[str, Any]] | None = None) -> dict[str, Any]:
    return {
        "format": "pointplan-scene",
        "version": 1,
        "dim": dim,
        "bounds": {"low": [-1.0] * dim, "high": [1.0] * dim},
        "obstacles": [obstacle],
        "problems": problems or [],
    }


def write(d: Path, doc: dict[str, Any], name: str = "scene.json") -> Path:
    (d / name).write_text(json.dumps(doc))
    return d / name


def box_cloud(n: int = 3000, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    box = Box(center=[0.1, -0.2, 0.3], size=[0.5, 0.3, 0.4], rotation=lie.so3_exp([0.3, -0.2, 0.6]))
    p, nrm, _ = area_weighted_points([box], n, np.random.default_rng(seed))
    return p, nrm


def agreement(est: np.ndarray, true: np.ndarray, degrees: float = 15.0) -> float:
    return float(np.mean(np.einsum("pi,pi->p", est, true) > np.cos(np.radians(degrees))))


def ply_with_normals(path: Path, p: np.ndarray, n: np.ndarray) -> None:
    mesh = trimesh.Trimesh(vertices=p, vertex_normals=n, process=False)
    path.write_bytes(trimesh.exchange.ply.export_ply(mesh, encoding="binary", vertex_normal=True))


# ============================================================================ readers
def test_ply_with_normals(tmp_path: Path) -> None:
    p, n = box_cloud(500)
    ply_with_normals(tmp_path / "c.ply", p, n)
    points, normals = read_point_file(tmp_path / "c.ply")
    np.testing.assert_allclose(points, p, atol=1e-6)  # PLY stores float32
    assert normals is not None
    np.testing.assert_allclose(normals, n, atol=1e-6)
    cloud = load_scene(write(tmp_path, scene_doc(3, {"type": "points", "path": "c.ply"}))).scene.obstacles[0]
    assert isinstance(cloud, PointCloud)
    np.testing.assert_allclose(cloud.normals, n, atol=1e-5)  # the file's normals, not estimates


def test_ply_without_normals_gets_estimated_normals(tmp_path: Path) -> None:
    p, n = box_cloud(3000)
    trimesh.PointCloud(p).export(tmp_path / "c.ply")
    points, normals = read_point_file(tmp_path / "c.ply")
    assert normals is None and points.shape == (3000, 3)
    cloud = load_scene(write(tmp_path, scene_doc(3, {"type": "points", "path": "c.ply"}))).scene.obstacles[0]
    np.testing.assert_allclose(np.linalg.norm(cloud.normals, axis=1), 1.0)
    assert agreement(cloud.normals, n) > 0.95


def test_flat_ply_is_a_2d_cloud(tmp_path: Path) -> None:
    t = np.linspace(0, 2 * np.pi, 200, endpoint=False)
    p = np.c_[0.3 * np.cos(t), 0.3 * np.sin(t)]
    trimesh.PointCloud(np.c_[p, np.zeros(len(p))]).export(tmp_path / "ring.ply")
    cloud = load_scene(write(tmp_path, scene_doc(2, {"type": "points", "path": "ring.ply"}))).scene.obstacles[0]
    assert cloud.points.shape == (200, 2)
    assert agreement(cloud.normals, p / 0.3) == 1.0  # outwards
    # a cloud that is not flat is no 2D cloud
    trimesh.PointCloud(np.c_[p, np.ones(len(p))]).export(tmp_path / "lifted.ply")
    with pytest.raises(SceneFormatError, match=r"obstacles\[0\]\.path: .*'lifted.ply' holds 3D points"):
        load_scene(write(tmp_path, scene_doc(2, {"type": "points", "path": "lifted.ply"})))


def test_pcd_with_and_without_normals(tmp_path: Path) -> None:
    pypcd4 = pytest.importorskip("pypcd4")
    p, n = box_cloud(2000)
    pypcd4.PointCloud.from_points(
        np.c_[p, n].astype(np.float32), ("x", "y", "z", "normal_x", "normal_y", "normal_z"), (np.float32,) * 6
    ).save(tmp_path / "with.pcd")
    pypcd4.PointCloud.from_xyz_points(p.astype(np.float32)).save(tmp_path / "bare.pcd")
    points, normals = read_point_file(tmp_path / "with.pcd")
    np.testing.assert_allclose(points, p, atol=1e-6)
    assert normals is not None
    np.testing.assert_allclose(normals, n, atol=1e-6)
    bare = load_scene(write(tmp_path, scene_doc(3, {"type": "points", "path": "bare.pcd"}))).scene.obstacles[0]
    assert agreement(bare.normals, n) > 0.95


@pytest.mark.parametrize("suffix", [".npy", ".xyz", ".csv"])
def test_npy_and_text_without_normals(tmp_path: Path, suffix: str) -> None:
    p, n = box_cloud(2000)
    if suffix == ".npy":
        np.save(tmp_path / f"c{suffix}", p)
    else:
        np.savetxt(tmp_path / f"c{suffix}", p, delimiter="," if suffix == ".csv" else " ")
    cloud = load_scene(write(tmp_path, scene_doc(3, {"type": "points", "path": f"c{suffix}"}))).scene.obstacles[0]
    np.testing.assert_allclose(cloud.points, p, atol=1e-12)
    assert agreement(cloud.normals, n) > 0.95


@pytest.mark.parametrize("bad", ["zero", "nan", "tiny"])
def test_degenerate_normals_name_the_file(tmp_path: Path, bad: str) -> None:
    p, n = box_cloud(50)
    n = n.copy()
    n[7] = {"zero": 0.0, "nan": np.nan, "tiny": 1e-300}[bad]
    np.save(tmp_path / "scan.npy", np.c_[p, n])
    with pytest.raises(SceneFormatError) as info:
        load_scene(write(tmp_path, scene_doc(3, {"type": "points", "path": "scan.npy"})))
    assert info.value.field == "obstacles[0].path"
    assert "scan.npy" in str(info.value) and "scene.json" in str(info.value)
    assert re.search(r"degenerate|NaN", str(info.value))


def test_all_zero_normals_in_a_ply_are_an_error(tmp_path: Path) -> None:
    p, _ = box_cloud(50)
    ply_with_normals(tmp_path / "flat.ply", p, np.zeros_like(p))
    with pytest.raises(
        SceneFormatError, match=r"obstacles\[0\]\.path: points file 'flat.ply': 50 of 50 normals are degenerate"
    ):
        load_scene(write(tmp_path, scene_doc(3, {"type": "points", "path": "flat.ply"})))


# ============================================================================ normals
def test_estimated_normals_of_a_sphere_and_a_box() -> None:
    rng = np.random.default_rng(3)
    p, n, _ = area_weighted_points([Sphere(center=[0.2, 0.1, -0.3], radius=0.25)], 2000, rng)
    assert agreement(estimate_normals(p), n) > 0.99
    p, n = box_cloud(4000, seed=1)
    est = estimate_normals(p)
    assert agreement(est, n) > 0.95
    assert np.mean(np.einsum("pi,pi->p", est, n) < 0) < 0.01  # oriented outwards
    noisy = p + rng.normal(0.0, 0.002, p.shape)
    assert agreement(estimate_normals(noisy), n) > 0.9


def test_viewpoint_orients_normals_towards_it() -> None:
    # a wall seen from one side: the camera's side is the outside
    g = np.stack(np.meshgrid(np.linspace(-0.5, 0.5, 30), np.linspace(-0.5, 0.5, 30)), -1).reshape(-1, 2)
    p = np.c_[g, np.zeros(len(g))]
    for view, want in (([0.1, 0.2, 2.0], [0, 0, 1]), ([0.0, 0.0, -1.0], [0, 0, -1])):
        est = estimate_normals(p, viewpoint=np.array(view))
        np.testing.assert_allclose(est, np.tile(want, (len(p), 1)), atol=1e-9)


def test_viewpoint_field_in_a_scene_file(tmp_path: Path) -> None:
    g = np.stack(np.meshgrid(np.linspace(-0.5, 0.5, 20), np.linspace(-0.5, 0.5, 20)), -1).reshape(-1, 2)
    np.save(tmp_path / "wall.npy", np.c_[g, np.zeros(len(g))])
    doc = scene_doc(3, {"type": "points", "path": "wall.npy", "viewpoint": [0.0, 0.0, -0.8], "k": 8})
    cloud = load_scene(write(tmp_path, doc)).scene.obstacles[0]
    np.testing.assert_allclose(cloud.normals[:, 2], -1.0, atol=1e-9)
    doc["obstacles"][0]["k"] = 2
    with pytest.raises(SceneFormatError, match=r"obstacles\[0\]\.k: expected an integer of at least 3"):
        load_scene(write(tmp_path, doc))


# ============================================================================ depth images
def plane_depth(h: int = 48, w: int = 64) -> tuple[np.ndarray, dict[str, float]]:
    intr = {"fx": 60.0, "fy": 55.0, "cx": 31.5, "cy": 23.5}
    depth = np.full((h, w), 1.5)
    depth[:3, :5] = 0.0  # no return
    return depth, intr


def test_depth_image_round_trip_against_a_plane() -> None:
    depth, intr = plane_depth()
    pts = depth_to_points(depth, **intr)
    assert len(pts) == depth.size - 15
    np.testing.assert_allclose(pts[:, 2], 1.5)
    # projecting back lands on the pixels
    u = pts[:, 0] * intr["fx"] / pts[:, 2] + intr["cx"]
    v = pts[:, 1] * intr["fy"] / pts[:, 2] + intr["cy"]
    np.testing.assert_allclose(u, np.round(u), atol=1e-9)
    np.testing.assert_allclose(depth[np.round(v).astype(int), np.round(u).astype(int)], 1.5)
    # a pose moves the plane: a camera at (0, 0, 2) looking down (z forward = world -z)
    pose = np.eye(4)
    pose[:3, :3] = np.diag([1.0, -1.0, -1.0])
    pose[:3, 3] = [0.0, 0.0, 2.0]
    world = depth_to_points(depth, **intr, pose=pose)
    np.testing.assert_allclose(world[:, 2], 0.5)
    # millimetres in a 16-bit image
    mm = depth_to_points((depth * 1000).astype(np.uint16), **intr, depth_scale=0.001)
    np.testing.assert_allclose(mm, pts)


def test_depth_png_in_a_scene_file(tmp_path: Path) -> None:
    from PIL import Image

    depth, intr = plane_depth()
    Image.fromarray((depth * 1000).astype(np.uint16)).save(tmp_path / "depth.png")
    np.testing.assert_array_equal(read_depth_image(tmp_path / "depth.png"), depth * 1000)
    q = [0.0, 1.0, 0.0, 0.0]  # half a turn about x: the camera looks down the world's -z
    ob = {
        "type": "points",
        "depth": "depth.png",
        "intrinsics": intr,
        "depth_scale": 0.001,
        "camera_pose": {"position": [0.0, 0.0, 2.0], "quaternion": q},
        "stride": 2,
    }
    doc = scene_doc(3, ob)
    doc["bounds"] = {"low": [-2, -2, 0], "high": [2, 2, 3]}
    cloud = load_scene(write(tmp_path, doc)).scene.obstacles[0]
    np.testing.assert_allclose(cloud.points[:, 2], 0.5, atol=1e-9)
    assert len(cloud.points) == (depth[::2, ::2] > 0).sum()
    # towards the camera
    np.testing.assert_allclose(cloud.normals, np.tile([0.0, 0.0, 1.0], (len(cloud.points), 1)), atol=1e-9)
    ob["path"] = "depth.png"
    with pytest.raises(SceneFormatError, match="exactly one of 'path'"):
        load_scene(write(tmp_path, doc))


# ============================================================================ planning
def test_observers_see_the_cloud_and_its_normals() -> None:
    p, n = box_cloud(2000)
    scene = load_points_scene_from_arrays(p, n)
    robot = make_robot("sphere3d")
    obs = make_observer("global", robot, n_points=64)
    obs.bind([scene])
    q = np.array([[0.9, 0.9, 0.9]])
    out = obs.observe(q, np.random.default_rng(0))[0]
    world = out[:, :3] + q[0]
    dist = np.min(np.linalg.norm(world[:, None] - p[None], axis=2), axis=1)
    assert np.all(dist < 1e-5)  # the cloud's own points
    idx = np.argmin(np.linalg.norm(world[:, None] - p[None], axis=2), axis=1)
    np.testing.assert_allclose(out[:, 3:], n[idx], atol=1e-5)  # with the cloud's normals


def load_points_scene_from_arrays(p: np.ndarray, n: np.ndarray) -> Any:
    from pointplan.scenes import Scene

    return Scene([PointCloud(p, n)], low=np.full(3, -1.0), high=np.full(3, 1.0), name="cloud")


def test_the_example_cloud_has_no_normals_and_the_policy_solves_it(tmp_path: Path) -> None:
    doc = json.loads(EXAMPLE.read_text())
    ply = EXAMPLE.parent / doc["obstacles"][0]["path"]
    assert ply.suffix == ".ply" and ply.stat().st_size < 200_000
    points, normals = read_point_file(ply)
    assert normals is None
    out, png = tmp_path / "plan.json", tmp_path / "plan.png"
    assert (
        main(["plan", "--scene", str(EXAMPLE), "--planner", "policy", "--json", str(out), "-o", str(png), "--quiet"])
        == 0
    )
    result = json.loads(out.read_text())
    assert result["metrics"]["success_rate"] == 1.0
    sf = load_scene(EXAMPLE)
    robot = make_robot(sf.robot)
    for problem, rec in zip(sf.problems, result["problems"]):
        assert rec["success"] and check_path(robot, problem, np.array(rec["path"]))
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_plan_writes_a_picture_of_a_3d_cloud(tmp_path: Path) -> None:
    p, _ = box_cloud(1500)
    trimesh.PointCloud(p).export(tmp_path / "box.ply")
    doc = scene_doc(3, {"type": "points", "path": "box.ply"}, [{"start": [-0.8, -0.8, -0.8], "goal": [0.8, 0.6, 0.8]}])
    doc["robot"] = "sphere3d"
    png = tmp_path / "plan3d.png"
    assert main(["plan", "--scene", str(write(tmp_path, doc)), "--planner", "birrt", "-o", str(png), "--quiet"]) == 0
    assert png.stat().st_size > 10_000 and png.read_bytes()[:4] == b"\x89PNG"


def test_plan_on_a_bare_point_file(tmp_path: Path) -> None:
    p, _ = box_cloud(1500)
    np.save(tmp_path / "box.npy", p)
    scene = load_points_scene(tmp_path / "box.npy")
    assert scene.dim == 3 and np.all(scene.low < p.min(0)) and np.all(scene.high > p.max(0))
    out = tmp_path / "o.json"
    args = [
        "plan",
        "--points",
        str(tmp_path / "box.npy"),
        "--bounds=-1,-1,-1,1,1,1",
        "--start=-0.8,-0.8,-0.8",
        "--goal",
        "0.8,0.6,0.8",
        "--json",
        str(out),
        "--quiet",
    ]
    assert main(args) == 0
    assert json.loads(out.read_text())["metrics"]["success_rate"] == 1.0
    # drawn problems when none are given
    assert main(["plan", "--points", str(tmp_path / "box.npy"), "--episodes", "2", "--quiet"]) == 0
    assert main(["plan", "--points", str(tmp_path / "box.npy"), "--start", "0,0"]) == 2


def test_birrt_avoids_the_cloud() -> None:
    sf = load_scene(EXAMPLE)
    robot = make_robot("disc2d")
    res = make_planner("birrt", robot, seed=0).plan(sf.problems[0])
    assert res.success and check_path(robot, sf.problems[0], res.path)
    # every configuration of the path keeps clear of every point
    d = np.min(np.linalg.norm(res.path[:, None] - sf.scene.obstacles[0].points[None], axis=2))
    assert d > float(robot.parts.sphere_radii.max())
