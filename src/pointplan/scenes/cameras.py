"""A scene as a few depth cameras see it: the point cloud a real cell would plan against.

:func:`camera_ring` places ``n`` cameras as a cell might have them: on the robot's side of
the obstacles (the robot's base at the origin), at ``distance`` from the obstacles' centre,
looking at it from ``elevation`` degrees up, spread ``spread`` degrees apart around it.
:func:`seen_by_cameras` renders each camera's depth image
(:func:`~pointplan.geometry.camera.render_depth`), back-projects it with normals
(:func:`~pointplan.geometry.clouds.depth_to_cloud`) and returns a scene whose only obstacle
is the merged cloud, with the original scene's bounds. What no camera sees (the backs of
obstacles, what one obstacle hides behind another) is not in it: a planner that trusts the
cloud can pass through it, which is why paths planned on it are certified against the true
scene.

    poses = camera_ring(problem.scene, 2)
    cloud_scene = seen_by_cameras(problem.scene, poses)
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from ..geometry.camera import look_at, render_depth
from ..geometry.clouds import depth_to_cloud
from ..geometry.collision import _bounding_sphere
from ..geometry.shapes import Box, PointCloud, Shape, Sphere
from .scene import Scene

Array = NDArray[np.float64]


@dataclasses.dataclass(frozen=True)
class CameraModel:
    """A pinhole depth camera: image size and focal length in pixels (the principal point
    at the image's centre), and its range (returns beyond it read 0)."""

    width: int = 320
    height: int = 240
    focal: float = 280.0
    max_range: float = 4.0

    @property
    def intrinsics(self) -> tuple[float, float, float, float]:
        """``fx, fy, cx, cy``."""
        return self.focal, self.focal, (self.width - 1) / 2.0, (self.height - 1) / 2.0


def _extent(s: Shape) -> tuple[Array, Array]:
    """An axis-aligned box around one obstacle (exact for boxes, spheres and clouds)."""
    if isinstance(s, Box):
        half = np.abs(s.rotation) @ (s.size / 2.0)
        return s.center - half, s.center + half
    if isinstance(s, Sphere):
        return s.center - s.radius, s.center + s.radius
    if isinstance(s, PointCloud):
        return s.points.min(0), s.points.max(0)
    c, r = _bounding_sphere(s)
    return c - r, c + r


def obstacle_box(scene: Scene) -> tuple[Array, Array]:
    """An axis-aligned box around ``scene``'s obstacles."""
    if not scene.obstacles:
        raise ValueError("the scene has no obstacles to look at")
    ext = [_extent(s) for s in scene.obstacles]
    return np.min([lo for lo, _ in ext], axis=0), np.max([hi for _, hi in ext], axis=0)


def camera_ring(
    scene: Scene, n: int, distance: float = 2.0, elevation: float = 35.0, spread: float = 70.0
) -> list[Array]:
    """``n`` camera poses (4 x 4, camera-to-world) looking at the centre of ``scene``'s
    obstacles from the side of the robot's base (the origin): ``distance`` from it,
    ``elevation`` degrees above the horizontal, their azimuths ``spread`` degrees apart in
    all, centred on the direction from the obstacles to the base."""
    if n < 1:
        raise ValueError(f"at least one camera, not {n}")
    lo, hi = obstacle_box(scene)
    target = (lo + hi) / 2.0
    back = -target[:2]
    if np.linalg.norm(back) < 1e-6:  # obstacles around the base: look from -x
        back = np.array([-1.0, 0.0])
    heading = np.arctan2(back[1], back[0])
    offsets = np.zeros(1) if n == 1 else np.linspace(-spread / 2.0, spread / 2.0, n)
    el = np.radians(elevation)
    poses = []
    for a in heading + np.radians(offsets):
        eye = target + distance * np.array([np.cos(el) * np.cos(a), np.cos(el) * np.sin(a), np.sin(el)])
        poses.append(look_at(eye, target))
    return poses


def seen_by_cameras(scene: Scene, poses: Sequence[Array], camera: CameraModel | None = None) -> Scene:
    """``scene`` as the depth cameras at ``poses`` see it: one point cloud (with normals from
    each image's pixel grid) in the original bounds. Raises ``ValueError`` if no camera
    sees anything."""
    cam = camera or CameraModel()
    points, normals = [], []
    for pose in poses:
        depth = render_depth(scene.world, cam.intrinsics, pose, cam.width, cam.height, cam.max_range)
        if (depth > 0).any():
            p, n = depth_to_cloud(depth, cam.intrinsics, pose)
            points.append(p)
            normals.append(n)
    if not points:
        raise ValueError("no camera sees any obstacle")
    cloud = PointCloud(np.concatenate(points), np.concatenate(normals))
    # (the same kind of scene: an arm's keeps its joint limits and workspace box)
    return dataclasses.replace(scene, obstacles=[cloud], name=f"{scene.name} seen by {len(poses)} cameras")
