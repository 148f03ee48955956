"""Depth images in: a plane and a box rendered by ray casting come back as points on their
surfaces with normals towards the camera (Python, a scene file and ``pointplan plan
--depth``), and bad inputs are refused in one line."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from pointplan.cli import main
from pointplan.geometry import lie
from pointplan.geometry.clouds import CloudError, camera_pose, depth_to_cloud, read_depth_cloud
from pointplan.scenes.io import SceneFormatError, load_depth_scene, load_scene

INTR = (60.0, 58.0, 31.5, 23.5)
H, W = 48, 64
BOX_CENTER, BOX_HALF = np.array([0.1, -0.05, 0.2]), np.array([0.3, 0.2, 0.2])
#: world normals of the faces: the floor (0), then the box's -x, +x, -y, +y, -z, +z
FACE_NORMALS = np.array([[0, 0, 1], [-1, 0, 0], [1, 0, 0], [0, -1, 0], [0, 1, 0], [0, 0, -1], [0, 0, 1]], float)


def look_at(position: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The rotation (camera to world) of a camera at ``position`` looking at ``target``,
    x right and y down in the image (OpenCV)."""
    z = target - position
    z = z / np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x = x / np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z], axis=1)


def ray_cast(position: np.ndarray, rot: np.ndarray, box: bool) -> tuple[np.ndarray, np.ndarray]:
    """Depth (the camera-frame z of the first hit; 0 for none) and the face hit (-1 for
    none) of every pixel, for the floor z = 0 and, with ``box``, the box on it."""
    fx, fy, cx, cy = INTR
    u, v = np.meshgrid(np.arange(W, dtype=float), np.arange(H, dtype=float))
    ray = np.stack([(u - cx) / fx, (v - cy) / fy, np.ones_like(u)], axis=-1) @ rot.T  # camera z = 1
    with np.errstate(divide="ignore", invalid="ignore"):
        t_floor = -position[2] / ray[..., 2]
    depth = np.where(t_floor > 0, t_floor, np.inf)
    face = np.where(t_floor > 0, 0, -1)
    if box:
        with np.errstate(divide="ignore", invalid="ignore"):
            lo = (BOX_CENTER - BOX_HALF - position) / ray
            hi = (BOX_CENTER + BOX_HALF - position) / ray
        near = np.minimum(lo, hi)
        t_in, t_out = near.max(axis=-1), np.maximum(lo, hi).min(axis=-1)
        axis = near.argmax(axis=-1)
        positive = np.take_along_axis(ray, axis[..., None], axis=-1)[..., 0] < 0  # entering through the + face
        hit = (t_in <= t_out) & (t_in > 0) & (t_in < depth)
        depth = np.where(hit, t_in, depth)
        face = np.where(hit, 1 + 2 * axis + positive, face)
    return np.where(np.isfinite(depth), depth, 0.0), face


def surface_distance(points: np.ndarray) -> np.ndarray:
    """Distance of each point to the nearer of the floor and the box's surface."""
    d = np.abs(points - BOX_CENTER) - BOX_HALF
    outside = np.linalg.norm(np.maximum(d, 0.0), axis=1)
    to_box = np.where(outside > 0, outside, -d.max(axis=1))
    return np.minimum(np.abs(points[:, 2]), np.abs(to_box))


CAMERA = np.array([1.4, -1.6, 1.8])
ROT = look_at(CAMERA, np.array([0.0, 0.0, 0.1]))
POSE7 = np.concatenate([CAMERA, lie.matrix_to_quat(ROT)])


@pytest.mark.parametrize("box", [False, True], ids=["plane", "box"])
def test_points_lie_on_the_rendered_surfaces_and_normals_face_the_camera(box: bool) -> None:
    depth, face = ray_cast(CAMERA, ROT, box)
    depth[0, :4] = [0.0, np.nan, np.inf, -1.0]  # no return, and garbage
    face[0, :4] = -1
    points, normals = depth_to_cloud(depth, INTR, POSE7)
    valid = face >= 0
    assert len(points) == valid.sum() and valid.sum() > 0.5 * H * W
    assert surface_distance(points).max() < 1e-6
    if box:
        assert (face[valid] > 0).sum() > 100  # the box is seen, on more than one face
        assert len(np.unique(face[face > 0])) >= 2
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-12)
    assert np.all(np.einsum("pi,pi->p", normals, CAMERA - points) > 0)
    # where a pixel and its four neighbours see the same face, its normal is the face's
    f = np.pad(face, 1, constant_values=-1)
    inner = (face >= 0) & np.all([np.roll(f, s, a)[1:-1, 1:-1] == face for s in (-1, 1) for a in (0, 1)], axis=0)
    inner_of_valid = inner[valid]
    assert inner_of_valid.sum() > 0.6 * valid.sum()
    np.testing.assert_allclose(normals[inner_of_valid], FACE_NORMALS[face[valid][inner_of_valid]], atol=1e-6)
    # the same pose as a 4 x 4 matrix
    matrix = camera_pose(POSE7)
    np.testing.assert_allclose(matrix[:3, :3], ROT, atol=1e-12)
    again, _ = depth_to_cloud(depth, INTR, matrix)
    np.testing.assert_allclose(again, points, atol=1e-12)


def test_a_lone_pixel_and_a_depth_edge() -> None:
    """A pixel without neighbours faces back along its ray; across a jump in depth the
    normal comes from the side that stays on the surface."""
    depth = np.zeros((5, 7))
    depth[2, 3] = 1.0
    points, normals = depth_to_cloud(depth, (10.0, 10.0, 3.0, 2.0))
    np.testing.assert_allclose(normals, [[0.0, 0.0, -1.0]])
    np.testing.assert_allclose(points, [[0.0, 0.0, 1.0]])
    step = np.full((6, 8), 1.0)
    step[:, 4:] = 3.0  # a wall behind, far from the front plane
    points, normals = depth_to_cloud(step, (10.0, 10.0, 3.5, 2.5))
    np.testing.assert_allclose(normals, np.tile([0.0, 0.0, -1.0], (48, 1)), atol=1e-12)


def test_a_16_bit_png_holds_millimetres_and_a_scene_file_takes_it(tmp_path: Path) -> None:
    from PIL import Image

    depth = np.full((H, W), 1500, np.uint16)  # a wall 1.5 m in front of the camera
    depth[5:9, 10:20] = 0
    Image.fromarray(depth).save(tmp_path / "wall.png")
    points, normals = read_depth_cloud(tmp_path / "wall.png", INTR, [0, 0, 0, 0, 0, 0, 1])
    assert len(points) == H * W - 40
    np.testing.assert_allclose(points[:, 2], 1.5, atol=1e-12)  # default 0.001 m per unit
    np.testing.assert_allclose(normals, np.tile([0.0, 0.0, -1.0], (len(points), 1)), atol=1e-12)
    np.save(tmp_path / "wall.npy", depth.astype(np.float32) / 1000)  # a float image: metres
    np.testing.assert_allclose(read_depth_cloud(tmp_path / "wall.npy", INTR)[0], points, atol=1e-6)
    # the camera at (0, 0, 2) looking down the world's -z; strided
    doc = {
        "format": "pointplan-scene",
        "version": 1,
        "dim": 3,
        "bounds": {"low": [-2, -2, 0], "high": [2, 2, 3]},
        "obstacles": [
            {
                "type": "points",
                "depth": "wall.png",
                "intrinsics": dict(zip(("fx", "fy", "cx", "cy"), INTR)),
                "camera_pose": {"position": [0.0, 0.0, 2.0], "quaternion": [1.0, 0.0, 0.0, 0.0]},
                "stride": 2,
            }
        ],
    }
    (tmp_path / "s.json").write_text(json.dumps(doc))
    cloud = load_scene(tmp_path / "s.json").scene.obstacles[0]
    np.testing.assert_allclose(cloud.points[:, 2], 0.5, atol=1e-12)
    np.testing.assert_allclose(cloud.normals, np.tile([0.0, 0.0, 1.0], (len(cloud.points), 1)), atol=1e-12)
    doc["obstacles"][0]["k"] = 8
    (tmp_path / "s.json").write_text(json.dumps(doc))
    with pytest.raises(SceneFormatError, match=r"obstacles\[0\]\.k: only for a point file"):
        load_scene(tmp_path / "s.json")


def test_the_default_workspace_holds_the_cloud_and_the_camera(tmp_path: Path) -> None:
    depth, _ = ray_cast(CAMERA, ROT, True)
    np.save(tmp_path / "d.npy", depth)
    scene = load_depth_scene(tmp_path / "d.npy", INTR, POSE7)
    assert scene.dim == 3 and np.all(scene.low < CAMERA) and np.all(scene.high > CAMERA)
    cloud = scene.obstacles[0]
    assert np.all(cloud.points >= scene.low) and np.all(cloud.points <= scene.high)


@pytest.mark.parametrize(
    ("bad", "message"),
    [
        ({"intrinsics": (60.0, 58.0, 31.5)}, "intrinsics: expected 4 finite numbers"),
        ({"intrinsics": (0.0, 58.0, 31.5, 23.5)}, "fx, fy > 0"),
        ({"pose": [0.0, 0.0, 1.0]}, "expected 7 finite numbers"),
        ({"pose": [0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0]}, "quaternion qx, qy, qz, qw is zero"),
        ({"pose": np.diag([1.0, 1.0, 2.0, 1.0])}, "rigid transform"),
        ({"depth_scale": -1.0}, "expected a positive number"),
    ],
)
def test_bad_cameras_are_refused(bad: dict[str, object], message: str) -> None:
    kwargs: dict[str, object] = {"intrinsics": INTR, "pose": None, "depth_scale": 1.0, **bad}
    with pytest.raises(CloudError, match=message):
        depth_to_cloud(np.ones((4, 4)), **kwargs)  # type: ignore[arg-type]


# ---------------------------------------------------------------------------- the command line
def test_plan_on_a_depth_image(tmp_path: Path) -> None:
    depth, _ = ray_cast(CAMERA, ROT, True)
    np.save(tmp_path / "d.npy", depth)
    pose = ",".join(repr(float(x)) for x in POSE7)
    args = ["plan", "--depth", str(tmp_path / "d.npy"), "--intrinsics", ",".join(map(str, INTR))]
    args += [f"--camera-pose={pose}", "--start=-0.6,-0.6,0.3", "--goal=0.7,0.6,0.3", "--json", str(tmp_path / "r.json")]
    assert main([*args, "--quiet"]) == 0
    out = json.loads((tmp_path / "r.json").read_text())
    assert out["metrics"]["success_rate"] == 1.0
    path = np.array(out["problems"][0]["path"])
    # around the box, not through it
    along = np.concatenate([a + np.linspace(0, 1, 50)[:, None] * (b - a) for a, b in zip(path[:-1], path[1:])])
    assert len(path) >= 3 and not np.all(np.abs(along - BOX_CENTER) < BOX_HALF, axis=1).any()


def test_the_help_gives_the_camera_convention(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["plan", "-h"])
    text = " ".join(capsys.readouterr().out.split())
    assert "--depth" in text and "--intrinsics" in text and "--depth-scale" in text
    assert "looks along its +z with x to the right and y down" in text and "OpenCV" in text


@pytest.fixture
def depth_file(tmp_path: Path) -> Path:
    np.save(tmp_path / "d.npy", np.full((8, 8), 1.0))
    return tmp_path / "d.npy"


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--intrinsics", "60,58,31.5"], "--intrinsics: expected 4 numbers fx,fy,cx,cy, got 3"),
        (["--intrinsics", "60,0,31.5,23.5"], "--intrinsics: fx and fy must be positive"),
        (["--intrinsics", "60,a,31.5,23.5"], "--intrinsics: expected numbers separated by commas"),
        ([], "--depth needs --intrinsics fx,fy,cx,cy"),
        (["--intrinsics", "6,6,4,4", "--camera-pose", "0,0,1,0,0,0"], "--camera-pose: expected 7 numbers"),
        (["--intrinsics", "6,6,4,4", "--camera-pose", "0,0,1,0,0,0,0"], "--camera-pose: the quaternion"),
        (["--intrinsics", "6,6,4,4", "--depth-scale", "0"], "--depth-scale: expected a positive number"),
        (["--intrinsics", "6,6,4,4", "--robot", "disc2d"], "a depth image is 3D but robot disc2d is 2D"),
        (["--intrinsics", "6,6,4,4", "--bounds", "0,0,1,1"], "--bounds: a depth image is 3D, got 4 numbers"),
        (["--intrinsics", "6,6,4,4", "--points", "x.npy"], "give one of --scene, --points and --depth"),
    ],
)
def test_bad_depth_options_are_refused_in_one_line(
    depth_file: Path, extra: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["plan", "--depth", str(depth_file), *extra, "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("pointplan: error: ") and message in err[0], err


@pytest.mark.parametrize(
    ("name", "content", "message"),
    [
        ("garbage.png", b"not an image at all", "cannot read depth image 'garbage.png'"),
        ("missing.npy", None, "file not found"),
        ("zeros.npy", np.zeros((6, 9)), "holds no valid pixel"),
        ("nan.npy", np.full((6, 9), np.nan), "holds no valid pixel"),
        ("rgb.npy", np.ones((6, 9, 3)), "expected one channel of numbers (H, W)"),
        ("depth.jpg", b"\xff\xd8", "unsupported depth image type '.jpg'"),
    ],
)
def test_bad_depth_files_are_refused_in_one_line(
    tmp_path: Path, name: str, content: bytes | np.ndarray | None, message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / name
    if isinstance(content, bytes):
        path.write_bytes(content)
    elif content is not None:
        np.save(path, content)
    assert main(["plan", "--depth", str(path), "--intrinsics", "6,6,4,4", "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("pointplan: error: ") and message in err[0], err


def test_depth_options_need_depth(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["plan", "--intrinsics", "6,6,4,4", "--quiet"]) == 2
    assert "pointplan: error: --intrinsics goes with --depth" in capsys.readouterr().err
