"""Boxes against point clouds through the k-d tree: the brute-force answer, faster."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from pointplan.geometry.collision import CollisionWorld, _sub_boxes, boxes_contain_cloud_points, sphere_box_sqdist
from pointplan.geometry.shapes import PointCloud


def _brute(pts: np.ndarray, c: np.ndarray, rot: np.ndarray, h: np.ndarray, margin: float = 0.0) -> np.ndarray:
    return np.any(sphere_box_sqdist(pts, c, rot, h) <= margin * margin, 0)


@pytest.mark.parametrize("seed", range(4))
def test_tree_query_is_the_brute_force_answer_3d(seed: int) -> None:
    rng = np.random.default_rng(seed)
    pts = rng.uniform(0, 1, (4000, 3))
    m = 600
    c = rng.uniform(0, 1, (m, 3))
    rot = Rotation.random(m, random_state=seed).as_matrix()
    # long thin bars (as the S-shape's), flat plates and cubes
    h = np.stack([rng.uniform(0.05, 0.15, m), rng.uniform(0.003, 0.02, m), rng.uniform(0.003, 0.1, m)], -1)
    # points exactly on faces and corners of some boxes count as inside (<= 0), as in the brute force
    k = rng.integers(0, m, 50)
    face = np.einsum("kij,kj->ki", rot[k], h[k] * rng.choice([-1.0, 1.0], (50, 3)))
    pts = np.concatenate([pts, c[k] + face])
    for margin in (0.0, 0.004):
        expect = _brute(pts, c, rot, h, margin)
        got = boxes_contain_cloud_points(cKDTree(pts), c, rot, h, margin)
        assert 0 < expect.sum() < m
        np.testing.assert_array_equal(got, expect)


def test_tree_query_2d_and_batch_shapes() -> None:
    rng = np.random.default_rng(7)
    pts = rng.uniform(0, 1, (3000, 2))
    a = rng.uniform(0, 2 * np.pi, (4, 50))
    rot = np.stack([np.stack([np.cos(a), np.sin(a)], -1), np.stack([-np.sin(a), np.cos(a)], -1)], -2)
    c = rng.uniform(0, 1, (4, 50, 2))
    h = rng.uniform(0.001, 0.08, (4, 50, 2))
    got = boxes_contain_cloud_points(cKDTree(pts), c, rot, h)
    assert got.shape == (4, 50)
    np.testing.assert_array_equal(
        got.reshape(-1), _brute(pts, c.reshape(-1, 2), rot.reshape(-1, 2, 2), h.reshape(-1, 2))
    )


def test_sub_boxes_cover_their_box() -> None:
    """Every point of a box lies in the ball of one of its pieces."""
    rng = np.random.default_rng(3)
    c = rng.uniform(0, 1, (20, 3))
    rot = Rotation.random(20, random_state=3).as_matrix()
    h = rng.uniform(0.001, 0.2, (20, 3))
    centres, radius, owner = _sub_boxes(c, rot, h)
    for b in range(20):
        local = rng.uniform(-1, 1, (500, 3)) * h[b]
        p = c[b] + local @ rot[b].T
        mine = owner == b
        d = np.linalg.norm(p[:, None] - centres[mine][None], axis=-1)
        assert np.all(np.any(d <= radius[mine][None] * (1 + 1e-9) + 1e-12, 1))


def test_collision_world_with_a_cloud_uses_it() -> None:
    """Each cloud point is a sphere of the cloud's point radius, for boxes and spheres."""
    rng = np.random.default_rng(1)
    pts = rng.uniform(0, 1, (2000, 3))
    cloud = PointCloud(pts, np.zeros_like(pts))
    r = cloud.point_radius()
    assert 0 < r < 0.2
    world = CollisionWorld.from_shapes([cloud], 3)
    c = rng.uniform(0, 1, (100, 3))
    rot = Rotation.random(100, random_state=1).as_matrix()
    h = np.full((100, 3), 0.02)
    hit = world.boxes_collide(c, rot, h)
    np.testing.assert_array_equal(hit, _brute(pts, c, rot, h, r))
    assert hit.sum() > _brute(pts, c, rot, h).sum()  # the radius counts
    balls = world.spheres_collide(c, 0.01)
    np.testing.assert_array_equal(balls, np.min(np.linalg.norm(c[:, None] - pts[None], axis=-1), 1) <= 0.01 + r)
    fixed = CollisionWorld.from_shapes([PointCloud(pts, np.zeros_like(pts), radius=0.0)], 3)
    np.testing.assert_array_equal(fixed.boxes_collide(c, rot, h), _brute(pts, c, rot, h))
