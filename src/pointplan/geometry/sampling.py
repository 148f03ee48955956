"""Points sampled on obstacle surfaces and inside obstacles, with outward normals."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from .shapes import Box, Capsule, Cone, Cylinder, Mesh, PointCloud, Shape, Sphere

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


def _axis_frame(axis: Array) -> Array:
    """A rotation whose third column is ``axis`` (normalised; +z for a zero axis)."""
    n = float(np.linalg.norm(axis))
    z = axis / n if n > 0 else np.array([0.0, 0.0, 1.0])
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z], 1)


def _capsule_outline_2d(cap: Capsule, spacing: float) -> tuple[Array, Array]:
    """Points about ``spacing`` apart (cell centres) on the boundary of a 2D capsule: its two
    straight sides and the half circles around ``a`` and ``b``."""
    axis = cap.b - cap.a
    length = float(np.linalg.norm(axis))
    if length < 1e-12:
        return _sphere_surface(Sphere(cap.a, cap.radius), spacing)
    u = axis / length
    theta = float(np.arctan2(u[1], u[0]))
    n_side = max(1, int(np.floor(length / spacing)))
    t = (np.arange(n_side) + 0.5) / n_side * length
    pts, nrm = [], []
    for sign in (-1.0, 1.0):
        side = sign * np.array([-u[1], u[0]])
        pts.append(cap.a + t[:, None] * u + cap.radius * side)
        nrm.append(np.broadcast_to(side, (n_side, 2)))
    n_arc = max(4, int(np.ceil(np.pi * cap.radius / spacing)))
    angles = (np.arange(n_arc) + 0.5) / n_arc * np.pi - np.pi / 2
    for end, offset in ((cap.b, 0.0), (cap.a, np.pi)):
        a = theta + offset + angles
        nn = np.stack([np.cos(a), np.sin(a)], 1)
        pts.append(end + cap.radius * nn)
        nrm.append(nn)
    return np.concatenate(pts), np.concatenate(nrm)


def _capsule_surface_3d(cap: Capsule, spacing: float) -> tuple[Array, Array]:
    """Points about ``spacing`` apart on a 3D capsule: a grid of cell centres on the
    cylindrical side and a Fibonacci lattice split between the two half spheres."""
    axis = cap.b - cap.a
    length = float(np.linalg.norm(axis))
    frame = _axis_frame(axis)
    r = cap.radius
    n_ring = max(8, int(np.ceil(2 * np.pi * r / spacing)))
    n_along = int(np.floor(length / spacing))
    ang = (np.arange(n_ring) + 0.5) / n_ring * 2 * np.pi
    zs = (np.arange(n_along) + 0.5) / max(n_along, 1) * length
    ga, gz = np.meshgrid(ang, zs, indexing="ij")
    side = np.stack([np.cos(ga.ravel()), np.sin(ga.ravel()), np.zeros(ga.size)], 1)
    side_p = r * side + gz.ravel()[:, None] * np.array([0.0, 0.0, 1.0])
    ball = fibonacci_sphere(max(16, int(np.ceil(4 * np.pi * r**2 / spacing**2))))
    ball_p = r * ball + np.where(ball[:, 2:] > 0, length, 0.0) * np.array([0.0, 0.0, 1.0])
    local_p, local_n = np.concatenate([side_p, ball_p]), np.concatenate([side, ball])
    return local_p @ frame.T + cap.a, local_n @ frame.T


def capsule_surface(cap: Capsule, spacing: float) -> tuple[Array, Array]:
    """Points about ``spacing`` apart on the boundary of a capsule (2D or 3D), with
    outward normals."""
    return _capsule_outline_2d(cap, spacing) if cap.dim == 2 else _capsule_surface_3d(cap, spacing)


def fibonacci_sphere(n: int) -> Array:
    """``n`` nearly uniform unit vectors on the sphere (a Fibonacci lattice)."""
    i = np.arange(n) + 0.5
    phi = np.arccos(1 - 2 * i / n)
    theta = np.pi * (1 + 5**0.5) * i
    return np.stack([np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)], 1)


def surface_points(
    shapes: Sequence[Shape], spacing: float, low: Array | None = None, high: Array | None = None
) -> tuple[Array, Array]:
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
        elif isinstance(s, Capsule):
            p, n = capsule_surface(s, spacing)
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
        elif isinstance(s, Capsule):
            hit = _capsule_sqdist(p, s) < (s.radius - eps) ** 2
        else:
            continue
        inside |= hit & (owner != k)
    return inside


def _capsule_sqdist(p: Array, cap: Capsule) -> Array:
    """Squared distance from points ``(N, d)`` to a capsule's segment ``a -> b``."""
    from .collision import point_segment_sqdist

    return np.asarray(point_segment_sqdist(p, cap.a[None], cap.b[None])[:, 0])


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
        elif isinstance(s, Capsule):
            inside |= _capsule_sqdist(grid, s) <= s.radius**2
        else:
            raise NotImplementedError(f"interior sampling of {type(s).__name__} is not implemented yet")
    return grid[inside]


# ------------------------------------------------------------------ area-weighted (3D)
def shape_to_trimesh(s: Shape, sections: int = 32) -> trimesh.Trimesh:  # type: ignore[name-defined]  # noqa: F821
    """A triangle mesh of a 3D shape in the world frame (primitives tessellated)."""
    import trimesh

    if isinstance(s, Box):
        m = trimesh.creation.box(extents=s.size)
        tf = np.eye(4)
        tf[:3, :3], tf[:3, 3] = s.rotation, s.center
    elif isinstance(s, Sphere):
        m = trimesh.creation.icosphere(subdivisions=3, radius=s.radius)
        tf = np.eye(4)
        tf[:3, 3] = s.center
    elif isinstance(s, Capsule):
        from .collision import _rotation_to_z

        axis = s.b - s.a
        m = trimesh.creation.capsule(height=float(np.linalg.norm(axis)), radius=s.radius, count=[sections, sections])
        tf = np.eye(4)
        tf[:3, :3], tf[:3, 3] = _rotation_to_z(axis), (s.a + s.b) / 2
    elif isinstance(s, Cylinder):
        m = trimesh.creation.cylinder(radius=s.radius, height=s.length, sections=sections)
        tf = np.eye(4)
        tf[:3, :3], tf[:3, 3] = s.rotation, s.center
    elif isinstance(s, Cone):
        m = trimesh.creation.cone(radius=s.radius, height=s.length, sections=sections)
        m.apply_translation([0.0, 0.0, -s.length / 2])  # trimesh puts the base at z = 0
        tf = np.eye(4)
        tf[:3, :3], tf[:3, 3] = s.rotation, s.center
    elif isinstance(s, Mesh):
        return trimesh.Trimesh(s.vertices, s.faces, process=False)
    else:
        raise TypeError(f"no mesh for {type(s).__name__}")
    m.apply_transform(tf)
    return m


def _box_area_samples(box: Box, n: int, rng: np.random.Generator) -> tuple[Array, Array]:
    h = box.half
    areas = np.array([h[1] * h[2], h[0] * h[2], h[0] * h[1]] * 2)
    face = rng.choice(6, size=n, p=areas / areas.sum())
    axis, sign = face % 3, np.where(face < 3, 1.0, -1.0)
    local = rng.uniform(-1.0, 1.0, (n, 3)) * h
    local[np.arange(n), axis] = sign * h[axis]
    nrm = np.zeros((n, 3))
    nrm[np.arange(n), axis] = sign
    return local @ box.rotation.T + box.center, nrm @ box.rotation.T


def cloud_area(cloud: PointCloud) -> float:
    """The surface a point cloud covers, estimated as one square of the typical point
    spacing (the median nearest-neighbour distance) per point."""
    from scipy.spatial import cKDTree

    p = cloud.points
    if len(p) < 2:
        return 0.0
    dist, _ = cKDTree(p).query(p, k=2)
    return float(len(p) * np.median(dist[:, 1]) ** 2)


def shape_area(s: Shape) -> float:
    """Surface area of a 3D shape (tessellated for capsules, cylinders, cones, meshes;
    estimated from the spacing of its points for a point cloud)."""
    if isinstance(s, PointCloud):
        return cloud_area(s)
    if isinstance(s, Box):
        a, b, c = s.size
        return float(2 * (a * b + b * c + a * c))
    if isinstance(s, Sphere):
        return float(4 * np.pi * s.radius**2)
    return float(shape_to_trimesh(s).area)


def area_weighted_points(
    shapes: Sequence[Shape], n: int, rng: np.random.Generator, drop_hidden: bool = True
) -> tuple[Array, Array, NDArray[np.int64]]:
    """``n`` points drawn uniformly on the obstacles' surfaces (each shape gets points in
    proportion to its area) with outward normals, and the index of the shape each lies on.

    Boxes and spheres are sampled exactly; point clouds give their own points and normals
    (drawn without replacement while they last); other shapes are sampled on their
    tessellation (face normals). With ``drop_hidden``, points strictly inside another obstacle are discarded,
    so fewer than ``n`` may come back."""
    shapes = list(shapes)
    if not shapes or n <= 0:
        return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, np.int64)
    areas = np.array([shape_area(s) for s in shapes])
    if not areas.sum() > 0:
        return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, np.int64)
    counts = rng.multinomial(n, areas / areas.sum())
    pts, nrm, own = [], [], []
    for k, (s, c) in enumerate(zip(shapes, counts)):
        if c == 0:
            continue
        if isinstance(s, Box):
            p, nn = _box_area_samples(s, int(c), rng)
        elif isinstance(s, PointCloud):
            pick = rng.choice(len(s.points), size=int(c), replace=int(c) > len(s.points))
            p, nn = s.points[pick], s.normals[pick]
        elif isinstance(s, Sphere):
            nn = rng.normal(size=(int(c), 3))
            nn /= np.linalg.norm(nn, axis=1, keepdims=True)
            p = s.center + s.radius * nn
        else:
            import trimesh

            m = shape_to_trimesh(s)
            p, face = trimesh.sample.sample_surface(m, int(c), seed=int(rng.integers(2**31)))
            nn = np.asarray(m.face_normals)[face]
            if isinstance(s, Mesh) and m.is_watertight and m.volume < 0:
                nn = -nn  # a closed mesh wound inwards: turn its normals outwards
        pts.append(np.asarray(p, np.float64))
        nrm.append(np.asarray(nn, np.float64))
        own.append(np.full(len(pts[-1]), k, np.int64))
    p, nn, o = np.concatenate(pts), np.concatenate(nrm), np.concatenate(own)
    if drop_hidden:
        keep = ~_hidden(p, o, shapes)
        p, nn, o = p[keep], nn[keep], o[keep]
    return p, nn, o


def _hidden(p: Array, owner: NDArray[np.int64], shapes: Sequence[Shape], eps: float = 1e-6) -> NDArray[np.bool_]:
    """Is each point strictly inside (by more than ``eps``) an obstacle other than its own?"""
    from .collision import (
        mesh_contains,
        point_cone_sqdist,
        point_cylinder_sqdist,
        point_segment_sqdist,
    )

    out = np.zeros(len(p), dtype=bool)
    for k, s in enumerate(shapes):
        other = owner != k
        if not other.any():
            continue
        q = p[other]
        if isinstance(s, Box):
            hit = np.all(np.abs((q - s.center) @ s.rotation) < s.half - eps, axis=1)
        elif isinstance(s, Sphere):
            hit = np.linalg.norm(q - s.center, axis=1) < s.radius - eps
        elif isinstance(s, Capsule):
            hit = point_segment_sqdist(q, s.a[None], s.b[None])[:, 0] < (s.radius - eps) ** 2
        elif isinstance(s, Cylinder):
            hit = (
                point_cylinder_sqdist(
                    q, s.center[None], s.rotation[None], np.array([s.radius - eps]), np.array([s.length / 2 - eps])
                )[:, 0]
                <= 0
            )
        elif isinstance(s, Cone):
            hit = (
                point_cone_sqdist(
                    q, s.center[None], s.rotation[None], np.array([s.radius - eps]), np.array([s.length / 2 - eps])
                )[:, 0]
                <= 0
            )
        elif isinstance(s, Mesh):
            lo, hi = s.vertices.min(0), s.vertices.max(0)
            box = np.all((q > lo) & (q < hi), axis=1)  # the inside test only where it can hold
            hit = np.zeros(len(q), dtype=bool)
            if box.any():
                hit[box] = mesh_contains(s, q[box])
        else:
            continue
        out[np.flatnonzero(other)[hit]] = True
    return out
