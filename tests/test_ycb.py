"""YCB object meshes: the folder-layout loader, the default set, loading and placing."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest
import trimesh

from pointplan.geometry.collision import mesh_contains
from pointplan.geometry.shapes import Mesh
from pointplan.scenes import ycb

pytestmark = pytest.mark.slow  # YCB meshes are loaded and repaired


def _write(path: Path, mesh) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    mesh.export(path)
    return path


def _closed(mesh: Mesh):
    return trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)


# ----------------------------------------------------------------------------- default set


def test_default_set_loads_closed_small_and_sized():
    try:
        objects = ycb.default_ycb_objects()
    except FileNotFoundError as exc:  # no bundled source installed on this machine
        pytest.skip(str(exc))
    assert len(objects) >= 5
    assert set(objects) <= set(ycb.DEFAULT_YCB_OBJECTS)
    for name, path in objects.items():
        mesh = ycb.load_object_mesh(path, max_faces=800)
        tm = _closed(mesh)
        assert len(mesh.faces) <= 800, name
        assert tm.is_watertight and tm.is_volume, name
        extent = np.ptp(mesh.vertices, axis=0).max()
        assert 0.02 <= extent <= 0.40, (name, extent)
        np.testing.assert_allclose(tm.bounds.mean(axis=0), 0.0, atol=1e-9)


def test_default_set_error_names_the_places_looked_at(monkeypatch, tmp_path):
    monkeypatch.setattr(ycb, "_bundled_sources", lambda: [("nowhere", tmp_path / "none", ".obj")])
    with pytest.raises(FileNotFoundError, match="find_ycb_objects") as info:
        ycb.default_ycb_objects()
    assert str(tmp_path / "none") in str(info.value)


def test_default_set_takes_the_curated_objects_of_a_source(monkeypatch, tmp_path):
    box = trimesh.creation.box((0.1, 0.05, 0.2))
    _write(tmp_path / "003_cracker_box.obj", box)
    _write(tmp_path / "035_power_drill.obj", box)
    _write(tmp_path / "999_not_curated.obj", box)
    monkeypatch.setattr(
        ycb, "_bundled_sources", lambda: [("empty", tmp_path / "none", ".obj"), ("here", tmp_path, ".obj")]
    )
    assert ycb.default_ycb_objects() == {
        "003_cracker_box": tmp_path / "003_cracker_box.obj",
        "035_power_drill": tmp_path / "035_power_drill.obj",
    }


# ----------------------------------------------------------------------------- YCB layout


def test_find_ycb_objects_reads_the_dataset_layout(tmp_path):
    big, small = trimesh.creation.box((0.2, 0.2, 0.2)), trimesh.creation.box((0.05, 0.05, 0.05))
    a = _write(tmp_path / "003_cracker_box" / "google_16k" / "textured.obj", big)
    _write(tmp_path / "003_cracker_box" / "poisson" / "textured.ply", small)
    _write(tmp_path / "003_cracker_box" / "tsdf" / "textured.obj", small)
    b = _write(tmp_path / "011_banana" / "poisson" / "textured.ply", big)
    _write(tmp_path / "011_banana" / "tsdf" / "textured.obj", small)
    c = _write(tmp_path / "025_mug" / "tsdf" / "textured.obj", small)
    (tmp_path / "030_fork" / "clouds").mkdir(parents=True)  # no mesh: skipped
    (tmp_path / "notes.txt").write_text("not an object")

    found = ycb.find_ycb_objects(tmp_path)
    assert found == {"003_cracker_box": a, "011_banana": b, "025_mug": c}
    # the google_16k mesh (the big box) is the one loaded, not the poisson or tsdf ones
    assert np.ptp(ycb.load_object_mesh(found["003_cracker_box"]).vertices, axis=0).max() == pytest.approx(0.2)


def test_find_ycb_objects_empty_folder_names_the_folder(tmp_path):
    (tmp_path / "003_cracker_box").mkdir()
    with pytest.raises(FileNotFoundError) as info:
        ycb.find_ycb_objects(tmp_path)
    assert str(tmp_path) in str(info.value) and "google_16k/textured.obj" in str(info.value)
    with pytest.raises(FileNotFoundError, match="does not exist"):
        ycb.find_ycb_objects(tmp_path / "missing")
    with pytest.raises(ValueError, match="not a directory"):
        ycb.find_ycb_objects(_write(tmp_path / "box.obj", trimesh.creation.box()))


# ----------------------------------------------------------------------------- loading


def test_load_object_mesh_decimates_closes_and_centres(tmp_path):
    # a torus (R 5 cm, r 2 cm) off the origin: decimation must keep the hole, which a convex
    # hull would fill
    torus = trimesh.creation.torus(0.05, 0.02, major_sections=64, minor_sections=32)  # 4096 faces
    torus.apply_translation([0.3, -0.2, 0.1])
    mesh = ycb.load_object_mesh(_write(tmp_path / "torus.obj", torus), max_faces=300)
    tm = _closed(mesh)
    assert 200 <= len(mesh.faces) <= 300
    assert tm.is_watertight and tm.is_volume
    np.testing.assert_allclose(tm.bounds.mean(axis=0), 0.0, atol=1e-9)
    np.testing.assert_allclose(tm.extents, [0.14, 0.14, 0.04], rtol=0.05)
    assert tm.volume == pytest.approx(2 * np.pi**2 * 0.05 * 0.02**2, rel=0.1)
    # the collision module sees a solid ring: inside the tube, not in the hole nor outside
    points = np.array([[0.05, 0.0, 0.0], [0.0, -0.05, 0.0], [0.0, 0.0, 0.0], [0.08, 0.0, 0.0]])
    assert mesh_contains(mesh, points).tolist() == [True, True, False, False]


def test_load_object_mesh_repairs_holes_and_merges_split_vertices(tmp_path):
    torus = trimesh.creation.torus(0.05, 0.02)  # 2048 faces, within the budget below
    volume = torus.volume
    # three scattered faces missing (scan holes): filled, not replaced by the convex hull
    holes = trimesh.Trimesh(torus.vertices, np.delete(torus.faces, [0, 700, 1400], axis=0), process=False)
    assert not holes.is_watertight
    tm = _closed(ycb.load_object_mesh(_write(tmp_path / "holes.obj", holes), max_faces=4096))
    assert tm.is_watertight and len(tm.faces) == len(torus.faces)
    assert tm.volume == pytest.approx(volume, rel=0.01)
    # every face with its own three vertices (like texture seams): merged back into a closed mesh
    soup = trimesh.Trimesh(
        torus.vertices[torus.faces].reshape(-1, 3), np.arange(3 * len(torus.faces)).reshape(-1, 3), process=False
    )
    assert not soup.is_watertight
    tm = _closed(ycb.load_object_mesh(_write(tmp_path / "soup.ply", soup), max_faces=4096))
    assert tm.is_watertight and len(tm.faces) == len(torus.faces)
    assert tm.volume == pytest.approx(volume, rel=0.01)


def test_load_object_mesh_takes_millimetres_to_metres(tmp_path):
    mesh = ycb.load_object_mesh(_write(tmp_path / "box_mm.stl", trimesh.creation.box((100.0, 50.0, 200.0))))
    np.testing.assert_allclose(np.ptp(mesh.vertices, axis=0), [0.1, 0.05, 0.2])


def test_load_object_mesh_falls_back_to_a_small_hull(tmp_path):
    # two crossing boxes share faces' planes: a budget of 8 faces is too small for anything
    # but a hull, which must still be closed and within budget
    cross = trimesh.util.concatenate([trimesh.creation.box((0.3, 0.05, 0.05)), trimesh.creation.box((0.05, 0.3, 0.05))])
    mesh = ycb.load_object_mesh(_write(tmp_path / "cross.obj", cross), max_faces=8)
    tm = _closed(mesh)
    assert len(mesh.faces) <= 8 and tm.is_watertight and tm.is_volume


def test_load_object_mesh_is_cached_and_read_only(tmp_path):
    path = _write(tmp_path / "box.obj", trimesh.creation.box((0.1, 0.1, 0.1)))
    first = ycb.load_object_mesh(path)
    assert ycb.load_object_mesh(str(path)) is first
    assert ycb.load_object_mesh(path, max_faces=500) is not first
    with pytest.raises(ValueError):
        first.vertices[0, 0] = 1.0


def test_load_object_mesh_reads_mujoco_msh(tmp_path):
    box = trimesh.creation.box((0.1, 0.2, 0.3))
    v = box.vertices.astype(np.float32)
    f = box.faces.astype(np.int32)
    path = tmp_path / "002_box.msh"
    path.write_bytes(struct.pack("4i", len(v), 0, 0, len(f)) + v.tobytes() + f.tobytes())
    mesh = ycb.load_object_mesh(path)
    assert len(mesh.faces) == 12 and _closed(mesh).is_watertight
    np.testing.assert_allclose(np.ptp(mesh.vertices, axis=0), [0.1, 0.2, 0.3], rtol=1e-6)
    bad = tmp_path / "bad.msh"
    bad.write_bytes(path.read_bytes()[:-4])
    with pytest.raises(ValueError, match="not a MuJoCo .msh"):
        ycb.load_object_mesh(bad)


def test_load_object_mesh_errors(tmp_path):
    with pytest.raises(FileNotFoundError):
        ycb.load_object_mesh(tmp_path / "missing.obj")
    with pytest.raises(ValueError):
        ycb.load_object_mesh(_write(tmp_path / "box.obj", trimesh.creation.box()), max_faces=2)


# ----------------------------------------------------------------------------- placing


def test_place_mesh_moves_rotates_and_scales(tmp_path):
    mesh = ycb.load_object_mesh(_write(tmp_path / "box.obj", trimesh.creation.box((0.1, 0.2, 0.3))))
    t = np.array([0.3, -0.1, 0.25])
    moved = ycb.place_mesh(mesh, np.eye(3), t)
    np.testing.assert_allclose(moved.vertices - mesh.vertices, np.broadcast_to(t, mesh.vertices.shape))
    np.testing.assert_array_equal(moved.faces, mesh.faces)
    assert moved.source == mesh.source
    quarter_z = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    turned = ycb.place_mesh(mesh, quarter_z, t, scale=2.0)
    np.testing.assert_allclose(np.ptp(turned.vertices, axis=0), [0.4, 0.2, 0.6])
    np.testing.assert_allclose(turned.vertices.mean(axis=0), t + 2.0 * quarter_z @ mesh.vertices.mean(axis=0))
    assert mesh_contains(turned, t[None])[0] and not mesh_contains(turned, (t + [0.0, 0.15, 0.0])[None])[0]


def test_place_mesh_rejects_bad_poses(tmp_path):
    mesh = ycb.load_object_mesh(_write(tmp_path / "box.obj", trimesh.creation.box((0.1, 0.2, 0.3))))
    with pytest.raises(ValueError):
        ycb.place_mesh(mesh, np.diag([1.0, 1.0, -1.0]), np.zeros(3))  # a reflection
    with pytest.raises(ValueError):
        ycb.place_mesh(mesh, 2 * np.eye(3), np.zeros(3))
    with pytest.raises(ValueError):
        ycb.place_mesh(mesh, np.eye(3), np.zeros(2))
    with pytest.raises(ValueError):
        ycb.place_mesh(mesh, np.eye(3), np.zeros(3), scale=0.0)
