"""Points sampled on obstacle surfaces and inside obstacles, with outward normals."""

from __future__ import annotations

from typing import Sequence

import numpy as np
from numpy.typing import NDArray

from .shapes import Box, PointCloud, Shape, Sphere

Array = NDArray[np.float64]


def _box_edges_2d(box: Box, spacing: float) -> tuple[Array, Array]:
    """Evenly spaced points (cell centres) on the four edges of a 2D box."""
    pts, nrm = [], []
    h = box.half
    for axis in range(2):
        other = 1 - axis
        n = max(1, int(np.floor(2 * h[other] / spacing)))
        t = (np.arange(n) + 0.5) / n * 2 * h[other] - h[other]
        for sign in (-1.0, 1.0):
            p = np.zeros((n, 2))
            p[:, axis] = sign * h[axis]
            p[:, other] = t
            nn = np.zeros((n, 2))
            nn[:, axis] = sign
            pts.append(p)
            nrm.append(nn)
    p = np.concatenate(pts) @ box.rotation.T + box.center
    return p, np.concatenate(nrm) @ box.rotation.T


def _box_faces_3d(box: Box, spacing: float) -> tuple[Array, Array]:
    """Points on a grid of cell centres on the six faces of a 3D box."""
    pts, nrm = [], []
    h = box.half
    for axis in range(3):
        a, b = [i for i in range(3) if i != axis]
        na = max(1, int(np.floor(2 * h[a] / spacing)))
        nb = max(1, int(np.floor(2 * h[b] / spacing)))
        ua = (np.arange(na) + 0.5) / na * 2 * h[a] - h[a]
        ub = (np.arange(nb) + 0.5) / nb * 2 * h[b] - h[b]
        ga, gb = np.meshgrid(ua, ub, indexing="ij")
        for sign in (-1.0, 1.0):
            p = np.zeros((na * nb, 3))
            p[:, axis] = sign * h[axis]
            p[:, a] = ga.ravel()
            p[:, b] = gb.ravel()
            nn = np.zeros_like(p)
            nn[:, axis] = sign
            pts.append(p)
            nrm.append(nn)
    p = np.concatenate(pts) @ box.rotation.T + box.center
    return p, np.concatenate(nrm) @ box.rotation.T


def _sphere_surface(s: Sphere, spacing: float) -> tuple[Array, Array]:
    if s.dim == 2:
        n = max(8, int(np.ceil(2 * np.pi * s.radius / spacing)))
        a = (np.arange(n) + 0.5) / n * 2 * np.pi
        nn = np.stack([np.cos(a), np.sin(a)], 1)
    else:
        n = max(16, int(np.ceil(4 * np.pi * s.radius**2 / spacing**2)))
        nn = fibonacci_sphere(n)
    return s.center + s.radius * nn, nn


def fibonacci_sphere(n: int) -> Array:
    """``n`` nearly uniform unit vectors on the sphere (a Fibonacci lattice)."""
    i = np.arange(n) + 0.5
    phi = np.arccos(1 - 2 * i / n)
    theta = np.pi * (1 + 5**0.5) * i
    return np.stack([np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)], 1)


def surface_points(shapes: Sequence[Shape], spacing: float, low: Array | None = None, high: Array | None = None) -> tuple[Array, Array]:
    """Points on the union's boundary about ``spacing`` apart, with outward normals.

    Points buried inside another obstacle are dropped, and so are points on the bounds'
    faces whose normal points out of the workspace (nobody inside can see them).
    """
    pts, nrm, owner = [], [], []
    for k, s in enumerate(shapes):
        if isinstance(s, Box):
            p, n = _box_edges_2d(s, spacing) if s.dim == 2 else _box_faces_3d(s, spacing)
        elif isinstance(s, Sphere):
            p, n = _sphere_surface(s, spacing)
        elif isinstance(s, PointCloud):
            p, n = s.points, s.normals
        else:
            raise NotImplementedError(f"surface sampling of {type(s).__name__} is not implemented yet")
        pts.append(p)
        nrm.append(n)
        owner.append(np.full(len(p), k))
    if not pts:
        d = len(low) if low is not None else (shapes[0].dim if shapes else 0)
        return np.zeros((0, d)), np.zeros((0, d))
    p, n, own = np.concatenate(pts), np.concatenate(nrm), np.concatenate(owner)
    keep = ~_inside_other(p, own, shapes)
    if low is not None and high is not None:
        on_low = (np.abs(p - low) < 1e-9) & (n < -0.5)
        on_high = (np.abs(p - high) < 1e-9) & (n > 0.5)
        keep &= ~np.any(on_low | on_high, axis=1)
    return p[keep], n[keep]


def _inside_other(p: Array, owner: NDArray[np.int64], shapes: Sequence[Shape], eps: float = 1e-9) -> NDArray[np.bool_]:
    """Is each point strictly inside an obstacle other than its own?"""
    inside = np.zeros(len(p), dtype=bool)
    for k, s in enumerate(shapes):
        if isinstance(s, Box):
            local = (p - s.center) @ s.rotation
            hit = np.all(np.abs(local) < s.half - eps, axis=1)
        elif isinstance(s, Sphere):
            hit = np.linalg.norm(p - s.center, axis=1) < s.radius - eps
        else:
            continue
        inside |= hit & (owner != k)
    return inside


def interior_points(shapes: Sequence[Shape], spacing: float, low: Array, high: Array) -> Array:
    """Cell centres of a grid of ``spacing`` that lie inside an obstacle (within bounds)."""
    d = len(low)
    axes = [np.arange(lo + spacing / 2, hi, spacing) for lo, hi in zip(low, high)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, d)
    inside = np.zeros(len(grid), dtype=bool)
    for s in shapes:
        if isinstance(s, Box):
            inside |= np.all(np.abs((grid - s.center) @ s.rotation) <= s.half, axis=1)
        elif isinstance(s, Sphere):
            inside |= np.linalg.norm(grid - s.center, axis=1) <= s.radius
        else:
            raise NotImplementedError(f"interior sampling of {type(s).__name__} is not implemented yet")
    return grid[inside]
