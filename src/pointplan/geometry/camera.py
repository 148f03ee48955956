"""A simulated depth camera: the depth image a pinhole camera would take of a scene.

The camera follows OpenCV's convention, as :func:`~pointplan.geometry.clouds.depth_to_cloud`
does: it looks along its +z with x right and y down; pixel ``(u, v)`` (column, row) sees
along ``((u - cx) / fx, (v - cy) / fy, 1)``, and its depth is the hit's z in the camera
frame (not the distance along the ray). Rays are cast against every obstacle of the scene
(:func:`~pointplan.geometry.raycast.cast_rays`); a pixel whose ray hits nothing within
``max_range`` reads 0, as a real sensor's no-return does. So ``depth_to_cloud`` of a
rendered image gives back the visible surface points, and only those: what the camera
cannot see (behind an obstacle, outside the image) is missing, as in a real cell.

Typical use::

    pose = look_at(eye=[1.6, -1.0, 1.2], target=[0.5, 0.0, 0.4])
    depth = render_depth(scene.world, (300, 300, 160, 120), pose, 320, 240, max_range=4.0)
    points, normals = depth_to_cloud(depth, (300, 300, 160, 120), pose)
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from .clouds import camera_intrinsics, camera_pose
from .collision import CollisionWorld
from .raycast import cast_rays

Array = NDArray[np.float64]


def look_at(eye: Sequence[float] | Array, target: Sequence[float] | Array, up: Sequence[float] = (0, 0, 1)) -> Array:
    """The 4 x 4 camera-to-world pose of a camera at ``eye`` looking at ``target`` (its
    +z), with its image's "up" (-y) toward ``up`` as far as it can be."""
    eye, target = np.asarray(eye, np.float64).reshape(3), np.asarray(target, np.float64).reshape(3)
    z = target - eye
    if not np.linalg.norm(z) > 0:
        raise ValueError("look_at: the eye and the target are the same point")
    z /= np.linalg.norm(z)
    x = np.cross(z, np.asarray(up, np.float64))
    if np.linalg.norm(x) < 1e-9:  # looking along up: any sideways axis will do
        x = np.cross(z, [1.0, 0.0, 0.0] if abs(z[0]) < 0.9 else [0.0, 1.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    pose = np.eye(4)
    pose[:3, 0], pose[:3, 1], pose[:3, 2], pose[:3, 3] = x, y, z, eye
    return pose


def pixel_rays(intrinsics: Sequence[float] | Array, width: int, height: int) -> Array:
    """The unnormalised camera-frame direction ``(H, W, 3)`` of every pixel (z = 1)."""
    fx, fy, cx, cy = camera_intrinsics(intrinsics)
    if width < 1 or height < 1:
        raise ValueError(f"an image needs width, height >= 1, not {width} x {height}")
    u = np.arange(width, dtype=np.float64)[None, :]
    v = np.arange(height, dtype=np.float64)[:, None]
    x, y = np.broadcast_arrays((u - cx) / fx, (v - cy) / fy)
    return np.stack([x, y, np.ones_like(x)], axis=-1)


def render_depth(
    world: CollisionWorld,
    intrinsics: Sequence[float] | Array,
    pose: Sequence[float] | Array,
    width: int,
    height: int,
    max_range: float = np.inf,
) -> Array:
    """The depth image ``(height, width)`` (metres along the optical axis; 0 for no return
    within ``max_range`` of the camera) of ``world`` (one 3D scene) seen by a pinhole
    camera with ``intrinsics`` ``fx, fy, cx, cy`` at ``pose`` (camera-to-world: a 4 x 4
    matrix or ``x, y, z, qx, qy, qz, qw``)."""
    if world.dim != 3 or world.batch_shape != ():
        raise ValueError("render_depth takes one 3D scene's collision world")
    t = camera_pose(pose)
    rays = pixel_rays(intrinsics, width, height)
    norm = np.linalg.norm(rays, axis=-1)
    directions = (rays / norm[..., None]).reshape(-1, 3) @ t[:3, :3].T
    origins = np.broadcast_to(t[:3, 3], directions.shape)
    hits = cast_rays(world, origins, directions, max_range)
    depth = np.where(hits.hit, hits.distance, 0.0).reshape(height, width) / norm
    return np.where(np.isfinite(depth), depth, 0.0)
