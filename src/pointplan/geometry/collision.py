"""Batched collision of robot bodies against a scene's obstacles.

A :class:`CollisionWorld` packs a scene's obstacles into arrays, one group per shape type.
Worlds of several scenes can be stacked (``CollisionWorld.stack``) into one world with a
leading batch dimension ``E``: obstacle groups are padded with empty shapes far away, so a
query ``(E, M, ...)`` is answered for every scene at once with no Python loop over scenes,
configurations or obstacles.

Robot bodies are unions of spheres and oriented boxes. Pairs handled in closed form:
sphere vs {box, sphere, capsule, cylinder, cone, points} in 2D and 3D, box vs {box
(separating axis test), sphere, points} in 3D. Meshes, and box vs capsule/cylinder/cone, go
through coal.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from ._kernels import obb_overlap_compiled, spheres_hit_cloud_compiled, winding_numbers_compiled
from .shapes import Box, Capsule, Cone, Cylinder, Mesh, PointCloud, Shape, Sphere

Array = NDArray[np.float64]
Bool = NDArray[np.bool_]

_FAR = 1e6
#: a point cloud sorted into a grid (:func:`cloud_grid_arrays`)
CloudGrid = tuple[Array, NDArray[np.int64], Array, NDArray[np.int64], Array, NDArray[np.int64]]


# ---------------------------------------------------------------------------- kernels
def sphere_box_sqdist(c: Array, bc: Array, br: Array, bh: Array) -> Array:
    """Squared distance from points ``c: (..., M, d)`` to solid boxes ``(..., K, ...)``.

    Returns ``(..., M, K)``; zero inside a box.
    """
    diff = c[..., :, None, :] - bc[..., None, :, :]
    rot = br[..., None, :, :, :]  # (..., 1, K, d, d)
    d = c.shape[-1]
    # local_i = sum_j diff_j R_ji, written out: much faster than einsum for d = 2, 3
    out = np.zeros(diff.shape[:-1])
    for i in range(d):
        local = diff[..., 0] * rot[..., 0, i]
        for j in range(1, d):
            local = local + diff[..., j] * rot[..., j, i]
        excess = np.maximum(np.abs(local) - bh[..., None, :, i], 0.0)
        out += excess * excess
    return out


def _dot_last(x: Array, y: Array) -> Array:
    """``sum_i x_i y_i`` over the last axis (broadcast), added in axis order: the order the
    compiled kernels add in (einsum's order depends on numpy's vector code)."""
    out = x[..., 0] * y[..., 0]
    for i in range(1, x.shape[-1]):
        out = out + x[..., i] * y[..., i]
    return out


def sphere_sphere_sqdist(c: Array, sc: Array) -> Array:
    """Squared centre distances ``(..., M, K)``."""
    diff = c[..., :, None, :] - sc[..., None, :, :]
    return _dot_last(diff, diff)


def point_segment_sqdist(c: Array, a: Array, b: Array) -> Array:
    """Squared distance from points ``(..., M, d)`` to segments ``a, b: (..., K, d)``."""
    ab = b - a
    denom = np.maximum(_dot_last(ab, ab), 1e-18)
    ac = c[..., :, None, :] - a[..., None, :, :]
    t = np.clip(_dot_last(ac, ab[..., None, :, :]) / denom[..., None, :], 0.0, 1.0)
    d = ac - t[..., None] * ab[..., None, :, :]
    return _dot_last(d, d)


def _local_frame(c: Array, cc: Array, cr: Array) -> Array:
    """Points ``c: (..., M, 3)`` in the frames ``cc: (..., K, 3)``, ``cr: (..., K, 3, 3)``
    (columns the axes): ``(..., M, K, 3)``, ``local_i = sum_j (c_j - cc_j) cr_ji`` added in
    axis order (as the compiled kernels add)."""
    diff = c[..., :, None, :] - cc[..., None, :, :]
    rot = cr[..., None, :, :, :]
    return np.stack([_dot_last(diff, rot[..., :, i]) for i in range(3)], axis=-1)


def point_cylinder_sqdist(c: Array, cc: Array, cr: Array, rad: Array, half: Array) -> Array:
    """Squared distance from points to solid cylinders along their local z axis."""
    local = _local_frame(c, cc, cr)
    rho = np.sqrt(local[..., 0] * local[..., 0] + local[..., 1] * local[..., 1])
    dr = np.maximum(rho - rad[..., None, :], 0.0)
    dz = np.maximum(np.abs(local[..., 2]) - half[..., None, :], 0.0)
    return dr * dr + dz * dz


def _segment2_sqdist(px: Array, pz: Array, ax: Array, az: Array, bx: Array, bz: Array) -> Array:
    """Squared distance from 2D points ``(px, pz)`` to segments ``a -> b`` (broadcast)."""
    ux, uz = bx - ax, bz - az
    t = np.clip(((px - ax) * ux + (pz - az) * uz) / np.maximum(ux * ux + uz * uz, 1e-18), 0.0, 1.0)
    dx, dz = px - ax - t * ux, pz - az - t * uz
    return dx * dx + dz * dz


def point_cone_sqdist(c: Array, cc: Array, cr: Array, rad: Array, half: Array) -> Array:
    """Squared distance from points ``(..., M, 3)`` to solid cones ``(..., K, ...)`` (base at
    local ``z = -half``, apex at ``z = +half``). The cone is the revolution of the triangle
    (0, -h), (R, -h), (0, h) in the (rho, z) half-plane, so the 3D distance is the 2D distance
    to that triangle."""
    local = _local_frame(c, cc, cr)
    rho = np.sqrt(local[..., 0] * local[..., 0] + local[..., 1] * local[..., 1])
    z = local[..., 2]
    r = np.broadcast_to(rad[..., None, :], rho.shape)
    h = np.broadcast_to(half[..., None, :], rho.shape)
    inside = (z >= -h) & (z <= h) & (rho * 2.0 * h <= r * (h - z))
    zero = np.zeros_like(rho)
    d_base = _segment2_sqdist(rho, z, zero, -h, r, -h)
    d_side = _segment2_sqdist(rho, z, r, -h, zero, h)
    return np.where(inside, 0.0, np.minimum(d_base, d_side))


def obb_overlap(ca: Array, ra: Array, ha: Array, cb: Array, rb: Array, hb: Array) -> Bool:
    """Separating-axis test between 3D boxes A ``(..., M, ...)`` and B ``(..., K, ...)``.

    Returns ``(..., M, K)``: True where the closed boxes overlap.
    """
    # Bounding-sphere prefilter: most pairs are far apart; run the full test on the rest.
    gap = cb[..., None, :, :] - ca[..., :, None, :]
    reach = np.linalg.norm(ha, axis=-1)[..., :, None] + np.linalg.norm(hb, axis=-1)[..., None, :]
    near = np.einsum("...i,...i->...", gap, gap) <= reach * reach
    out = np.zeros(near.shape, dtype=bool)
    if not near.any():
        return out
    shape = near.shape
    lead = np.indices(shape).reshape(len(shape), -1)[:, near.ravel()]
    m_idx = tuple(lead[:-1])  # batch indices and m
    k_idx = tuple(lead[:-2]) + (lead[-1],)  # batch indices and k
    out[near] = _obb_pairs(ca[m_idx], ra[m_idx], ha[m_idx], cb[k_idx], rb[k_idx], hb[k_idx])
    return out


def _obb_pairs(ca: Array, ra: Array, ha: Array, cb: Array, rb: Array, hb: Array) -> Bool:
    """Separating-axis test on paired boxes ``(P, ...)``: True where they overlap."""
    rel = np.einsum("pji,pjl->pil", ra, rb)  # R = Ra^T Rb
    t = np.einsum("pji,pj->pi", ra, cb - ca)
    absr = np.abs(rel) + 1e-9
    sep = np.any(np.abs(t) > ha + np.einsum("pij,pj->pi", absr, hb), -1)
    tb = np.einsum("pi,pij->pj", t, rel)
    sep |= np.any(np.abs(tb) > np.einsum("pi,pij->pj", ha, absr) + hb, -1)
    i1, i2 = np.array([1, 2, 0]), np.array([2, 0, 1])
    lhs = np.abs(t[:, i2, None] * rel[:, i1, :] - t[:, i1, None] * rel[:, i2, :])
    ra_term = ha[:, i1, None] * absr[:, i2, :] + ha[:, i2, None] * absr[:, i1, :]
    rb_term = hb[:, None, i1] * absr[:, :, i2] + hb[:, None, i2] * absr[:, :, i1]
    sep |= np.any(lhs > ra_term + rb_term, axis=(-1, -2))
    return ~sep


# ---------------------------------------------------------------------------- world
@dataclass
class CollisionWorld:
    """Obstacles of one scene (batch shape ``()``) or of ``E`` stacked scenes (``(E,)``)."""

    dim: int
    box_c: Array
    box_r: Array
    box_h: Array
    sph_c: Array
    sph_r: Array
    cap_a: Array
    cap_b: Array
    cap_r: Array
    cyl_c: Array
    cyl_r: Array
    cyl_rad: Array
    cyl_half: Array
    con_c: Array = field(default_factory=lambda: np.zeros((0, 3)))
    con_r: Array = field(default_factory=lambda: np.zeros((0, 3, 3)))
    con_rad: Array = field(default_factory=lambda: np.zeros(0))
    con_half: Array = field(default_factory=lambda: np.zeros(0))
    #: per scene: point clouds (merged) as a KD-tree, or None
    cloud_trees: list[cKDTree | None] = field(default_factory=list)
    #: per scene: the normals of the tree's points (in its order), or None
    cloud_normals: list[Array | None] = field(default_factory=list)
    #: per scene: the radius of the sphere each cloud point stands for (``PointCloud.point_radius``)
    cloud_radius: list[float] = field(default_factory=list)
    #: per scene: coal collision objects of meshes
    coal_objects: list[list[tuple[Any, Any]]] = field(default_factory=list)
    #: per scene: shapes kept for the coal fallback (capsules, cylinders, cones)
    shapes: list[list[Shape]] = field(default_factory=list)
    #: per scene: coal geometry, transform, bounding-sphere centre and radius, and the mesh
    #: (None for a primitive) of every obstacle the coal fallback handles, built once
    coal_items: list[list[tuple[Any, Any, Array, float, Mesh | None]]] = field(default_factory=list)
    #: per scene: the meshes behind the coal objects (for the inside test: meshes are solid)
    meshes: list[list[Mesh]] = field(default_factory=list)

    @property
    def batch_shape(self) -> tuple[int, ...]:
        """The leading shape of stacked scenes (``()`` for one scene, ``(E,)`` stacked)."""
        return self.box_c.shape[:-2]

    def box_arrays(self) -> tuple[Array, Array, Array]:
        """The boxes as the compiled kernels take them: contiguous float64 ``(centres,
        rotations, half sides)``."""
        f = np.ascontiguousarray
        return f(self.box_c, np.float64), f(self.box_r, np.float64), f(self.box_h, np.float64)

    @property
    def boxes_only(self) -> bool:
        """Are all the obstacles boxes (no spheres, capsules, cylinders, cones, meshes or
        point clouds, in any scene)?"""
        others = (self.sph_c, self.cap_a, self.cyl_c, self.con_c)
        return (
            all(a.shape[-2] == 0 for a in others)
            and not self._has_clouds
            and not any(self.coal_items)
            and not any(self.meshes)
        )

    @property
    def primitives_only(self) -> bool:
        """Are all the obstacles boxes, spheres, capsules, cylinders or cones (no meshes or
        point clouds, in any scene)? The balls' compiled checks take such a single-scene
        world (:meth:`ball_prims`)."""
        return not self._has_clouds and not any(self.meshes)

    def ball_prims(self) -> tuple[Array, ...]:
        """The single scene's spheres, capsules, cylinders and cones as the balls' compiled
        checks take them (``pointplan.robots._ball_kernels``): contiguous float64
        ``(sphere centres, radii, capsule ends a, b, radii, cylinder centres, rotations,
        radii, half lengths, cone centres, rotations, base radii, half heights)``, or
        ``()`` where there are none (boxes only)."""
        if self.batch_shape != ():
            raise ValueError("ball_prims takes a single-scene world")
        cached: tuple[Array, ...] | None = self.__dict__.get("_ball_prims")
        if cached is None:
            arrays = (
                self.sph_c, self.sph_r, self.cap_a, self.cap_b, self.cap_r,
                self.cyl_c, self.cyl_r, self.cyl_rad, self.cyl_half,
                self.con_c, self.con_r, self.con_rad, self.con_half,
            )  # fmt: skip
            none = all(a.shape[0] == 0 for a in (self.sph_c, self.cap_a, self.cyl_c, self.con_c))
            cached = () if none else tuple(np.ascontiguousarray(a, np.float64) for a in arrays)
            self.__dict__["_ball_prims"] = cached
        return cached

    @property
    def boxes_and_clouds_only(self) -> bool:
        """Are all the obstacles boxes or point clouds (no spheres, capsules, cylinders,
        cones or meshes, in any scene)? The S-shape's compiled checks take such a
        single-scene world (the cloud through :meth:`cloud_grid`)."""
        others = (self.sph_c, self.cap_a, self.cyl_c, self.con_c)
        return all(a.shape[-2] == 0 for a in others) and not any(self.coal_items) and not any(self.meshes)

    def cloud_grid(self, cell: float) -> CloudGrid | None:
        """The single scene's cloud sorted into a uniform grid of cubes of side about
        ``cell`` (:func:`cloud_grid_arrays`), as the compiled checks read it; ``None``
        where the scene has no cloud points. Built once per world and cell size (kept in
        the world's ``__dict__``: another world, a stacked one or a later scene's, builds
        its own)."""
        if self.batch_shape != ():
            raise ValueError("cloud_grid takes a single-scene world")
        cache = self.__dict__.setdefault("_cloud_grids", {})
        key = float(cell)
        if key not in cache:
            tree = self.cloud_trees[0] if self.cloud_trees else None
            cache[key] = (
                None if tree is None or not tree.n else cloud_grid_arrays(tree.data, key, self._cloud_margin(0))
            )
        grid: CloudGrid | None = cache[key]
        return grid

    def cloud_ray_grid(self, cell: float) -> tuple[CloudGrid, Array, NDArray[np.int64]] | None:
        """:meth:`cloud_grid` with what ray casting needs besides: the points' normals in
        the grid's order (zeros where the cloud has none) and their indices in the cloud
        (``grid[0] == cloud points[order]``); ``None`` where the scene has no cloud
        points. Cached like the grid."""
        grid = self.cloud_grid(cell)
        if grid is None:
            return None
        cache = self.__dict__.setdefault("_cloud_ray_grids", {})
        key = float(cell)
        if key not in cache:
            tree = self.cloud_trees[0]
            assert tree is not None  # (the grid exists)
            order = cloud_grid_order(tree.data, grid)
            nrm = self.cloud_normals[0] if self.cloud_normals else None
            normals = np.zeros((len(order), 3)) if nrm is None else np.asarray(nrm, np.float64)[order]
            cache[key] = (grid, np.ascontiguousarray(normals), order)
        out: tuple[CloudGrid, Array, NDArray[np.int64]] = cache[key]
        return out

    # ------------------------------------------------------------------ build
    @classmethod
    def from_shapes(cls, shapes: Sequence[Shape], dim: int) -> CollisionWorld:
        """Pack world-frame shapes of one scene."""
        boxes = [s for s in shapes if isinstance(s, Box)]
        spheres = [s for s in shapes if isinstance(s, Sphere)]
        caps = [s for s in shapes if isinstance(s, Capsule)]
        cyls = [s for s in shapes if isinstance(s, Cylinder)]
        cones = [s for s in shapes if isinstance(s, Cone)]
        coal_shapes: list[Shape] = [*caps, *cyls, *cones]
        meshes = [s for s in shapes if isinstance(s, Mesh)]
        clouds = [s for s in shapes if isinstance(s, PointCloud)]
        for s in shapes:
            if s.dim != dim:
                raise ValueError(f"{type(s).__name__} is {s.dim}D in a {dim}D scene")
        if dim == 2 and (cyls or meshes or cones):
            raise ValueError("cylinders, cones and meshes are 3D shapes")
        d = dim

        def arr(xs: list[Array], shape: tuple[int, ...]) -> Array:
            return np.stack(xs).astype(np.float64) if xs else np.zeros((0,) + shape)

        tree, normals, point_r = None, None, 0.0
        if clouds:
            tree = cKDTree(np.concatenate([c.points for c in clouds]))
            normals = np.concatenate([c.normals for c in clouds])
            point_r = max(c.point_radius() for c in clouds)
        coal_objs = [_coal_mesh(m) for m in meshes]
        return cls(
            dim=d,
            box_c=arr([b.center for b in boxes], (d,)),
            box_r=arr([b.rotation for b in boxes], (d, d)),
            box_h=arr([b.half for b in boxes], (d,)),
            sph_c=arr([s.center for s in spheres], (d,)),
            sph_r=np.array([s.radius for s in spheres], dtype=np.float64),
            cap_a=arr([c.a for c in caps], (d,)),
            cap_b=arr([c.b for c in caps], (d,)),
            cap_r=np.array([c.radius for c in caps], dtype=np.float64),
            cyl_c=arr([c.center for c in cyls], (3,)) if d == 3 else np.zeros((0, 3)),
            cyl_r=arr([c.rotation for c in cyls], (3, 3)) if d == 3 else np.zeros((0, 3, 3)),
            cyl_rad=np.array([c.radius for c in cyls], dtype=np.float64),
            cyl_half=np.array([c.length / 2 for c in cyls], dtype=np.float64),
            con_c=arr([c.center for c in cones], (3,)) if d == 3 else np.zeros((0, 3)),
            con_r=arr([c.rotation for c in cones], (3, 3)) if d == 3 else np.zeros((0, 3, 3)),
            con_rad=np.array([c.radius for c in cones], dtype=np.float64),
            con_half=np.array([c.length / 2 for c in cones], dtype=np.float64),
            cloud_trees=[tree],
            cloud_normals=[normals],
            cloud_radius=[point_r],
            coal_objects=[coal_objs],
            shapes=[coal_shapes],
            coal_items=[
                [(g, tf, *_bounding_sphere(m), m) for m, (g, tf) in zip(meshes, coal_objs)]
                + (
                    [
                        (*_coal_primitive(sh), *_bounding_sphere(sh), None)
                        for sh in list(caps) + list(cyls) + list(cones)
                    ]
                    if d == 3
                    else []
                )
            ],
            meshes=[list(meshes)],
        )

    @classmethod
    def stack(cls, worlds: Sequence[CollisionWorld]) -> CollisionWorld:
        """Stack single-scene worlds into one with batch shape ``(E,)``, padding each group."""
        if not worlds:
            raise ValueError("nothing to stack")
        dim = worlds[0].dim
        if any(w.dim != dim or w.batch_shape != () for w in worlds):
            raise ValueError("stack takes single-scene worlds of one dimension")

        def pad(name: str, fill: Array) -> Array:
            xs = [getattr(w, name) for w in worlds]
            k = max(x.shape[0] for x in xs)
            out = np.empty((len(xs), k) + xs[0].shape[1:])
            out[...] = fill
            for i, x in enumerate(xs):
                out[i, : x.shape[0]] = x
            return out

        d = dim
        return cls(
            dim=d,
            box_c=pad("box_c", np.full(d, _FAR)),
            box_r=pad("box_r", np.eye(d)),
            box_h=pad("box_h", np.zeros(d)),
            sph_c=pad("sph_c", np.full(d, _FAR)),
            sph_r=pad("sph_r", np.zeros(())),
            cap_a=pad("cap_a", np.full(d, _FAR)),
            cap_b=pad("cap_b", np.full(d, _FAR)),
            cap_r=pad("cap_r", np.zeros(())),
            cyl_c=pad("cyl_c", np.full(3, _FAR)),
            cyl_r=pad("cyl_r", np.eye(3)),
            cyl_rad=pad("cyl_rad", np.zeros(())),
            cyl_half=pad("cyl_half", np.zeros(())),
            con_c=pad("con_c", np.full(3, _FAR)),
            con_r=pad("con_r", np.eye(3)),
            con_rad=pad("con_rad", np.zeros(())),
            con_half=pad("con_half", np.zeros(())),
            cloud_trees=[w.cloud_trees[0] for w in worlds],
            cloud_normals=[w.cloud_normals[0] if w.cloud_normals else None for w in worlds],
            cloud_radius=[w.cloud_radius[0] if w.cloud_radius else 0.0 for w in worlds],
            coal_objects=[w.coal_objects[0] for w in worlds],
            shapes=[w.shapes[0] for w in worlds],
            coal_items=[w.coal_items[0] for w in worlds],
            meshes=[w.meshes[0] if w.meshes else [] for w in worlds],
        )

    # ------------------------------------------------------------------ queries
    def _per_scene(self, x: Array) -> list[Array]:
        """Split a query array ``(*batch, M, ...)`` into one array per scene."""
        if self.batch_shape == ():
            return [x]
        return [x[i] for i in range(self.batch_shape[0])]

    def spheres_collide(self, centers: Array, radii: Array | float) -> Bool:
        """Do spheres ``centers: (*batch, M, d)`` of ``radii`` (scalar or ``(*batch, M)``) hit?"""
        c = np.asarray(centers, np.float64)
        r = np.broadcast_to(np.asarray(radii, np.float64), c.shape[:-1])
        r2 = (r * r)[..., None]
        hit = np.zeros(c.shape[:-1], dtype=bool)
        if self.box_c.shape[-2]:
            hit |= np.any(sphere_box_sqdist(c, self.box_c, self.box_r, self.box_h) <= r2, -1)
        if self.sph_c.shape[-2]:
            rr = r[..., None] + self.sph_r[..., None, :]
            hit |= np.any(sphere_sphere_sqdist(c, self.sph_c) <= rr * rr, -1)
        if self.cap_a.shape[-2]:
            rr = r[..., None] + self.cap_r[..., None, :]
            hit |= np.any(point_segment_sqdist(c, self.cap_a, self.cap_b) <= rr * rr, -1)
        if self.dim == 3 and self.cyl_c.shape[-2]:
            d2 = point_cylinder_sqdist(c, self.cyl_c, self.cyl_r, self.cyl_rad, self.cyl_half)
            hit |= np.any(d2 <= r2, -1)
        if self.dim == 3 and self.con_c.shape[-2]:
            hit |= np.any(point_cone_sqdist(c, self.con_c, self.con_r, self.con_rad, self.con_half) <= r2, -1)
        if self._has_clouds:
            hit |= self._spheres_vs_clouds(c, r)
        if self._has_meshes:
            hit |= self._coal_query(c, r, kind="sphere", meshes_only=True)
        return hit

    @property
    def _has_clouds(self) -> bool:
        """Whether any scene has point clouds (computed once)."""
        flag = self.__dict__.get("_clouds_flag")
        if flag is None:
            flag = self.__dict__["_clouds_flag"] = any(t is not None for t in self.cloud_trees)
        return bool(flag)

    @property
    def _has_meshes(self) -> bool:
        """Whether any scene has meshes for coal (computed once)."""
        flag = self.__dict__.get("_meshes_flag")
        if flag is None:
            flag = self.__dict__["_meshes_flag"] = any(it[4] is not None for items in self.coal_items for it in items)
        return bool(flag)

    def boxes_collide(self, centers: Array, rotations: Array, halfs: Array) -> Bool:
        """Do 3D boxes ``centers: (*batch, M, 3)``, ``rotations: (*batch, M, 3, 3)``,
        ``halfs: (*batch, M, 3)`` (half sides) hit any obstacle?"""
        if self.dim != 3:
            raise NotImplementedError("box-shaped robot parts are supported in 3D only")
        c = np.asarray(centers, np.float64)
        rot = np.asarray(rotations, np.float64)
        h = np.broadcast_to(np.asarray(halfs, np.float64), c.shape)
        hit = np.zeros(c.shape[:-1], dtype=bool)
        if self.box_c.shape[-2]:
            if c.shape[:-2] == self.batch_shape:
                hit |= np.any(obb_overlap_compiled(c, rot, h, self.box_c, self.box_r, self.box_h), -1)
            else:
                hit |= np.any(obb_overlap(c, rot, h, self.box_c, self.box_r, self.box_h), -1)
        if self.sph_c.shape[-2]:
            # distance from each obstacle sphere centre to each robot box
            d2 = sphere_box_sqdist(self.sph_c, c, rot, h)  # (*batch, K, M)
            hit |= np.any(d2 <= (self.sph_r**2)[..., :, None], -2)
        if self._has_clouds:
            for i, (ci, ri, hi) in enumerate(zip(self._per_scene(c), self._per_scene(rot), self._per_scene(h))):
                tree = self.cloud_trees[i]
                if tree is None:
                    continue
                inside = boxes_contain_cloud_points(tree, ci, ri, hi, self._cloud_margin(i))
                if self.batch_shape == ():
                    hit |= inside
                else:
                    hit[i] |= inside
        hit |= self._coal_query((c, rot, h), None, kind="box", meshes_only=False)
        return hit

    def sphere_grid(self) -> CloudGrid | None:
        """The single scene's cloud grid the compiled sphere tests read (``None``: no cloud):
        cells of four point radii, at least 2 cm (a sphere's test reads a few cells; a
        smaller cell holds few points)."""
        return self.cloud_grid(max(4.0 * self._cloud_margin(0), 0.02))

    def cloud_point_radius(self) -> float:
        """The single scene's cloud point radius (0 without a cloud)."""
        return self._cloud_margin(0)

    def _cloud_margin(self, i: int) -> float:
        return float(self.cloud_radius[i]) if i < len(self.cloud_radius) else 0.0

    def _spheres_vs_clouds(self, c: Array, r: Array) -> Bool:
        out = np.zeros(c.shape[:-1], dtype=bool)
        for i, (ci, ri) in enumerate(zip(self._per_scene(c), self._per_scene(r))):
            tree = self.cloud_trees[i] if i < len(self.cloud_trees) else None
            if tree is None:
                continue
            flat = ci.reshape(-1, self.dim)
            reach = ri.reshape(-1) + self._cloud_margin(i)  # each point is a sphere of the cloud's point radius
            reach = np.broadcast_to(reach, flat.shape[:1])
            grid = self.sphere_grid() if self.dim == 3 and self.batch_shape == () else None
            if grid is not None:  # the compiled test on the cloud's grid (the same answer)
                hits = np.empty(len(flat), dtype=bool)
                pts, starts, origin, dims, params, _ = grid
                spheres_hit_cloud_compiled(
                    np.ascontiguousarray(flat, np.float64),
                    np.ascontiguousarray(reach, np.float64),
                    pts,
                    starts,
                    origin,
                    dims,
                    params,
                    hits,
                )
                res = hits.reshape(ci.shape[:-1])
            else:
                rmax = float(reach.max()) if reach.size else 0.0
                dist, _ = tree.query(flat, k=1, distance_upper_bound=rmax + 1e-12)
                res = (dist <= reach).reshape(ci.shape[:-1])
            if self.batch_shape == ():
                out |= res
            else:
                out[i] |= res
        return out

    def _coal_query(self, q: Any, r: Array | None, kind: str, meshes_only: bool) -> Bool:
        """Slow path through coal, one pair at a time (meshes and rare pairs), after a
        bounding-sphere filter: only pairs whose bounding spheres meet are handed to coal."""
        if kind == "sphere":
            c = q
        else:
            c, rot, h = q
        shape = c.shape[:-1]
        out = np.zeros(shape, dtype=bool)
        scenes = range(1) if self.batch_shape == () else range(self.batch_shape[0])
        for i in scenes:
            items = [it for it in self.coal_items[i] if it[4] is not None or not meshes_only]
            if not items:
                continue
            ci = c if self.batch_shape == () else c[i]
            flat_c = ci.reshape(-1, ci.shape[-1])
            if kind == "sphere":
                assert r is not None
                reach = (r if self.batch_shape == () else r[i]).reshape(-1)
            else:
                roti = (rot if self.batch_shape == () else rot[i]).reshape(-1, 3, 3)
                hi = (h if self.batch_shape == () else h[i]).reshape(-1, 3)
                reach = np.linalg.norm(hi, axis=-1)
            res = np.zeros(flat_c.shape[0], dtype=bool)
            for g, tf, bc, br, mesh in items:
                near = np.flatnonzero((np.sum((flat_c - bc) ** 2, -1) <= (reach + br) ** 2) & ~res)
                if not len(near):
                    continue
                if kind == "sphere":
                    hit = np.array([coal_collide_sphere(flat_c[m], reach[m], g, tf) for m in near], dtype=bool)
                else:
                    hit = np.array([coal_collide_box(flat_c[m], roti[m], hi[m], g, tf) for m in near], dtype=bool)
                if mesh is not None:
                    # coal tests mesh surfaces only; a mesh is solid: a body deep inside it,
                    # or a mesh wholly inside the body, also collides
                    rest = near[~hit]
                    if len(rest):
                        inside = mesh_contains(mesh, flat_c[rest])
                        if kind == "sphere":
                            inside |= np.sum((flat_c[rest] - mesh.vertices[0]) ** 2, -1) <= reach[rest] ** 2
                        else:
                            inside |= sphere_box_sqdist(mesh.vertices[:1], flat_c[rest], roti[rest], hi[rest])[0] <= 0.0
                        hit[~hit] = inside
                res[near] |= hit
            res = res.reshape(ci.shape[:-1])
            if self.batch_shape == ():
                out |= res
            else:
                out[i] |= res
        return out


def _sub_boxes(c: Array, rot: Array, h: Array, cap: int = 512) -> tuple[Array, Array, NDArray[np.int64]]:
    """Cover each box ``c: (M, d)``, ``rot: (M, d, d)``, ``h: (M, d)`` by near-cubic
    pieces (each axis cut into ``ceil(h_i / min h)`` equal parts, at most ``cap`` pieces
    a box): their centres, the radius of the ball around each piece, and the box each
    piece belongs to. The balls cover the box, and hug it far closer than its own
    circumscribed ball does when it is long and thin."""
    m, d = h.shape
    counts = np.ceil(h / np.maximum(h.min(-1, keepdims=True), 1e-12) - 1e-9).astype(np.int64).clip(1, None)
    while np.any(big := counts.prod(-1) > cap):
        counts[big] = np.maximum(counts[big] // 2, 1)
    per = counts.prod(-1)
    owner = np.repeat(np.arange(m), per)
    # the piece's index along each axis, then its centre offset in the box's frame
    k = np.arange(len(owner)) - np.repeat(np.cumsum(per) - per, per)
    local = np.empty((len(owner), d))
    stride = np.ones((m, d), np.int64)
    for i in range(d - 2, -1, -1):
        stride[:, i] = stride[:, i + 1] * counts[:, i + 1]
    for i in range(d):
        n_i, h_i = counts[owner, i], h[owner, i]
        j = (k // stride[owner, i]) % n_i
        local[:, i] = -h_i + (2 * j + 1) * h_i / n_i
    centres = c[owner] + np.einsum("pij,pj->pi", rot[owner], local)
    radius = np.sqrt(np.sum((h / counts) ** 2, -1))[owner]
    return centres, radius, owner


#: at most this many cells in a cloud's grid (:func:`cloud_grid_arrays` widens its cells to fit)
_MAX_GRID_CELLS = 1 << 22


def cloud_grid_arrays(points: Array, cell: float, margin: float) -> CloudGrid:
    """A 3D cloud ``points (N, 3)`` (each point a sphere of radius ``margin``) sorted into a
    uniform grid of cubes of side ``cell`` (widened until the grid has at most
    :data:`_MAX_GRID_CELLS` cells) over its bounding box, compressed-row style: ``(points
    sorted by cell (N, 3), starts (C + 1,), origin (3,), cells per axis n (3,), params,
    prefix sums)``: cell ``(i, j, k)`` is row ``(i * n1 + j) * n2 + k`` and holds
    ``points[starts[row] : starts[row + 1]]``; a point ``p`` is in the cells ``floor((p -
    origin) * params[0])`` (the formula the kernels use to find the cells a box's bounding
    box covers); ``params``: ``1 / cell``, ``cell``, ``margin``, and a slack for round-off
    at the cloud's scale; the prefix sums ``((n0 + 1) * (n1 + 1) * (n2 + 1),)``: the points
    in the cells below each ``(i, j, k)`` (a block's count in eight reads)."""
    p = np.ascontiguousarray(points, np.float64).reshape(-1, 3)
    if not len(p) or not np.all(np.isfinite(p)):
        raise ValueError("a cloud grid takes a non-empty cloud of finite points")
    cell = float(cell)
    if not (np.isfinite(cell) and cell > 0):
        raise ValueError(f"the cell size must be a positive number, not {cell}")
    origin = p.min(0)
    extent = p.max(0) - origin
    while np.prod(np.floor(extent / cell) + 2.0) > _MAX_GRID_CELLS:
        cell *= 1.5
    inv = 1.0 / cell
    key3 = np.floor((p - origin) * inv).astype(np.int64)
    dims = key3.max(0) + 1
    key = (key3[:, 0] * dims[1] + key3[:, 1]) * dims[2] + key3[:, 2]
    order = np.argsort(key, kind="stable")
    counts = np.bincount(key, minlength=int(np.prod(dims)))
    starts = np.zeros(len(counts) + 1, np.int64)
    np.cumsum(counts, out=starts[1:])
    cum = np.zeros(tuple(dims + 1), np.int64)
    cum[1:, 1:, 1:] = counts.reshape(tuple(dims)).cumsum(0).cumsum(1).cumsum(2)
    scale = float(np.max(np.abs(p))) + float(np.max(extent)) + cell
    params = np.array([inv, cell, float(margin), 1e-9 * scale])
    return np.ascontiguousarray(p[order]), starts, np.ascontiguousarray(origin), dims, params, cum.reshape(-1)


def cloud_grid_order(points: Array, grid: CloudGrid) -> NDArray[np.int64]:
    """Where each of the grid's sorted points comes from in ``points``, the cloud the grid
    was built from (:func:`cloud_grid_arrays`: the same cells, the same stable sort)."""
    p = np.ascontiguousarray(points, np.float64).reshape(-1, 3)
    _, _, origin, dims, params, _ = grid
    key3 = np.floor((p - origin) * params[0]).astype(np.int64)
    order = np.argsort((key3[:, 0] * dims[1] + key3[:, 1]) * dims[2] + key3[:, 2], kind="stable")
    if not np.array_equal(p[order], grid[0]):
        raise ValueError("the grid was not built from these points")
    return order


def boxes_contain_cloud_points(tree: cKDTree, c: Array, rot: Array, h: Array, margin: float = 0.0) -> Bool:
    """Does any point of the cloud in ``tree`` lie within ``margin`` of (or in) each box
    ``c: (..., d)``, ``rot: (..., d, d)``, ``h: (..., d)``? Only the points near a box are tested: the
    k-d tree rules out the boxes with no point within their circumscribed ball (most, in
    free space), then finds the points in balls around near-cubic pieces of the others
    (:func:`_sub_boxes`: the nearest point first, then a ball query), and each is tested with :func:`sphere_box_sqdist`'s arithmetic against
    the box itself, so the answer is the brute-force one at a cost that grows with the
    points near the boxes, not with the cloud."""
    shape = c.shape[:-1]
    d = c.shape[-1]
    fc, fr, fh = c.reshape(-1, d), rot.reshape(-1, d, d), h.reshape(-1, d)
    out = np.zeros(len(fc), dtype=bool)
    if not len(fc) or not tree.n:
        return out.reshape(shape)
    # boxes with no point within their circumscribed ball are free: most, in free space
    reach = np.sqrt(np.sum(fh * fh, -1)) * (1.0 + 1e-9) + margin + 1e-12
    dist, _ = tree.query(fc, k=1, distance_upper_bound=float(reach.max()))
    boxes = np.flatnonzero(dist <= reach)
    if not len(boxes):
        return out.reshape(shape)
    centres, radius, piece_owner = _sub_boxes(fc[boxes], fr[boxes], fh[boxes])
    piece_owner = boxes[piece_owner]
    radius = radius * (1.0 + 1e-9) + margin + 1e-12  # a point within margin of a piece is this close to its centre
    dist, _ = tree.query(centres, k=1, distance_upper_bound=float(radius.max()))
    near = np.flatnonzero(dist <= radius)
    if not len(near):
        return out.reshape(shape)
    lists = tree.query_ball_point(centres[near], radius[near], return_sorted=False)
    counts = np.array([len(x) for x in lists], np.int64)
    idx = np.concatenate(lists).astype(np.int64) if len(lists) else np.zeros(0, np.int64)
    owner = np.repeat(piece_owner[near], counts)
    diff = tree.data[idx] - fc[owner]
    r = fr[owner]
    d2 = np.zeros(len(idx))
    for i in range(d):  # as sphere_box_sqdist: local_i = sum_j diff_j R_ji, in the same order
        local = diff[:, 0] * r[:, 0, i]
        for j in range(1, d):
            local = local + diff[:, j] * r[:, j, i]
        excess = np.maximum(np.abs(local) - fh[owner, i], 0.0)
        d2 += excess * excess
    out[owner[d2 <= margin * margin]] = True
    return out.reshape(shape)


def _bounding_sphere(s: Shape) -> tuple[Array, float]:
    """A sphere enclosing a capsule, cylinder, cone or mesh."""
    if isinstance(s, Mesh) and not len(s.vertices):
        return np.full(3, _FAR), 0.0  # nothing to hit
    if isinstance(s, Mesh):
        c = (s.vertices.min(0) + s.vertices.max(0)) / 2
        r = float(np.sqrt(np.max(np.sum((s.vertices - c) ** 2, -1))))
    elif isinstance(s, Capsule):
        c, r = (s.a + s.b) / 2, float(np.linalg.norm(s.b - s.a) / 2 + s.radius)
    elif isinstance(s, (Cylinder, Cone)):
        c, r = s.center, float(np.hypot(s.radius, s.length / 2))
    else:
        raise TypeError(f"no bounding sphere for {type(s).__name__}")
    return c, r


# ---------------------------------------------------------------------------- coal glue
def _coal() -> Any:
    import coal  # imported lazily: only meshes and rare pairs need it

    return coal


def _coal_tf(rotation: Array, translation: Array) -> Any:
    coal = _coal()
    return coal.Transform3s(np.asarray(rotation, np.float64), np.asarray(translation, np.float64))


def _coal_mesh(m: Mesh) -> tuple[Any, Any]:
    coal = _coal()
    model = coal.BVHModelOBBRSS()
    model.beginModel(len(m.faces), len(m.vertices))
    model.addVertices(np.ascontiguousarray(m.vertices, np.float64))
    model.addTriangles(np.ascontiguousarray(m.faces, np.int64))
    model.endModel()
    return model, _coal_tf(np.eye(3), np.zeros(3))


def mesh_contains(mesh: Mesh, points: Array) -> Bool:
    """Are ``points: (N, 3)`` inside the closed mesh? Generalised winding number > 1/2
    (solid angles of the triangles, Van Oosterom & Strackee), either face orientation;
    compiled (``_kernels.winding_numbers_compiled``)."""
    p = np.asarray(points, np.float64).reshape(-1, 3)
    if not len(p) or not len(mesh.faces):
        return np.zeros(len(p), dtype=bool)
    return np.abs(winding_numbers_compiled(p, mesh.vertices[mesh.faces])) > 0.5


def mesh_winding_reference(mesh: Mesh, points: Array, chunk: int = 1 << 20) -> Array:
    """The winding numbers of :func:`mesh_contains` computed with numpy (the reference the
    compiled kernel is tested against)."""
    p = np.asarray(points, np.float64).reshape(-1, 3)
    tri = mesh.vertices[mesh.faces]  # (F, 3, 3)
    out = np.zeros(len(p))
    step = max(1, chunk // max(1, len(tri)))
    for s in range(0, len(p), step):
        v = tri[None] - p[s : s + step, None, None, :]  # (n, F, 3, 3)
        a, b, c = v[..., 0, :], v[..., 1, :], v[..., 2, :]
        la, lb, lc = (np.linalg.norm(x, axis=-1) for x in (a, b, c))
        num = np.einsum("...i,...i->...", a, np.cross(b, c))
        den = la * lb * lc + np.einsum("...i,...i->...", a, b) * lc
        den += np.einsum("...i,...i->...", a, c) * lb + np.einsum("...i,...i->...", b, c) * la
        out[s : s + step] = np.sum(np.arctan2(num, den), -1) / (2.0 * np.pi)
    return out


def _coal_primitive(s: Shape) -> tuple[Any, Any]:
    coal = _coal()
    if isinstance(s, Capsule):
        axis = s.b - s.a
        length = float(np.linalg.norm(axis))
        return coal.Capsule(s.radius, length), _coal_tf(_rotation_to_z(axis), (s.a + s.b) / 2)
    if isinstance(s, Cylinder):
        return coal.Cylinder(s.radius, s.length), _coal_tf(s.rotation, s.center)
    if isinstance(s, Cone):
        return coal.Cone(s.radius, s.length), _coal_tf(s.rotation, s.center)
    raise TypeError(f"no coal fallback for {type(s).__name__}")


def _rotation_to_z(axis: Array) -> Array:
    """A rotation whose third column is ``axis`` (normalised)."""
    z = np.asarray(axis, np.float64)
    n = np.linalg.norm(z)
    z = z / n if n > 0 else np.array([0.0, 0.0, 1.0])
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.stack([x, y, z], 1)


def coal_collide_sphere(center: Array, radius: float, geom: Any, tf: Any) -> bool:
    coal = _coal()
    req, res = coal.CollisionRequest(), coal.CollisionResult()
    return bool(coal.collide(coal.Sphere(float(radius)), _coal_tf(np.eye(3), center), geom, tf, req, res))


def coal_collide_box(center: Array, rotation: Array, half: Array, geom: Any, tf: Any) -> bool:
    coal = _coal()
    req, res = coal.CollisionRequest(), coal.CollisionResult()
    box = coal.Box(*(2.0 * np.asarray(half, np.float64)))
    return bool(coal.collide(box, _coal_tf(rotation, center), geom, tf, req, res))
