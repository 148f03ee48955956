"""Batched first-hit ray casting against the obstacles of a :class:`CollisionWorld`.

``cast_rays(world, origins, directions, max_range)`` answers ``R`` rays per scene for one
scene (``world.batch_shape == ()``) or for ``E`` stacked scenes (``(E,)``) at once.

Primitives (boxes, spheres, capsules, cylinders, cones) are answered in closed form with
numpy, vectorised over (scene, ray, obstacle): no Python loop over rays or obstacles. Every
primitive is convex, so the line ``o + t d`` meets it in one interval ``[t0, t1]`` (empty
intervals are stored as ``(inf, -inf)``):

* boxes: slab method in the box frame;
* spheres: the quadratic, in the precise form ``disc = r^2 - |oc - (oc.d) d|^2``;
* cylinders: infinite cylinder (quadratic in the local xy plane) intersected with the slab
  ``|z| <= half``;
* cones: the solid lower nappe ``rho <= k (half - z)`` (a quadratic inequality intersected
  with the half-line ``z <= half``), intersected with the base half-space ``z >= -half``;
* capsules: hull of the intervals of the two end spheres and of the finite cylinder body.

The first hit is ``max(t0, 0)`` when ``t1 >= 0``, minimised over all obstacles.

Meshes go through trimesh's embree ray caster (``embreex``; trimesh's pure-numpy caster if
embree is missing): one first-hit query per scene for all of its meshes, concatenated into
one trimesh that is cached by the identities of the scene's ``Mesh`` objects.

Conventions
-----------
* Rays whose origin lies in a solid obstacle (closed set: the surface counts) hit at
  distance ``0`` with normal ``-direction``. For meshes "inside" is decided by the first hit
  face: a watertight, consistently wound mesh is oriented outward once (by the sign of its
  volume), and a first hit on a face whose outward normal points along the ray means the
  ray starts inside. Open or inconsistently wound meshes are surfaces only (no inside).
  Meshes of one scene are cast as one mesh; an origin inside a solid mesh A whose first
  hit is on another mesh B (B overlapping A, or nested in it) is found by a winding-number
  test of the origin against every solid mesh, and reports distance 0 too.
* Missed rays (nothing within ``max_range``): ``distance = inf``, ``hit = False`` and
  ``points``/``normals`` are **nan**.
* Normals are unit outward surface normals at the hit, flipped where needed so that
  ``dot(normal, direction) <= 0``. On box edges and cylinder/cone rims the normal is that
  of the face the ray enters through.
* Point clouds of the world (``cloud_trees``) are surfaces sampled by points: each point
  stands for a small sphere (``PointCloud.point_radius``: by default
  :data:`~pointplan.geometry.shapes.SPLAT_FACTOR` times the cloud's median
  nearest-neighbour spacing, so that a ray does not slip between the points of a sampled
  surface), and a ray hits the
  first such sphere it enters, with that point's normal (:func:`_cloud_hits`). A ray has
  no inside of a cloud to start in.
* Degenerate primitives (zero-size boxes, zero radius or length) are ignored; this is also
  how the padding of stacked worlds (far away, zero size) drops out.
* Only 3D worlds are supported (``ValueError`` otherwise).
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray

from ._kernels import ray_box_compiled
from .collision import CollisionWorld
from .shapes import Mesh

Array = NDArray[np.float64]
Bool = NDArray[np.bool_]
Int = NDArray[np.int64]

_INF = np.inf
#: direction components (of unit vectors) below this count as parallel to a slab/axis
_PAR = 1e-15
#: scene x ray x obstacle entries evaluated at once per primitive group (memory bound)
_CHUNK = 1 << 17
#: scenes' concatenated meshes kept with their ray intersectors
_MESH_CACHE_SIZE = 32

_GROUPS = ("box", "sphere", "capsule", "cylinder", "cone")


@dataclass(frozen=True)
class RayHits:
    """First hits of rays ``(*batch, R)``.

    ``distance``: along the (normalised) ray, ``inf`` where nothing is hit within range;
    ``points``: world hit points, nan where missed; ``normals``: unit outward normals facing
    the ray (``-direction`` for rays starting inside an obstacle), nan where missed;
    ``hit``: bool.
    """

    distance: Array
    points: Array
    normals: Array
    hit: Bool


# ---------------------------------------------------------------------------- intervals
def _slab(o: Array, d: Array, lo: Array | float, hi: Array | float) -> tuple[Array, Array]:
    """Parameters ``t`` with ``lo <= o + t d <= hi`` as an interval (``(inf, -inf)`` if
    empty); ``d`` is a component of a unit vector."""
    par = np.abs(d) < _PAR
    inv = 1.0 / np.where(par, 1.0, d)
    ta, tb = (lo - o) * inv, (hi - o) * inv
    inside = (o >= lo) & (o <= hi)
    t0 = np.where(par, np.where(inside, -_INF, _INF), np.minimum(ta, tb))
    t1 = np.where(par, np.where(inside, _INF, -_INF), np.maximum(ta, tb))
    return t0, t1


def _roots(a: Array, b: Array, c: Array, sq: Array) -> tuple[Array, Array]:
    """Sorted roots of ``a t^2 + 2 b t + c`` given ``sq = sqrt(b^2 - a c)`` (a != 0), in the
    cancellation-free form ``q = -(b + sign(b) sq)``, roots ``q / a`` and ``c / q``."""
    q = -(b + np.copysign(sq, b))
    ra = q / a
    qz = q == 0.0
    rb = np.where(qz, ra, c / np.where(qz, 1.0, q))
    return np.minimum(ra, rb), np.maximum(ra, rb)


def _convex_quadratic(a: Array, b: Array, c: Array, disc: Array) -> tuple[Array, Array]:
    """``{t : a t^2 + 2 b t + c <= 0}`` for ``a >= 0`` (sphere, infinite cylinder), given the
    discriminant ``disc = b^2 - a c`` (computed by the caller in a precise form)."""
    par = a <= 1e-18
    safe_a = np.where(par, 1.0, a)
    r0, r1 = _roots(safe_a, b, c, np.sqrt(np.maximum(disc, 0.0)))
    miss = disc < 0.0
    t0 = np.where(par, np.where(c <= 0.0, -_INF, _INF), np.where(miss, _INF, r0))
    t1 = np.where(par, np.where(c <= 0.0, _INF, -_INF), np.where(miss, -_INF, r1))
    return t0, t1


def _meet(*ivs: tuple[Array, Array]) -> tuple[Array, Array]:
    """Intersection of intervals, empty ones normalised to ``(inf, -inf)``."""
    t0 = ivs[0][0]
    t1 = ivs[0][1]
    for lo, hi in ivs[1:]:
        t0, t1 = np.maximum(t0, lo), np.minimum(t1, hi)
    empty = t0 > t1
    return np.where(empty, _INF, t0), np.where(empty, -_INF, t1)


def _dot(x: Array, y: Array) -> Array:
    return x[..., 0] * y[..., 0] + x[..., 1] * y[..., 1] + x[..., 2] * y[..., 2]


def _to_local(o: Array, d: Array, c: Array, rot: Array) -> tuple[Array, Array]:
    """Ray origins/directions ``(B, r, 3)`` in the frames of obstacles ``c: (B, K, 3)``,
    ``rot: (B, K, 3, 3)`` (columns = local axes): ``(B, r, K, 3)`` each, by two matrix
    products ``(B, r, 3) @ (B, 3, 3K)``."""
    nb, nk = rot.shape[:2]
    flat = rot.transpose(0, 2, 1, 3).reshape(nb, 3, 3 * nk)  # [b, j, 3k + i] = R[b, k, j, i]
    c_local = np.einsum("bkj,bkji->bki", c, rot)
    ol = (o @ flat).reshape(nb, -1, nk, 3) - c_local[:, None]
    dl = (d @ flat).reshape(nb, -1, nk, 3)
    return ol, dl


def _frames_z(axis: Array) -> Array:
    """Rotations ``(..., 3, 3)`` whose third column is ``axis (..., 3)`` (unit, or zero: z)."""
    z = np.where((np.abs(axis).sum(-1) > 0)[..., None], axis, [0.0, 0.0, 1.0])
    helper = np.where((np.abs(z[..., 0]) < 0.9)[..., None], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x, axis=-1, keepdims=True)
    return np.stack([x, np.cross(z, x), z], -1)


def _sphere_iv(oc: Array, d: Array, r: Array) -> tuple[Array, Array]:
    """Interval of rays with ``oc = o - c: (..., 3)``, unit ``d`` (broadcast) in spheres."""
    b = _dot(oc, d)
    perp = oc - b[..., None] * d
    disc = r * r - _dot(perp, perp)
    return _convex_quadratic(np.ones_like(b), b, _dot(oc, oc) - r * r, disc)


def _disc_iv(ox: Array, oy: Array, dx: Array, dy: Array, r: Array) -> tuple[Array, Array]:
    """Interval of rays (local xy components) in the infinite cylinder ``x^2 + y^2 <= r^2``."""
    qa = dx * dx + dy * dy
    qb = ox * dx + oy * dy
    qc = ox * ox + oy * oy - r * r
    cross = ox * dy - oy * dx
    return _convex_quadratic(qa, qb, qc, qa * r * r - cross * cross)


# ------------------------------------------------------------------------ primitive groups
# Each returns t0, t1: (B, r, K) and an int8 "part" code (which face the ray enters by).
def _box(o: Array, d: Array, g: dict[str, Array]) -> tuple[Array, Array, NDArray[np.int8]]:
    return ray_box_compiled(o, d, g["box_c"], g["box_r"], g["box_h"])


def box_slabs_reference(o: Array, d: Array, g: dict[str, Array]) -> tuple[Array, Array, NDArray[np.int8]]:
    """The slab test of ``_box`` in numpy: the reference the compiled kernel (about 10x
    faster) is tested against."""
    ol, dl = _to_local(o, d, g["box_c"], g["box_r"])
    h = g["box_h"][:, None]
    # slabs; a direction component of 0 gives inv = +-inf and so infinite bounds, or nan
    # (0 * inf) for a ray in a slab's boundary plane: that ray is in the closed slab
    inv = 1.0 / dl
    ta, tb = (-h - ol) * inv, (h - ol) * inv
    lo = np.nan_to_num(np.minimum(ta, tb), copy=False, nan=-_INF, posinf=_INF, neginf=-_INF)
    hi = np.nan_to_num(np.maximum(ta, tb), copy=False, nan=_INF, posinf=_INF, neginf=-_INF)
    # reductions over the last axis of length 3, written out (numpy's are slow there)
    t0 = lo[..., 0]
    axis = np.zeros(t0.shape, np.int8)
    for i in (1, 2):
        later = lo[..., i] > t0
        axis[later] = i
        t0 = np.where(later, lo[..., i], t0)
    t1 = np.minimum(np.minimum(hi[..., 0], hi[..., 1]), hi[..., 2])
    t0, t1 = _meet((t0, t1))
    return t0, t1, axis


def _sphere(o: Array, d: Array, g: dict[str, Array]) -> tuple[Array, Array, NDArray[np.int8]]:
    oc = o[:, :, None, :] - g["sph_c"][:, None, :, :]
    t0, t1 = _sphere_iv(oc, d[:, :, None, :], g["sph_r"][:, None, :])
    return t0, t1, np.zeros(t0.shape, np.int8)


def _capsule(o: Array, d: Array, g: dict[str, Array]) -> tuple[Array, Array, NDArray[np.int8]]:
    a, b, r = g["cap_a"], g["cap_b"], g["cap_r"][:, None, :]
    axis = b - a
    length = np.sqrt(_dot(axis, axis))  # (B, K)
    flat = length <= 1e-12
    u = axis / np.where(flat, 1.0, length)[..., None]
    ol, dl = _to_local(o, d, a, _frames_z(np.where(flat[..., None], 0.0, u)))  # a at 0, b at z = L
    ox, oy, oz = ol[..., 0], ol[..., 1], ol[..., 2]
    dx, dy, dz = dl[..., 0], dl[..., 1], dl[..., 2]
    ln = length[:, None, :]
    body = _meet(_disc_iv(ox, oy, dx, dy, r), _slab(oz, dz, 0.0, ln))
    ca = _sphere_iv(ol, dl, r)
    ol[..., 2] -= ln
    cb = _sphere_iv(ol, dl, r)
    t0 = np.minimum(np.minimum(np.where(flat[:, None, :], _INF, body[0]), ca[0]), cb[0])
    t1 = np.maximum(np.maximum(body[1], ca[1]), cb[1])
    return t0, t1, np.zeros(t0.shape, np.int8)


def _cylinder(o: Array, d: Array, g: dict[str, Array]) -> tuple[Array, Array, NDArray[np.int8]]:
    ol, dl = _to_local(o, d, g["cyl_c"], g["cyl_r"])
    r, h = g["cyl_rad"][:, None, :], g["cyl_half"][:, None, :]
    side = _disc_iv(ol[..., 0], ol[..., 1], dl[..., 0], dl[..., 1], r)
    caps = _slab(ol[..., 2], dl[..., 2], -h, h)
    t0, t1 = _meet(side, caps)
    return t0, t1, (caps[0] > side[0]).astype(np.int8)  # 1: enters through a cap


def _cone(o: Array, d: Array, g: dict[str, Array]) -> tuple[Array, Array, NDArray[np.int8]]:
    ol, dl = _to_local(o, d, g["con_c"], g["con_r"])
    ox, oy, oz = ol[..., 0], ol[..., 1], ol[..., 2]
    dx, dy, dz = dl[..., 0], dl[..., 1], dl[..., 2]
    h = g["con_half"][:, None, :]
    k = g["con_rad"][:, None, :] / np.maximum(2.0 * h, 1e-300)
    k2 = k * k
    zeta = h - oz  # height below the apex; the lower nappe is rho <= k * zeta, zeta >= 0
    qa = dx * dx + dy * dy - k2 * dz * dz
    qb = ox * dx + oy * dy + k2 * zeta * dz
    qc = ox * ox + oy * oy - k2 * zeta * zeta
    disc = qb * qb - qa * qc
    sq = np.sqrt(np.maximum(disc, 0.0))
    eps = 1e-12 * (1.0 + k2)
    pos, neg = qa > eps, qa < -eps
    lin = ~(pos | neg)
    r0, r1 = _roots(np.where(lin, 1.0, qa), qb, qc, sq)
    miss = disc < 0.0
    # {f <= 0} as the union of two intervals I1, I2
    # a > 0: [r0, r1] or empty; a < 0: (-inf, r0] u [r1, inf) or everything;
    # a = 0: the half-line 2 b t + c <= 0
    lb = np.abs(qb) > 1e-300
    root_lin = -qc / np.where(lb, 2.0 * qb, 1.0)
    i1_0 = np.where(pos, np.where(miss, _INF, r0), -_INF)
    i1_1 = np.where(pos, np.where(miss, -_INF, r1), np.where(neg, np.where(miss, _INF, r0), _INF))
    i2_0 = np.where(neg & ~miss, r1, _INF)
    i2_1 = np.where(neg & ~miss, _INF, -_INF)
    lin0 = np.where(lb, np.where(qb > 0, -_INF, root_lin), np.where(qc <= 0, -_INF, _INF))
    lin1 = np.where(lb, np.where(qb > 0, root_lin, _INF), np.where(qc <= 0, _INF, -_INF))
    i1_0, i1_1 = np.where(lin, lin0, i1_0), np.where(lin, lin1, i1_1)
    below_apex = _slab(oz, dz, -_INF, h)
    p1, p2 = _meet((i1_0, i1_1), below_apex), _meet((i2_0, i2_1), below_apex)
    nappe = (np.minimum(p1[0], p2[0]), np.maximum(p1[1], p2[1]))
    base = _slab(oz, dz, -h, _INF)
    t0, t1 = _meet(nappe, base)
    return t0, t1, (base[0] > nappe[0]).astype(np.int8)  # 1: enters through the base


def _group_arrays(world: CollisionWorld, name: str, nb: int) -> dict[str, Array]:
    """The group's world arrays reshaped to a flat scene axis ``(B, K, ...)``."""
    fields = {
        "box": ("box_c", "box_r", "box_h"),
        "sphere": ("sph_c", "sph_r"),
        "capsule": ("cap_a", "cap_b", "cap_r"),
        "cylinder": ("cyl_c", "cyl_r", "cyl_rad", "cyl_half"),
        "cone": ("con_c", "con_r", "con_rad", "con_half"),
    }[name]
    nd = len(world.batch_shape)
    out = {}
    for f in fields:
        x = np.asarray(getattr(world, f), np.float64)
        out[f] = x.reshape((nb,) + x.shape[nd:])
    return out


def _valid(name: str, g: dict[str, Array]) -> Bool:
    """Non-degenerate obstacles ``(B, K)`` (padding of stacked worlds has zero size)."""
    if name == "box":
        return np.any(g["box_h"] > 0, -1)
    if name == "sphere":
        return g["sph_r"] > 0
    if name == "capsule":
        return g["cap_r"] > 0
    if name == "cylinder":
        return (g["cyl_rad"] > 0) & (g["cyl_half"] > 0)
    return (g["con_rad"] > 0) & (g["con_half"] > 0)


_KERNELS = {"box": _box, "sphere": _sphere, "capsule": _capsule, "cylinder": _cylinder, "cone": _cone}


def _normals(name: str, g: dict[str, Array], bi: Int, ki: Int, part: NDArray[np.int8], p: Array) -> Array:
    """Outward normals ``(n, 3)`` at hit points ``p`` on obstacles ``(bi, ki)``."""
    if name == "box":
        return g["box_r"][bi, ki, :, part.astype(np.int64)]
    if name == "sphere":
        return p - g["sph_c"][bi, ki]
    if name == "capsule":
        a, b = g["cap_a"][bi, ki], g["cap_b"][bi, ki]
        ab = b - a
        t = np.clip(_dot(p - a, ab) / np.maximum(_dot(ab, ab), 1e-300), 0.0, 1.0)
        return p - (a + t[:, None] * ab)
    pre = "cyl" if name == "cylinder" else "con"
    rot = g[f"{pre}_r"][bi, ki]  # (n, 3, 3)
    local = np.einsum("nji,nj->ni", rot, p - g[f"{pre}_c"][bi, ki])
    rho = np.hypot(local[:, 0], local[:, 1])
    safe = np.where(rho > 0, rho, 1.0)
    radial = rot[:, :, 0] * (local[:, 0] / safe)[:, None] + rot[:, :, 1] * (local[:, 1] / safe)[:, None]
    z = rot[:, :, 2]
    if name == "cylinder":
        side = radial
        cap = z * np.where(local[:, 2] >= 0, 1.0, -1.0)[:, None]
    else:
        k = (g["con_rad"][bi, ki] / (2.0 * g["con_half"][bi, ki]))[:, None]
        side = np.where((rho > 0)[:, None], radial + k * z, z)
        cap = -z
    return np.where((part == 1)[:, None], cap, side)


# ---------------------------------------------------------------------------- meshes
@dataclass
class _MeshSet:
    meshes: tuple[Mesh, ...]  # keeps the keyed objects alive, so their ids stay unique
    intersector: Any
    normals: Array  # (F, 3) face normals, outward for solid meshes
    solid: Bool  # (F,) face belongs to a watertight, consistently wound mesh
    solids: tuple[Mesh, ...] = ()  # the solid meshes (for the inside test of origins)


_mesh_cache: OrderedDict[tuple[int, ...], _MeshSet] = OrderedDict()


def _intersector_class() -> Any:
    try:
        from trimesh.ray.ray_pyembree import RayMeshIntersector
    except ImportError:  # pragma: no cover - embreex is a dependency here
        from trimesh.ray.ray_triangle import RayMeshIntersector  # type: ignore[assignment]
    return RayMeshIntersector


def _mesh_set(meshes: Sequence[Mesh]) -> _MeshSet:
    """The scene's meshes as one trimesh with a ray intersector (cached)."""
    import trimesh

    key = tuple(id(m) for m in meshes)
    entry = _mesh_cache.get(key)
    if entry is not None and all(x is y for x, y in zip(entry.meshes, meshes)):
        _mesh_cache.move_to_end(key)
        return entry
    parts, solid = [], []
    for m in meshes:
        tm = trimesh.Trimesh(m.vertices, m.faces, process=True)
        closed = bool(tm.is_watertight and tm.is_winding_consistent)
        if closed and tm.volume < 0:
            tm.invert()
        parts.append(tm)
        solid.append(np.full(len(tm.faces), closed))
    combined: Any = parts[0] if len(parts) == 1 else trimesh.util.concatenate(parts)
    intersector = _intersector_class()(combined)
    intersector.intersects_first(np.zeros((1, 3)), np.array([[1.0, 0.0, 0.0]]))  # build now
    normals = np.asarray(combined.face_normals, np.float64)
    solids = tuple(m for m, flags in zip(meshes, solid) if flags.size and flags[0])
    entry = _MeshSet(tuple(meshes), intersector, normals, np.concatenate(solid), solids)
    _mesh_cache[key] = entry
    while len(_mesh_cache) > _MESH_CACHE_SIZE:
        _mesh_cache.popitem(last=False)
    return entry


def _cast_meshes(meshes: Sequence[Mesh], o: Array, d: Array) -> tuple[Int, Array, Array, Bool]:
    """First mesh hits of rays ``(n, 3)``: ray indices, distances, normals (outward where
    known), and whether the ray starts inside a solid mesh.

    A ray starts inside when its first hit leaves a solid mesh (the hit face's outward
    normal points along the ray) or when its origin is inside any solid mesh by the winding
    number: with overlapping meshes the first hit may belong to another mesh than the one
    the origin is in. Rays starting inside are reported (distance 0) even if they hit
    nothing."""
    from .collision import mesh_contains

    ms = _mesh_set(meshes)
    tri, ray, loc = ms.intersector.intersects_id(o, d, multiple_hits=False, return_locations=True)
    tri, ray = np.asarray(tri, np.int64), np.asarray(ray, np.int64)
    t = np.maximum(_dot(np.asarray(loc, np.float64) - o[ray], d[ray]), 0.0)
    n = ms.normals[tri]
    inside = ms.solid[tri] & (_dot(n, d[ray]) > 0)
    if ms.solids and len(o):
        uniq, back = np.unique(o, axis=0, return_inverse=True)  # rays share few origins
        within = np.zeros(len(uniq), bool)
        for m in ms.solids:
            within |= mesh_contains(m, uniq)
        start_in = within[back.reshape(-1)]
        inside |= start_in[ray]
        lost = np.setdiff1d(np.flatnonzero(start_in), ray)  # inside, yet no face was hit
        if len(lost):
            ray = np.concatenate([ray, lost])
            t = np.concatenate([t, np.zeros(len(lost))])
            n = np.concatenate([n, -d[lost]])
            inside = np.concatenate([inside, np.ones(len(lost), bool)])
    return ray, t, n, inside


# ---------------------------------------------------------------------------- main
def cast_rays(world: CollisionWorld, origins: Array, directions: Array, max_range: float = np.inf) -> RayHits:
    """First hits of rays against all obstacles of each scene.

    ``origins, directions: (*batch, R, 3)`` with ``*batch == world.batch_shape``
    (``directions`` may be anything broadcastable to that, e.g. ``(R, 3)``; it is
    normalised). Hits farther than ``max_range`` are dropped. See the module docstring for
    the conventions (rays from inside, misses, normals, point clouds).
    """
    batch, o, d, max_range = _checked_rays(world, origins, directions, max_range)
    nb = int(np.prod(batch, dtype=np.int64))
    n_rays = o.shape[-2]
    o2, d2 = o.reshape(nb, n_rays, 3), d.reshape(nb, n_rays, 3)
    best, inside, normal = _primitive_hits(world, o2, d2)
    _mesh_hits(world, o2, d2, best, inside, normal)
    _cloud_hits(world, o2, d2, best, inside, normal, max_range)
    hit = np.isfinite(best) & (best <= max_range)
    inside &= hit
    normal[inside] = -d2[inside]
    nn = np.linalg.norm(normal, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        normal = np.where(nn > 0, normal / nn, -d2)
    flip = _dot(normal, d2) > 0
    normal[flip] = -normal[flip]
    dist = np.where(hit, best, _INF)
    points = np.where(hit[..., None], o2 + np.where(hit, best, 0.0)[..., None] * d2, np.nan)
    normal[~hit] = np.nan
    shape = batch + (n_rays,)
    return RayHits(dist.reshape(shape), points.reshape(shape + (3,)), normal.reshape(shape + (3,)), hit.reshape(shape))


def _checked_rays(
    world: CollisionWorld, origins: Array, directions: Array, max_range: float
) -> tuple[tuple[int, ...], Array, Array, float]:
    """The batch shape, origins and unit directions (broadcast to the origins' shape) and the
    range, checked."""
    if world.dim != 3:
        raise ValueError(f"ray casting needs a 3D world, got dim={world.dim}")
    batch = tuple(world.batch_shape)
    o = np.asarray(origins, np.float64)
    if o.ndim != len(batch) + 2 or o.shape[: len(batch)] != batch or o.shape[-1] != 3:
        raise ValueError(f"origins must have shape {batch + ('R', 3)}, got {o.shape}")
    d = np.broadcast_to(np.asarray(directions, np.float64), o.shape)
    norm = np.linalg.norm(d, axis=-1, keepdims=True)
    if not np.all(np.isfinite(norm) & (norm > 0)) or not np.all(np.isfinite(o)):
        raise ValueError("origins must be finite and directions finite and non-zero")
    max_range = float(max_range)
    if not max_range >= 0:
        raise ValueError("max_range must be >= 0")
    return batch, o, d / norm, max_range


def _primitive_hits(world: CollisionWorld, o2: Array, d2: Array) -> tuple[Array, NDArray[np.bool_], Array]:
    """Nearest entry of rays ``(B, R, 3)`` into the primitive obstacles: distance (inf on a
    miss), whether the ray starts inside, and the normal there (nan when unknown)."""
    nb, n_rays = o2.shape[:2]
    best = np.full((nb, n_rays), _INF)
    inside = np.zeros((nb, n_rays), bool)
    normal = np.full((nb, n_rays, 3), np.nan)
    groups = {}
    for name in _GROUPS:
        g = _group_arrays(world, name, nb)
        valid = _valid(name, g)
        if valid.any():
            groups[name] = (g, valid)
    who = np.full((nb, n_rays), -1, np.int8)
    kbest = np.zeros((nb, n_rays), np.int64)
    pbest = np.zeros((nb, n_rays), np.int8)
    if groups and n_rays:
        kmax = max(v.shape[1] for _, v in groups.values())
        step = max(1, _CHUNK // max(1, nb * kmax))
        for s in range(0, n_rays, step):
            sl = slice(s, min(n_rays, s + step))
            for gi, name in enumerate(_GROUPS):
                if name not in groups:
                    continue
                g, valid = groups[name]
                with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
                    t0, t1, part = _KERNELS[name](o2[:, sl], d2[:, sl], g)
                ok = valid[:, None, :] & (t1 >= 0.0) & (t0 <= t1)
                t = np.where(ok, np.maximum(t0, 0.0), _INF)
                k = np.argmin(t, -1)
                tk = np.take_along_axis(t, k[..., None], -1)[..., 0]
                better = tk < best[:, sl]
                if not better.any():
                    continue
                t0k = np.take_along_axis(t0, k[..., None], -1)[..., 0]
                pk = np.take_along_axis(part, k[..., None], -1)[..., 0]
                best[:, sl] = np.where(better, tk, best[:, sl])
                inside[:, sl] = np.where(better, t0k < 0.0, inside[:, sl])
                who[:, sl] = np.where(better, gi, who[:, sl])
                kbest[:, sl] = np.where(better, k, kbest[:, sl])
                pbest[:, sl] = np.where(better, pk, pbest[:, sl])
        for gi, name in enumerate(_GROUPS):
            sel = (who == gi) & ~inside
            if name not in groups or not sel.any():
                continue
            bi, ri = np.nonzero(sel)
            p = o2[bi, ri] + best[bi, ri, None] * d2[bi, ri]
            normal[bi, ri] = _normals(name, groups[name][0], bi, kbest[bi, ri], pbest[bi, ri], p)
    return best, inside, normal


def _mesh_hits(
    world: CollisionWorld, o2: Array, d2: Array, best: Array, inside: NDArray[np.bool_], normal: Array
) -> None:
    """Bring ``best``, ``inside`` and ``normal`` (from the primitives) up to date with the
    meshes: one first-hit query per scene over all of its meshes."""
    for b in range(o2.shape[0]):
        meshes = [m for m in (world.meshes[b] if b < len(world.meshes) else []) if len(m.faces)]
        todo = np.flatnonzero(best[b] > 0.0)
        if not meshes or not len(todo):
            continue
        ray, t, n, ins = _cast_meshes(meshes, o2[b, todo], d2[b, todo])
        t = np.where(ins, 0.0, t)
        closer = t < best[b, todo[ray]]
        ray, t, n, ins = ray[closer], t[closer], n[closer], ins[closer]
        r_idx = todo[ray]
        best[b, r_idx] = t
        inside[b, r_idx] = ins
        normal[b, r_idx] = n


@numba.njit(cache=True, nogil=True)
def _first_cloud_hits(o, d, pts, radius, best, which):  # type: ignore[no-untyped-def]
    """For each ray ``(o[i], d[i])`` (unit ``d``), the entry distance into the nearest of
    the spheres of ``radius`` around ``pts`` closer than ``best[i]``: updates ``best`` and
    ``which`` (the point's index) in place."""
    for i in range(o.shape[0]):
        bi = best[i]
        for k in range(pts.shape[0]):
            te = sphere_entry(pts, k, o[i], d[i], radius, bi)
            if 0.0 <= te < bi:
                bi = te
                which[i] = k
        best[i] = bi


@numba.njit(cache=True, nogil=True, inline="always")
def sphere_entry(pts, k, o, d, radius, best):  # type: ignore[no-untyped-def]
    """Where the ray ``(o, d)`` (unit ``d``) enters the sphere of ``radius`` around
    ``pts[k]`` (0 from inside it), or -1 where it misses the sphere, the sphere lies
    behind the origin, or the entry is surely beyond ``best``."""
    px, py, pz = pts[k, 0] - o[0], pts[k, 1] - o[1], pts[k, 2] - o[2]
    t = px * d[0] + py * d[1] + pz * d[2]
    if t + radius < 0.0 or t - radius > best:
        return -1.0
    q2 = px * px + py * py + pz * pz - t * t
    r2 = radius * radius
    if q2 > r2:
        return -1.0
    half = np.sqrt(r2 - q2)
    if t + half < 0.0:  # the sphere lies behind the origin
        return -1.0
    return max(t - half, 0.0)


def _cloud_hits(
    world: CollisionWorld, o2: Array, d2: Array, best: Array, inside: NDArray[np.bool_], normal: Array, max_range: float
) -> None:
    """Bring ``best``, ``inside`` and ``normal`` up to date with the scenes' point clouds
    (see the module docstring): only the points within reach of the rays are tried (one
    k-d tree query per scene)."""
    for b in range(o2.shape[0]):
        tree = world.cloud_trees[b] if b < len(world.cloud_trees) else None
        if tree is None or not tree.n or not o2.shape[1]:
            continue
        radius = world.cloud_radius[b] if b < len(world.cloud_radius) else 0.0
        centre = o2[b].mean(0)
        spread = float(np.sqrt(np.max(np.sum((o2[b] - centre) ** 2, -1))))
        reach = spread + max_range + radius
        # (in the cloud's order: of equally near points the first one's normal is taken)
        cand = (
            np.sort(np.asarray(tree.query_ball_point(centre, reach), np.int64))
            if np.isfinite(reach)
            else np.arange(tree.n)
        )
        if not len(cand):
            continue
        nb = best[b].copy()
        which = np.full(o2.shape[1], -1, np.int64)
        _first_cloud_hits(
            np.ascontiguousarray(o2[b]),
            np.ascontiguousarray(d2[b]),
            np.ascontiguousarray(tree.data[cand]),
            radius,
            nb,
            which,
        )
        got = which >= 0
        if not got.any():
            continue
        best[b, got] = nb[got]
        inside[b, got] = False
        nrm = world.cloud_normals[b] if b < len(world.cloud_normals) else None
        normal[b, got] = nrm[cand[which[got]]] if nrm is not None else np.nan


__all__ = ["RayHits", "cast_rays"]
