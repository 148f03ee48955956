"""The simulated depth camera (pointplan.geometry.camera): depths in closed form, hit
points against trimesh's ray caster (Embree), the round trip through depth_to_cloud."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from pointplan.geometry.camera import look_at, pixel_rays, render_depth
from pointplan.geometry.clouds import depth_to_cloud, depth_to_points
from pointplan.geometry.collision import CollisionWorld
from pointplan.geometry.shapes import Box, Sphere

K = (80.0, 80.0, 31.5, 23.5)  # fx, fy, cx, cy of a 64 x 48 image
W, H = 64, 48


def test_look_at_is_a_rigid_pose_looking_at_the_target() -> None:
    pose = look_at([1.0, -2.0, 0.5], [0.0, 0.5, 0.2])
    r = pose[:3, :3]
    assert np.allclose(r @ r.T, np.eye(3)) and np.isclose(np.linalg.det(r), 1.0)
    axis = np.array([-1.0, 2.5, -0.3]) / np.linalg.norm([-1.0, 2.5, -0.3])
    assert np.allclose(r[:, 2], axis)
    assert r[:, 1] @ [0, 0, 1] < 0  # image "down" (+y) points down in the world
    straight_down = look_at([0.0, 0.0, 2.0], [0.0, 0.0, 0.0])  # along "up": still rigid
    assert np.allclose(straight_down[:3, 2], [0, 0, -1]) and np.isclose(np.linalg.det(straight_down[:3, :3]), 1.0)
    with pytest.raises(ValueError, match="same point"):
        look_at([1, 1, 1], [1, 1, 1])


def test_a_wall_facing_the_camera_reads_its_distance_everywhere() -> None:
    """A box face square to the optical axis: every pixel that sees it reads the same depth
    (z, not the ray length), and the pixels off its edges read 0 (no return)."""
    wall = Box(np.array([1.05, 0.0, 0.0]), np.array([0.1, 0.4, 0.3]))
    world = CollisionWorld.from_shapes([wall], 3)
    pose = look_at([0.0, 0.0, 0.0], [1.0, 0.0, 0.0])
    depth = render_depth(world, K, pose, W, H)
    seen = depth > 0
    assert np.allclose(depth[seen], 1.0)
    # which pixels see the face, in closed form: |camera x| <= 0.2 and |y| <= 0.15 at z = 1
    rays = pixel_rays(K, W, H)
    expect = (np.abs(rays[..., 0]) <= 0.2) & (np.abs(rays[..., 1]) <= 0.15)
    assert np.array_equal(seen, expect)
    assert not render_depth(world, K, pose, W, H, max_range=0.9).any()


def test_depths_of_a_sphere_match_the_closed_form() -> None:
    c, r = np.array([0.1, -0.05, 1.2]), 0.3
    world = CollisionWorld.from_shapes([Sphere(c, r)], 3)
    depth = render_depth(world, K, np.eye(4), W, H)
    d = pixel_rays(K, W, H)
    u = d / np.linalg.norm(d, axis=-1, keepdims=True)
    b = u @ c
    disc = b**2 - (c @ c - r * r)
    t = np.where(disc >= 0, b - np.sqrt(np.maximum(disc, 0)), np.inf)
    z = np.where(np.isfinite(t), t * u[..., 2], 0.0)
    assert np.array_equal(depth > 0, disc >= 0)
    assert np.allclose(depth, z, atol=1e-9)


def test_hit_points_agree_with_embree_and_round_trip_through_depth_to_cloud() -> None:
    """Two turned boxes seen from an oblique camera: the back-projected pixels are the
    points where trimesh's ray caster (Embree, on the boxes' meshes) first hits, and
    depth_to_cloud gives them back with normals facing the camera."""
    rng = np.random.default_rng(0)
    boxes = []
    for centre in ([0.6, 0.1, 0.0], [0.9, -0.3, 0.2]):
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        boxes.append(Box(np.array(centre), np.array([0.3, 0.2, 0.25]), q * np.sign(np.linalg.det(q))))
    world = CollisionWorld.from_shapes(boxes, 3)
    pose = look_at([-0.4, 0.6, 0.7], [0.75, -0.1, 0.1])
    depth = render_depth(world, K, pose, W, H, max_range=5.0)
    assert 0.1 < (depth > 0).mean() < 0.95  # the image holds boxes and background
    meshes = []
    for b in boxes:
        m = trimesh.creation.box(extents=b.size)
        t = np.eye(4)
        t[:3, :3], t[:3, 3] = b.rotation, b.center
        meshes.append(m.apply_transform(t))
    scene_mesh = trimesh.util.concatenate(meshes)
    d = pixel_rays(K, W, H).reshape(-1, 3) @ pose[:3, :3].T
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = np.broadcast_to(pose[:3, 3], d.shape)
    locs, ray_idx, _ = scene_mesh.ray.intersects_location(o, d, multiple_hits=True)
    first = np.full(len(d), np.inf)
    np.minimum.at(first, ray_idx, np.linalg.norm(locs - o[ray_idx], axis=1))
    hit = np.isfinite(first)
    seen = (depth > 0).reshape(-1)
    # Embree may miss a ray through an edge of the triangulation; allow a few pixels
    assert (hit != seen).sum() <= 2
    both = hit & seen
    points = depth_to_points(depth, *K, pose=pose)
    by_pixel = np.full((H * W, 3), np.nan)
    by_pixel[seen] = points
    assert np.allclose(by_pixel[both], o[both] + first[both, None] * d[both], atol=1e-6)
    pts, normals = depth_to_cloud(depth, K, pose)
    assert np.allclose(pts, points)
    to_camera = pose[:3, 3] - pts
    assert (np.einsum("ij,ij->i", normals, to_camera) > 0).all()


def test_bad_input_is_refused_in_one_line() -> None:
    world = CollisionWorld.from_shapes([Box(np.zeros(3), np.ones(3))], 3)
    with pytest.raises(ValueError, match="intrinsics"):
        render_depth(world, (0.0, 80.0, 1.0, 1.0), np.eye(4), W, H)
    with pytest.raises(ValueError, match="width, height"):
        render_depth(world, K, np.eye(4), 0, H)
    flat = CollisionWorld.from_shapes([Box(np.zeros(2), np.ones(2))], 2)
    with pytest.raises(ValueError, match="one 3D scene"):
        render_depth(flat, K, np.eye(4), W, H)
