"""The scene file format: round trips, the example file, and clear errors on bad input."""

from __future__ import annotations

import copy
import json
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

from pointplan.geometry import lie
from pointplan.geometry.shapes import Box, Capsule, Cylinder, Mesh, PointCloud, Sphere
from pointplan.robots import make_robot
from pointplan.scenes import Problem, Scene
from pointplan.scenes.io import SceneFile, SceneFormatError, load_scene, save_scene

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "scenes" / "narrow_example.json"
DOCS = ROOT / "docs" / "guide" / "scene-files.md"


# ============================================================================ fixtures
def base_2d() -> dict[str, Any]:
    return {
        "format": "pointplan-scene",
        "version": 1,
        "dim": 2,
        "bounds": {"low": [0, 0], "high": [1, 1]},
        "robot": "disc2d",
        "obstacles": [
            {"type": "box", "center": [0.5, 0.5], "size": [0.2, 0.1], "angle": 0.3},
            {"type": "sphere", "center": [0.2, 0.8], "radius": 0.05},
            {"type": "capsule", "a": [0.1, 0.1], "b": [0.3, 0.2], "radius": 0.02},
            {"type": "points", "path": "wall2d.npy"},
        ],
        "problems": [{"start": [0.05, 0.05], "goal": [0.95, 0.95]}, {"start": [0.9, 0.1], "goal": [0.1, 0.9]}],
    }


def base_3d() -> dict[str, Any]:
    return {
        "format": "pointplan-scene",
        "version": 1,
        "dim": 3,
        "bounds": {"low": [-1, -1, 0], "high": [1, 1, 2]},
        "robot": "sshape",
        "obstacles": [
            {"type": "box", "center": [0, 0, 0.5], "size": [0.4, 0.2, 1.0], "quaternion": [0, 0, 0.3826834, 0.9238795]},
            {"type": "sphere", "center": [0.5, 0.5, 1.0], "radius": 0.1},
            {"type": "capsule", "a": [-0.5, 0.5, 0.2], "b": [-0.5, 0.5, 1.2], "radius": 0.05},
            {
                "type": "cylinder",
                "center": [0.5, -0.5, 1],
                "radius": 0.1,
                "length": 0.6,
                "quaternion": [0.7071068, 0, 0, 0.7071068],
            },
            {
                "type": "mesh",
                "path": "meshes/block.obj",
                "scale": 0.5,
                "position": [-0.5, -0.5, 1.0],
                "quaternion": [0, 0, 0, 1],
            },
            {"type": "points", "path": "rock.xyz"},
        ],
        "problems": [{"start": [0.6, 0.0, 0.3, 0, 0, 0, 1], "goal": [-0.6, 0.0, 1.7, 0, 0, 0.7071068, 0.7071068]}],
    }


def write_assets(d: Path) -> None:
    """The mesh and point files the base documents refer to."""
    (d / "meshes").mkdir(exist_ok=True)
    trimesh.creation.box(extents=[0.4, 0.4, 0.4]).export(d / "meshes" / "block.obj")
    rng = np.random.default_rng(0)
    p2 = np.c_[rng.uniform(0.6, 0.7, (20, 2)), np.tile([1.0, 0.0], (20, 1))]
    np.save(d / "wall2d.npy", p2)
    p3 = np.c_[rng.uniform(-0.2, 0.2, (30, 3)) + [0.5, 0, 1.5], np.tile([0.0, 0.0, 1.0], (30, 1))]
    np.savetxt(d / "rock.xyz", p3)


def write(d: Path, doc: Any, name: str = "scene.json") -> Path:
    path = d / name
    path.write_text(json.dumps(doc, indent=2))
    return path


@pytest.fixture
def assets(tmp_path: Path) -> Path:
    write_assets(tmp_path)
    return tmp_path


# ============================================================================ loading
def test_base_documents_load(assets: Path) -> None:
    f2 = load_scene(write(assets, base_2d(), "two.json"))
    assert isinstance(f2, SceneFile)
    assert f2.robot == "disc2d" and f2.scene.dim == 2 and len(f2.problems) == 2
    assert [type(s) for s in f2.scene.obstacles] == [Box, Sphere, Capsule, PointCloud]
    box = f2.scene.obstacles[0]
    np.testing.assert_allclose(box.rotation, lie.so2_exp(0.3))
    np.testing.assert_allclose(box.size, [0.2, 0.1])
    assert f2.scene.name == "two"
    assert f2.problems[0].scene is f2.scene
    np.testing.assert_allclose(f2.problems[1].goal, [0.1, 0.9])

    f3 = load_scene(write(assets, base_3d(), "three.json"))
    assert f3.robot == "sshape" and f3.scene.dim == 3
    assert [type(s) for s in f3.scene.obstacles] == [Box, Sphere, Capsule, Cylinder, Mesh, PointCloud]
    np.testing.assert_allclose(f3.scene.obstacles[0].rotation, lie.so3_exp([0, 0, np.pi / 4]), atol=1e-6)
    cyl = f3.scene.obstacles[3]
    np.testing.assert_allclose(cyl.rotation[:, 2], [0, -1, 0], atol=1e-6)  # local z turned onto -y
    mesh = f3.scene.obstacles[4]
    np.testing.assert_allclose(mesh.vertices.min(0), [-0.6, -0.6, 0.9])  # 0.4 cube, scaled by 0.5
    np.testing.assert_allclose(mesh.vertices.max(0), [-0.4, -0.4, 1.1])
    assert mesh.source == assets / "meshes" / "block.obj"
    cloud = f3.scene.obstacles[5]
    assert cloud.points.shape == (30, 3)
    q = f3.problems[0].goal
    assert q.shape == (7,)
    np.testing.assert_allclose(np.linalg.norm(q[3:]), 1.0)
    # the robot the file names can be built and checked against the scene
    robot = make_robot(f3.robot)
    assert not robot.collides(f3.scene.world, f3.problems[0].start)


def test_mesh_pose_is_applied(assets: Path) -> None:
    doc = base_3d()
    rot = lie.so3_exp([0.3, -0.2, 1.0])
    doc["obstacles"] = [
        {
            "type": "mesh",
            "path": "meshes/block.obj",
            "scale": [1, 2, 3],
            "position": [0.1, 0.2, 0.3],
            "quaternion": lie.matrix_to_quat(rot).tolist(),
        }
    ]
    mesh = load_scene(write(assets, doc)).scene.obstacles[0]
    raw = trimesh.load(assets / "meshes" / "block.obj", force="mesh", process=False)
    np.testing.assert_allclose(mesh.vertices, (raw.vertices * [1, 2, 3]) @ rot.T + [0.1, 0.2, 0.3], atol=1e-12)
    np.testing.assert_array_equal(mesh.faces, raw.faces)


@pytest.mark.parametrize("suffix,sep", [(".xyz", " "), (".txt", "\t"), (".csv", ",")])
def test_points_text_files(tmp_path: Path, suffix: str, sep: str) -> None:
    data = np.array([[0.1, 0.2, 1.0, 0.0], [0.3, 0.4, 0.0, 2.0]])
    (tmp_path / f"p{suffix}").write_text(
        "# x y nx ny\n" + "\n".join(sep.join(repr(float(x)) for x in row) for row in data) + "\n"
    )
    doc = base_2d()
    doc["obstacles"] = [{"type": "points", "path": f"p{suffix}"}]
    cloud = load_scene(write(tmp_path, doc)).scene.obstacles[0]
    np.testing.assert_array_equal(cloud.points, data[:, :2])
    np.testing.assert_allclose(cloud.normals, [[1, 0], [0, 1]])  # normalised


def test_paths_are_relative_to_the_json_file(
    assets: Path, tmp_path_factory: pytest.TempPathFactory, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = write(assets, base_3d())
    monkeypatch.chdir(tmp_path_factory.mktemp("elsewhere"))
    assert len(load_scene(path).scene.obstacles) == 6


def test_optional_fields(tmp_path: Path) -> None:
    doc = {
        "format": "pointplan-scene",
        "version": 1,
        "dim": 3,
        "bounds": {"low": [0, 0, 0], "high": [1, 1, 1]},
        "obstacles": [],
    }
    f = load_scene(write(tmp_path, doc))
    assert f.robot is None and f.problems == [] and f.scene.obstacles == []
    # without a robot, 3D problems may hold positions (3) or poses (7), one kind per file
    doc["problems"] = [{"start": [0.1, 0.1, 0.1], "goal": [0.9, 0.9, 0.9]}]
    assert load_scene(write(tmp_path, doc)).problems[0].start.shape == (3,)
    doc["problems"] = [{"start": [0.1, 0.1, 0.1, 0, 0, 0, 2], "goal": [0.9, 0.9, 0.9, 0, 0, 0, 1], "tag": "t"}]
    p = load_scene(write(tmp_path, doc)).problems[0]
    np.testing.assert_allclose(p.start, [0.1, 0.1, 0.1, 0, 0, 0, 1])
    assert p.tag == "t"


def test_example_file_loads() -> None:
    f = load_scene(EXAMPLE)
    assert f.robot == "disc2d"
    assert f.scene.dim == 2 and len(f.scene.obstacles) == 5
    assert all(isinstance(s, Box) for s in f.scene.obstacles)
    assert len(f.problems) == 2
    robot = make_robot(f.robot)
    for p in f.problems:
        assert p.start.shape == p.goal.shape == (2,)
        assert not robot.collides(f.scene.world, np.stack([p.start, p.goal])).any()


def _json_blocks(text: str) -> list[dict[str, Any]]:
    return [json.loads(b) for b in re.findall(r"```json\n(.*?)```", text, flags=re.DOTALL)]


def test_documented_examples_load(tmp_path: Path) -> None:
    """Every complete scene example in docs/guide/scene-files.md is a valid file."""
    docs = [d for d in _json_blocks(DOCS.read_text()) if isinstance(d, dict) and d.get("format") == "pointplan-scene"]
    assert {d["dim"] for d in docs} == {2, 3}
    for i, doc in enumerate(docs):
        d = tmp_path / f"doc{i}"
        d.mkdir()
        for ob in doc["obstacles"]:  # create the files the example refers to
            if ob["type"] == "mesh":
                (d / ob["path"]).parent.mkdir(parents=True, exist_ok=True)
                trimesh.creation.box(extents=[0.2, 0.2, 0.2]).export(d / ob["path"])
            elif ob["type"] == "points":
                (d / ob["path"]).parent.mkdir(parents=True, exist_ok=True)
                dim = doc["dim"]
                np.save(d / ob["path"], np.c_[np.full((4, dim), 0.5), np.eye(dim)[np.zeros(4, int)]])
        f = load_scene(write(d, doc))
        assert len(f.scene.obstacles) == len(doc["obstacles"])
        assert len(f.problems) == len(doc.get("problems", []))


# ============================================================================ round trips
def assert_same_scene(a: Scene, b: Scene) -> None:
    assert a.dim == b.dim
    np.testing.assert_array_equal(a.low, b.low)
    np.testing.assert_array_equal(a.high, b.high)
    assert len(a.obstacles) == len(b.obstacles)
    for s, t in zip(a.obstacles, b.obstacles):
        assert type(s) is type(t)
        for name in ("center", "size", "radius", "a", "b", "length", "points", "normals", "vertices", "faces"):
            if hasattr(s, name):
                if getattr(s, name) is None or getattr(t, name) is None:  # a point cloud's automatic radius
                    assert getattr(s, name) is getattr(t, name), name
                    continue
                np.testing.assert_allclose(getattr(t, name), getattr(s, name), rtol=0, atol=1e-12, err_msg=name)
        if hasattr(s, "rotation"):
            np.testing.assert_allclose(t.rotation, s.rotation, atol=1e-12)


def assert_same_problems(a: list[Problem], b: list[Problem]) -> None:
    assert len(a) == len(b)
    for p, q in zip(a, b):
        np.testing.assert_allclose(q.start, p.start, atol=1e-12)
        np.testing.assert_allclose(q.goal, p.goal, atol=1e-12)
        assert q.tag == p.tag


@pytest.mark.parametrize("make", [base_2d, base_3d])
def test_round_trip_of_loaded_file(assets: Path, make: Callable[[], dict[str, Any]]) -> None:
    first = load_scene(write(assets, make()))
    out = assets / "out" / "copy.json"
    out.parent.mkdir()
    save_scene(out, first.scene, first.problems, robot=first.robot)
    second = load_scene(out)
    assert second.robot == first.robot
    assert second.scene.name == first.scene.name
    assert_same_scene(first.scene, second.scene)
    assert_same_problems(first.problems, second.problems)
    # saving again writes the same text: the format is stable
    again = assets / "out" / "again.json"
    save_scene(again, second.scene, second.problems, robot=make_robot(second.robot))
    assert again.read_text() == out.read_text().replace("copy.", "again.")
    # and the collision answers agree
    rng = np.random.default_rng(1)
    d = first.scene.dim
    c = rng.uniform(first.scene.low, first.scene.high, (300, d))
    np.testing.assert_array_equal(
        first.scene.world.spheres_collide(c, 0.05), second.scene.world.spheres_collide(c, 0.05)
    )


def test_round_trip_of_built_scene(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    m = trimesh.creation.icosphere(1, radius=0.2)
    scene = Scene(
        obstacles=[
            Box([0.2, 0.3, 0.4], [0.1, 0.2, 0.3], lie.random_rotations(rng, 1)[0]),
            Box([0.7, 0.7, 0.7], [0.1, 0.1, 0.1]),
            Sphere([0.5, 0.5, 0.5], 0.1),
            Capsule([0.1, 0.1, 0.1], [0.1, 0.1, 0.1], 0.05),
            Cylinder([0.3, 0.7, 0.2], 0.05, 0.3, lie.random_rotations(rng, 1)[0]),
            Mesh(m.vertices + 0.5, m.faces),
            PointCloud(rng.uniform(0, 1, (10, 3)), rng.normal(size=(10, 3))),
        ],
        low=[0, 0, 0],
        high=[1, 1, 1],
    )
    robot = make_robot("sshape")
    q = robot.sample_uniform(rng, 4, scene.low, scene.high)
    problems = [Problem(scene, q[0], q[1]), Problem(scene, q[2], q[3], tag="second")]
    path = tmp_path / "built.json"
    save_scene(path, scene, problems, robot="sshape")
    f = load_scene(path)
    assert_same_scene(scene, f.scene)
    np.testing.assert_allclose(f.problems[0].start, q[0], atol=1e-12)
    assert f.problems[0].tag == "built/0" and f.problems[1].tag == "second"
    assert (tmp_path / "built.mesh5.obj").is_file() and (tmp_path / "built.points6.npy").is_file()
    assert f.scene.obstacles[5].source == tmp_path / "built.mesh5.obj"


@given(
    st.lists(
        st.tuples(
            st.lists(st.floats(0.05, 0.95), min_size=2, max_size=2),
            st.lists(st.floats(1e-3, 0.5), min_size=2, max_size=2),
            st.floats(-np.pi, np.pi),
        ),
        max_size=6,
    )
)
@settings(max_examples=30, deadline=None)
def test_round_trip_random_2d_boxes(tmp_path_factory: pytest.TempPathFactory, boxes: list) -> None:
    scene = Scene([Box(c, s, lie.so2_exp(a)) for c, s, a in boxes], low=[0, 0], high=[1, 1], name="r")
    path = tmp_path_factory.mktemp("rt") / "r.json"
    save_scene(path, scene)
    f = load_scene(path)
    assert f.robot is None and f.problems == []
    assert_same_scene(scene, f.scene)


def test_save_rejects_what_load_would_reject(tmp_path: Path) -> None:
    scene = Scene([Box([0.5, 0.5], [0.1, 0.1])], low=[0, 0], high=[1, 1])
    with pytest.raises(SceneFormatError, match=r"robot: unknown robot 'tank'"):
        save_scene(tmp_path / "a.json", scene, robot="tank")
    with pytest.raises(SceneFormatError, match=r"robot: sphere3d is a 3D robot but the scene is 2D"):
        save_scene(tmp_path / "a.json", scene, robot="sphere3d")
    with pytest.raises(SceneFormatError, match=r"problems\[0\]\.goal: position \[1\.5, 0\.5\] lies outside the bounds"):
        save_scene(tmp_path / "a.json", scene, [Problem(scene, [0.1, 0.1], [1.5, 0.5])], robot="disc2d")
    with pytest.raises(SceneFormatError, match=r"problems\[0\]\.start: expected 2 numbers"):
        save_scene(tmp_path / "a.json", scene, [Problem(scene, [0.1, 0.1, 0.1], [0.5, 0.5, 0.5])], robot="disc2d")
    with pytest.raises(SceneFormatError, match=r"obstacles\[1\]: Sphere is 3D in a 2D scene"):
        save_scene(tmp_path / "a.json", Scene([scene.obstacles[0], Sphere([0, 0, 0], 1.0)], [0, 0], [1, 1]))
    with pytest.raises(SceneFormatError, match=r"obstacles\[0\]\.size: expected 2 positive numbers"):
        save_scene(tmp_path / "a.json", Scene([Box([0.5, 0.5], [0.1, 0.0])], [0, 0], [1, 1]))
    assert not (tmp_path / "a.json").exists()


# ============================================================================ errors
def set_in(doc: dict[str, Any], path: str, value: Any) -> None:
    """Set ``doc[path]`` for a path such as ``obstacles[0].size``; ``value=DELETE`` removes."""
    keys = [int(k) if k.isdigit() else k for k in re.findall(r"[^.\[\]]+", path)]
    target = doc
    for k in keys[:-1]:
        target = target[k]
    if value is DELETE:
        del target[keys[-1]]
    else:
        target[keys[-1]] = value


DELETE = object()

# (base, field path to change, new value, field named in the error, message pattern)
CASES_2D = [
    ("format", DELETE, "format", "missing required field"),
    ("format", "pointplan-scenes", "format", "expected 'pointplan-scene', got \"pointplan-scenes\""),
    ("version", DELETE, "version", "missing required field"),
    ("version", 2, "version", "unsupported version 2; this pointplan reads version 1"),
    ("version", "1", "version", 'expected an integer, got "1"'),
    ("version", True, "version", "expected an integer, got true"),
    ("dim", DELETE, "dim", "missing required field"),
    ("dim", 4, "dim", "expected 2 or 3, got 4"),
    ("dim", "2", "dim", "expected 2 or 3"),
    ("bounds", DELETE, "bounds", "missing required field"),
    ("bounds", [0, 1], "bounds", "expected an object, got a list"),
    ("bounds.low", DELETE, "bounds.low", "missing required field"),
    ("bounds.low", [0, 0, 0], "bounds.low", r"expected 2 numbers, got \[0, 0, 0\]"),
    ("bounds.high", [1, "1"], "bounds.high", "expected 2 numbers"),
    ("bounds.high", [1, 0], "bounds.high", "must exceed bounds.low in every axis"),
    ("bounds.high", [1, 10**400], "bounds.high", "expected 2 numbers"),
    ("bounds.extra", 1, "bounds.extra", "unknown field for bounds"),
    ("obstacle", [], "obstacle", "unknown field for a scene file"),
    ("robot", "tank", "robot", 'unknown robot "tank"; known: disc2d, sphere3d, sshape, sshape-oriented'),
    ("robot", 7, "robot", "unknown robot 7"),
    ("robot", "sshape", "robot", "sshape is a 3D robot but the scene is 2D"),
    ("name", 5, "name", "expected a string"),
    ("obstacles", DELETE, "obstacles", "missing required field"),
    ("obstacles", {"type": "box"}, "obstacles", "expected a list, got an object"),
    ("obstacles[1]", "sphere", "obstacles[1]", "expected an object, got a string"),
    ("obstacles[1].type", DELETE, "obstacles[1].type", "missing required field"),
    ("obstacles[1].type", "cone", "obstacles[1].type", 'unknown obstacle type "cone"; known: box, sphere'),
    ("obstacles[1].type", "cylinder", "obstacles[1].type", "cylinder obstacles need a 3D scene"),
    ("obstacles[1].type", "mesh", "obstacles[1].type", "mesh obstacles need a 3D scene"),
    ("obstacles[0].size", [1, -2], "obstacles[0].size", r"expected 2 positive numbers, got \[1, -2\]"),
    ("obstacles[0].size", [0, 1], "obstacles[0].size", "expected 2 positive numbers"),
    ("obstacles[0].size", [0.1, 0.1, 0.1], "obstacles[0].size", "expected 2 positive numbers"),
    ("obstacles[0].size", DELETE, "obstacles[0].size", "missing required field"),
    ("obstacles[0].center", "middle", "obstacles[0].center", 'expected 2 numbers, got "middle"'),
    ("obstacles[0].center", [0.5, True], "obstacles[0].center", "expected 2 numbers"),
    ("obstacles[0].center", [0.5, None], "obstacles[0].center", "expected 2 numbers"),
    ("obstacles[0].center", [0.5, 0.5, 0.5], "obstacles[0].center", r"expected 2 numbers, got \[0.5, 0.5, 0.5\]"),
    ("obstacles[0].angle", "30deg", "obstacles[0].angle", "expected a finite number"),
    ("obstacles[0].quaternion", [0, 0, 0, 1], "obstacles[0].quaternion", "unknown field for a 2D box"),
    ("obstacles[1].radius", -0.1, "obstacles[1].radius", "expected a positive number, got -0.1"),
    ("obstacles[1].radius", DELETE, "obstacles[1].radius", "missing required field"),
    ("obstacles[2].b", DELETE, "obstacles[2].b", "missing required field"),
    ("obstacles[2].radius", 0, "obstacles[2].radius", "expected a positive number, got 0"),
    ("obstacles[3].path", "nowhere.npy", "obstacles[3].path", "file not found: 'nowhere.npy'"),
    ("obstacles[3].path", 3, "obstacles[3].path", "expected a file name"),
    ("obstacles[3].path", "wall2d.obj", "obstacles[3].path", "unsupported file type '.obj'"),
    (
        "obstacles[3].path",
        "wall3d.npy",
        "obstacles[3].path",
        r"'wall3d.npy' holds 3D points \(z is not 0 everywhere\) but the scene is 2D",
    ),
    (
        "obstacles[3].path",
        "wide.npy",
        "obstacles[3].path",
        r"expected an array \(P, 2\) or \(P, 3\) of points.*got shape \(5, 5\)",
    ),
    ("obstacles[3].path", "bad.csv", "obstacles[3].path", "cannot read points file 'bad.csv'"),
    ("obstacles[3].path", "nan.npy", "obstacles[3].path", "contains NaN or infinite"),
    ("problems", {}, "problems", "expected a list"),
    ("problems[0]", [0.1, 0.1], "problems[0]", "expected an object, got a list"),
    ("problems[0].goal", DELETE, "problems[0].goal", "missing required field"),
    ("problems[0].start", [0.1, 0.1, 0.1], "problems[0].start", r"expected 2 numbers, got \[0.1, 0.1, 0.1\]"),
    ("problems[1].goal", [1.5, 0.5], "problems[1].goal", r"position \[1.5, 0.5\] lies outside the bounds"),
    ("problems[1].goal", [0.5, -0.01], "problems[1].goal", "lies outside the bounds"),
    ("problems[0].via", [], "problems[0].via", "unknown field for a problem"),
    ("problems[0].tag", 1, "problems[0].tag", "expected a string"),
]

CASES_3D = [
    ("robot", "disc2d", "robot", "disc2d is a 2D robot but the scene is 3D"),
    ("obstacles[0].size", [1, -2], "obstacles[0].size", r"expected 3 positive numbers, got \[1, -2\]"),
    ("obstacles[0].size", [1, -2, 1], "obstacles[0].size", r"expected 3 positive numbers, got \[1, -2, 1\]"),
    ("obstacles[0].center", [0, 0], "obstacles[0].center", "expected 3 numbers"),
    (
        "obstacles[0].quaternion",
        [0, 0, 0, 0],
        "obstacles[0].quaternion",
        r"expected 4 numbers, not all zero, got \[0, 0, 0, 0\]",
    ),
    ("obstacles[0].quaternion", [0, 0, 1], "obstacles[0].quaternion", "expected 4 numbers"),
    ("obstacles[0].angle", 0.3, "obstacles[0].angle", "unknown field for a 3D box"),
    ("obstacles[3].length", 0, "obstacles[3].length", "expected a positive number"),
    ("obstacles[3].radius", DELETE, "obstacles[3].radius", "missing required field"),
    ("obstacles[3].axis", [0, 0, 1], "obstacles[3].axis", "unknown field for a cylinder"),
    ("obstacles[4].path", DELETE, "obstacles[4].path", "missing required field"),
    ("obstacles[4].path", "meshes/missing.stl", "obstacles[4].path", "file not found: 'meshes/missing.stl'"),
    ("obstacles[4].path", "garbage.stl", "obstacles[4].path", "(cannot load mesh|contains no triangles)"),
    ("obstacles[4].path", "rock.xyz", "obstacles[4].path", "(cannot load mesh|contains no triangles)"),
    ("obstacles[4].scale", -1, "obstacles[4].scale", "expected a positive number, got -1"),
    ("obstacles[4].scale", [1, 1], "obstacles[4].scale", "expected 3 positive numbers"),
    ("obstacles[4].position", [0, 0], "obstacles[4].position", "expected 3 numbers"),
    ("obstacles[4].quaternion", "identity", "obstacles[4].quaternion", "expected 4 numbers"),
    ("obstacles[5].path", "wall2d.npy", "obstacles[5].path", r"'wall2d.npy' holds 2D points but the scene is 3D"),
    ("obstacles[5].path", "flat.npy", "obstacles[5].path", r"expected an array .*got shape \(6,\)"),
    ("problems[0].start", [0.6, 0.0, 0.3], "problems[0].start", "expected 7 numbers"),
    ("problems[0].goal", [-0.6, 0.0, 1.7, 0, 0, 0, 0], "problems[0].goal", "orientation quaternion .* is zero"),
    ("problems[0].goal", [-0.6, 0.0, 2.5, 0, 0, 0, 1], "problems[0].goal", "lies outside the bounds"),
]


def write_bad_assets(d: Path) -> None:
    np.save(d / "wall3d.npy", np.c_[np.ones((5, 3)), np.ones((5, 3))])
    np.save(d / "wide.npy", np.zeros((5, 5)))
    np.save(d / "flat.npy", np.zeros(6))
    np.save(d / "nan.npy", np.full((3, 4), np.nan))
    (d / "bad.csv").write_text("0.1,0.2,zero,1\n")
    (d / "garbage.stl").write_text("this is not a mesh\n")


@pytest.mark.parametrize(
    "base,where,value,field,message",
    [("2d", *c) for c in CASES_2D] + [("3d", *c) for c in CASES_3D],
    ids=[f"2d-{c[0]}={c[1] if c[1] is not DELETE else 'DELETE'}" for c in CASES_2D]
    + [f"3d-{c[0]}={c[1] if c[1] is not DELETE else 'DELETE'}" for c in CASES_3D],
)
def test_malformed_field(assets: Path, base: str, where: str, value: Any, field: str, message: str) -> None:
    write_bad_assets(assets)
    doc = copy.deepcopy(base_2d() if base == "2d" else base_3d())
    set_in(doc, where, value)
    path = write(assets, doc)
    with pytest.raises(SceneFormatError) as info:
        load_scene(path)
    err = info.value
    assert isinstance(err, ValueError)
    assert err.file == str(path) and err.field == field
    assert str(err).startswith(f"{path}: {field}: "), str(err)
    assert re.search(message, str(err)), str(err)


def test_the_documented_example_message(tmp_path: Path) -> None:
    doc = base_3d()
    doc["obstacles"] = doc["obstacles"][:2] + [{"type": "box", "center": [0, 0, 0], "size": [1, -2]}]
    (tmp_path / "scene.json").write_text(json.dumps(doc))
    with pytest.raises(SceneFormatError) as info:
        load_scene(tmp_path / "scene.json")
    assert str(info.value).endswith("scene.json: obstacles[2].size: expected 3 positive numbers, got [1, -2]")


@pytest.mark.parametrize(
    "text,message",
    [
        ('{"format": "pointplan-scene",\n "version": 1,\n "dim": 2,,\n}', r"invalid JSON at line 3, column 11"),
        ('{"format": "pointplan-scene"', r"invalid JSON at line 1"),
        ("", r"invalid JSON at line 1, column 1"),
        ("[1, 2]", r"\(top level\): expected an object, got a list"),
        ("null", r"\(top level\): expected an object, got null"),
        (
            '{"format": "pointplan-scene", "version": 1, "dim": 2, "bounds": {"low": [0, NaN], "high": [1, 1]}, "obstacles": []}',
            r"bounds\.low: expected 2 numbers, got \[0, NaN\]",
        ),
        (
            '{"format": "pointplan-scene", "version": 1, "dim": 2, "bounds": {"low": [0, 0], "high": [1, Infinity]}, "obstacles": []}',
            r"bounds\.high: expected 2 numbers",
        ),
    ],
)
def test_malformed_text(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "scene.json"
    path.write_text(text)
    with pytest.raises(SceneFormatError) as info:
        load_scene(path)
    assert str(info.value).startswith(f"{path}: ")
    assert re.search(message, str(info.value)), str(info.value)


def test_unreadable_files(tmp_path: Path) -> None:
    with pytest.raises(SceneFormatError, match=r"missing\.json: cannot read file"):
        load_scene(tmp_path / "missing.json")
    with pytest.raises(SceneFormatError, match=r"cannot read file"):
        load_scene(tmp_path)  # a directory
    (tmp_path / "latin1.json").write_bytes(b'{"name": "caf\xe9"}')
    with pytest.raises(SceneFormatError, match=r"latin1\.json: not UTF-8 text"):
        load_scene(tmp_path / "latin1.json")
