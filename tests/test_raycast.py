"""Ray casting (``pointplan.geometry.raycast``): hit points on the surfaces, first hits,
normals, agreement with trimesh on tessellated primitives, max_range, batching, rays from
inside, meshes and their cache.

The oracle for the primitives is the exact distance to the solid obstacles from the
collision kernels (zero inside): a hit point is at distance ~0, a point slightly before it
along the ray is outside, a point slightly after it (for rays aimed into the obstacle)
inside, and ``p + delta * normal`` is at distance ``delta`` from a convex obstacle exactly
when ``normal`` is an outward normal at ``p``.
"""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

from pointplan.geometry import raycast
from pointplan.geometry.collision import (
    CollisionWorld,
    point_cone_sqdist,
    point_cylinder_sqdist,
    point_segment_sqdist,
    sphere_box_sqdist,
    sphere_sphere_sqdist,
)
from pointplan.geometry.raycast import RayHits, cast_rays
from pointplan.geometry.shapes import (
    Box,
    Capsule,
    Cone,
    Cylinder,
    Mesh,
    PointCloud,
    Sphere,
)

KINDS = ["box", "sphere", "capsule", "cylinder", "cone"]


# ============================================================================ helpers
def unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


def random_shape(kind: str, rng: np.random.Generator, spread: float = 1.0):
    c = rng.uniform(-spread, spread, 3)
    rot = random_rotation(rng)
    if kind == "box":
        return Box(c, rng.uniform(0.2, 1.0, 3), rot)
    if kind == "sphere":
        return Sphere(c, rng.uniform(0.1, 0.6))
    if kind == "capsule":
        return Capsule(c, c + unit(rng.normal(size=3)) * rng.uniform(0.2, 1.0), rng.uniform(0.1, 0.4))
    if kind == "cylinder":
        return Cylinder(c, rng.uniform(0.1, 0.6), rng.uniform(0.2, 1.5), rot)
    return Cone(c, rng.uniform(0.1, 0.6), rng.uniform(0.2, 1.5), rot)


def world_of(shapes) -> CollisionWorld:
    return CollisionWorld.from_shapes(list(shapes), 3)


def solid_dist(w: CollisionWorld, p: np.ndarray) -> np.ndarray:
    """Distance from points ``(M, 3)`` to the union of the primitives of a single-scene
    world (0 inside), from the collision kernels."""
    out = np.full(len(p), np.inf)
    if len(w.box_c):
        out = np.minimum(out, np.sqrt(sphere_box_sqdist(p, w.box_c, w.box_r, w.box_h).min(-1)))
    if len(w.sph_c):
        out = np.minimum(out, np.maximum(np.sqrt(sphere_sphere_sqdist(p, w.sph_c)) - w.sph_r, 0).min(-1))
    if len(w.cap_a):
        d = np.sqrt(point_segment_sqdist(p, w.cap_a, w.cap_b)) - w.cap_r
        out = np.minimum(out, np.maximum(d, 0).min(-1))
    if len(w.cyl_c):
        d2 = point_cylinder_sqdist(p, w.cyl_c, w.cyl_r, w.cyl_rad, w.cyl_half)
        out = np.minimum(out, np.sqrt(d2.min(-1)))
    if len(w.con_c):
        d2 = point_cone_sqdist(p, w.con_c, w.con_r, w.con_rad, w.con_half)
        out = np.minimum(out, np.sqrt(d2.min(-1)))
    return out


def inside_points(w: CollisionWorld, n: int, rng: np.random.Generator, lo: float = -2.5, hi: float = 2.5) -> np.ndarray:
    """``n`` random points strictly inside the world's obstacles (rejection sampling)."""
    pts = []
    while sum(len(x) for x in pts) < n:
        cand = rng.uniform(lo, hi, (20000, 3))
        pts.append(cand[solid_dist(w, cand) == 0.0])
    return np.concatenate(pts)[:n]


def sphere_origins(n: int, rng: np.random.Generator, radius: float = 5.0) -> np.ndarray:
    return unit(rng.normal(size=(n, 3))) * radius


def mesh_of(shape) -> trimesh.Trimesh:
    """A fine tessellation of a primitive, in the world frame."""
    if isinstance(shape, Box):
        tf = np.eye(4)
        tf[:3, :3], tf[:3, 3] = shape.rotation, shape.center
        return trimesh.creation.box(extents=shape.size, transform=tf)
    if isinstance(shape, Sphere):
        m = trimesh.creation.icosphere(subdivisions=5, radius=shape.radius)
        m.apply_translation(shape.center)
        return m
    if isinstance(shape, Capsule):
        axis = shape.b - shape.a
        m = trimesh.creation.capsule(height=np.linalg.norm(axis), radius=shape.radius, count=[96, 96])
        tf = trimesh.geometry.align_vectors([0, 0, 1], axis)
        tf[:3, 3] = (shape.a + shape.b) / 2
        m.apply_transform(tf)
        return m
    tf = np.eye(4)
    tf[:3, :3], tf[:3, 3] = shape.rotation, shape.center
    if isinstance(shape, Cylinder):
        return trimesh.creation.cylinder(shape.radius, shape.length, sections=256, transform=tf)
    m = trimesh.creation.cone(shape.radius, shape.length, sections=256)
    m.apply_translation([0, 0, -shape.length / 2])  # trimesh: base at z = 0
    m.apply_transform(tf)
    return m


def check_normals(h: RayHits, d: np.ndarray) -> None:
    n = h.normals[h.hit]
    np.testing.assert_allclose(np.linalg.norm(n, axis=-1), 1.0, atol=1e-9)
    assert np.all(np.einsum("ij,ij->i", n, unit(d)[h.hit]) <= 1e-12)


# ============================================================================ primitives
@pytest.mark.parametrize("kind", KINDS)
def test_primitive_hits_on_surface(kind: str) -> None:
    rng = np.random.default_rng(KINDS.index(kind))
    for _ in range(4):
        shape = random_shape(kind, rng)
        w = world_of([shape])
        o = sphere_origins(200, rng)
        d = unit(inside_points(w, 200, rng) - o)  # aimed into the obstacle: must hit
        h = cast_rays(w, o, d)
        assert h.hit.all()
        p = h.points
        np.testing.assert_allclose(p, o + h.distance[:, None] * d, atol=1e-12)
        assert np.all(solid_dist(w, p) < 1e-9)  # on (or in) the solid ...
        assert np.all(solid_dist(w, p - 1e-6 * d) > 0)  # ... entered just there
        assert np.all(solid_dist(w, p + 1e-6 * d) == 0)
        check_normals(h, d)
        # p + delta n is at distance delta exactly when n is an outward normal at p
        delta = 1e-4
        np.testing.assert_allclose(solid_dist(w, p + delta * h.normals), delta, rtol=1e-5)
        if kind == "box":
            local = (p - shape.center) @ shape.rotation
            np.testing.assert_allclose(np.max(np.abs(local) - shape.half, -1), 0, atol=1e-9)
        if kind == "sphere":
            np.testing.assert_allclose(np.linalg.norm(p - shape.center, axis=-1), shape.radius, atol=1e-9)
            np.testing.assert_allclose(h.normals, (p - shape.center) / shape.radius, atol=1e-9)


@pytest.mark.parametrize("kind", KINDS)
def test_primitive_misses(kind: str) -> None:
    """Rays pointing anywhere: every miss stays outside (sampled), every hit is a first hit."""
    rng = np.random.default_rng(10 + KINDS.index(kind))
    shape = random_shape(kind, rng, spread=0.3)
    w = world_of([shape])
    o = sphere_origins(400, rng, radius=3.0)
    centre = inside_points(w, 100, rng).mean(0)
    d = unit(centre + rng.normal(size=(400, 3)) * 0.5 - o)
    h = cast_rays(w, o, d)
    assert 20 < h.hit.sum() < 380  # both cases are exercised
    miss = ~h.hit
    assert np.all(np.isinf(h.distance[miss]))
    assert np.all(np.isnan(h.points[miss])) and np.all(np.isnan(h.normals[miss]))
    s = np.linspace(0, 8, 801)
    samples = o[miss, None, :] + s[None, :, None] * d[miss, None, :]
    assert np.all(solid_dist(w, samples.reshape(-1, 3)) > 0)
    before = o[~miss, None, :] + (h.distance[~miss, None, None] * s[None, :-1, None] / 8) * d[~miss, None, :]
    assert np.all(solid_dist(w, before.reshape(-1, 3)) > 0)


def test_axis_aligned_values() -> None:
    rot_y_to_z = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])  # local z = world y
    w = world_of(
        [
            Box([3, 0, 0], [2, 2, 2]),
            Sphere([0, 3, 0], 0.5),
            Capsule([0, 0, 2], [0, 0, 3], 0.25),
            Cylinder([-2, 0, 0], 0.4, 1.0),
            Cone([0, -2, 0], 0.5, 1.0, rot_y_to_z),  # base at y = -2.5, apex at y = -1.5
        ]
    )
    d = np.array([[1.0, 0, 0], [0, 1, 0], [0, 0, 1], [-1, 0, 0], [0, -1, 0], [0, 0, -1]])
    h = cast_rays(w, np.zeros((6, 3)), d)
    np.testing.assert_allclose(h.distance, [2.0, 2.5, 1.75, 1.6, 1.5, np.inf])
    np.testing.assert_allclose(h.normals[:5], -d[:5], atol=1e-12)
    # the cone from below (through the base) and from the side
    h = cast_rays(w, np.array([[0, -4.0, 0], [1.0, -2.0, 0]]), np.array([[0, 1.0, 0], [-1.0, 0, 0]]))
    np.testing.assert_allclose(h.distance, [1.5, 1.0 - 0.25])  # radius 0.25 at the centre
    np.testing.assert_allclose(h.normals[0], [0, -1, 0], atol=1e-12)
    np.testing.assert_allclose(h.normals[1], unit(np.array([1.0, 0.5, 0])), atol=1e-12)


def test_rays_along_box_faces_and_edges() -> None:
    """A ray in a face's plane touches the closed box (parallel slab on its boundary)."""
    w = world_of([Box([0, 0, 0], [2, 2, 2])])
    o = np.array([[-5, 1, 0], [-5, -1, 0], [-5, 1, 1], [5, -1, -1], [-5, 1 + 1e-9, 0], [0, 5, 1], [0, 1, 5]])
    d = np.array([[1, 0, 0], [1, 0, 0], [1, 0, 0], [-1, 0, 0], [1, 0, 0], [0, -1, 0], [0, 0, -1.0]])
    h = cast_rays(w, o.astype(float), d)
    np.testing.assert_array_equal(h.distance, [4, 4, 4, 4, np.inf, 4, 4])


def test_cylinder_caps_and_degenerate_capsule() -> None:
    w = world_of([Cylinder([0, 0, 0], 0.5, 2.0), Capsule([5, 0, 0], [5, 0, 0], 0.5)])
    o = np.array([[0.2, 0.1, 3.0], [0.2, 0.1, -3.0], [8.0, 0.0, 0.0]])
    d = np.array([[0, 0, -1.0], [0, 0, 1.0], [-1.0, 0, 0]])
    h = cast_rays(w, o, d)
    np.testing.assert_allclose(h.distance, [2.0, 2.0, 2.5])
    np.testing.assert_allclose(h.normals, [[0, 0, 1], [0, 0, -1], [1, 0, 0]], atol=1e-12)


def test_cone_rays_parallel_to_a_generator() -> None:
    """The quadratic of the cone degenerates to a linear equation for these rays."""
    rng = np.random.default_rng(5)
    rot, c = random_rotation(rng), rng.uniform(-1, 1, 3)
    w = world_of([Cone(c, 0.5, 1.0, rot)])  # k = 0.5, apex at local (0, 0, 0.5)
    gen = unit(np.array([0.5, 0.0, -1.0]))  # apex -> rim at (0.5, 0, -0.5)
    shifts = np.array([-0.3, -0.1, -0.01, 0.01, 0.1])
    o_down = np.array([0, 0, 0.5]) + shifts[:, None] * [1, 0, 0] - 2 * gen  # above the apex
    o_up = np.array([0, 0, 0.5]) + shifts[:, None] * [1, 0, 0] + 2 * gen  # below the base
    o_local = np.concatenate([o_down, o_up])
    d_local = np.concatenate([np.tile(gen, (5, 1)), np.tile(-gen, (5, 1))])
    o, d = o_local @ rot.T + c, d_local @ rot.T
    h = cast_rays(w, o, d)
    np.testing.assert_array_equal(h.hit, np.tile(shifts < 0, 2))
    p = h.points[h.hit]
    assert np.all(solid_dist(w, p) < 1e-9)
    assert np.all(solid_dist(w, p - 1e-6 * d[h.hit]) > 0)
    assert np.all(solid_dist(w, p + 1e-6 * d[h.hit]) == 0)
    np.testing.assert_allclose(solid_dist(w, p + 1e-4 * h.normals[h.hit]), 1e-4, rtol=1e-5)
    np.testing.assert_allclose(h.normals[5:8], np.tile(-rot[:, 2], (3, 1)), atol=1e-12)  # base


# ============================================================================ meshes
@pytest.mark.parametrize("kind", KINDS)
def test_primitives_agree_with_trimesh(kind: str) -> None:
    """Analytic distances versus the mesh path on a fine tessellation (1e-2 of the size)."""
    rng = np.random.default_rng(20 + KINDS.index(kind))
    shape = random_shape(kind, rng, spread=0.5)
    w = world_of([shape])
    tm = mesh_of(shape)
    wm = world_of([Mesh(tm.vertices, tm.faces)])
    o = sphere_origins(300, rng, radius=4.0)
    d = np.concatenate([unit(inside_points(w, 200, rng) - o[:200]), unit(o[200:])])  # 100 away
    ha, hm = cast_rays(w, o, d), cast_rays(wm, o, d)
    np.testing.assert_array_equal(ha.hit, np.arange(300) < 200)
    np.testing.assert_array_equal(hm.hit, ha.hit)
    size = float(np.ptp(tm.vertices, 0).max())
    np.testing.assert_allclose(hm.distance[:200], ha.distance[:200], atol=1e-2 * size)
    check_normals(hm, d)
    # and directly against trimesh's own first hits (exact triangle intersector)
    ref = trimesh.ray.ray_triangle.RayMeshIntersector(tm)
    tri, ray, loc = ref.intersects_id(o, d, multiple_hits=False, return_locations=True)
    t_ref = np.full(300, np.inf)
    t_ref[ray] = np.einsum("ij,ij->i", loc - o[ray], d[ray])
    np.testing.assert_allclose(hm.distance, t_ref, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(hm.normals[ray], tm.face_normals[tri], atol=1e-6)  # outward, faces the ray


def test_mesh_inside_inverted_and_open() -> None:
    ico = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    d = unit(np.random.default_rng(0).normal(size=(50, 3)))
    o = np.zeros((50, 3))
    solid = Mesh(ico.vertices, ico.faces)
    inverted = Mesh(ico.vertices, ico.faces[:, ::-1])
    for m in (solid, inverted):
        h = cast_rays(world_of([m]), o, d)
        assert h.hit.all()
        np.testing.assert_array_equal(h.distance, 0.0)
        np.testing.assert_allclose(h.normals, -d)
        np.testing.assert_allclose(h.points, o)
    # an open mesh (one face missing) is a surface: rays from the centre hit it from inside
    op = Mesh(ico.vertices, ico.faces[1:])
    h = cast_rays(world_of([op]), o, d)
    assert np.all(h.distance[h.hit] > 0.9) and np.all(h.distance[h.hit] <= 1.0 + 1e-9)
    check_normals(h, d)
    # from outside, a solid mesh is hit on its surface with outward normals
    o2 = -3 * d
    for m in (solid, inverted):
        h = cast_rays(world_of([m]), o2, d)
        assert h.hit.all()
        assert np.all(np.abs(h.distance - 2.0) < 0.02)
        assert np.all(np.einsum("ij,ij->i", h.normals, h.points) > 0)  # outward


def test_mesh_and_primitives_first_hit() -> None:
    ico = trimesh.creation.icosphere(subdivisions=3, radius=0.5)
    ico.apply_translation([2.0, 0, 0])
    w = world_of([Mesh(ico.vertices, ico.faces), Box([4.0, 0, 0], [1, 1, 1]), Box([0.0, 0, 0], [0.2, 0.2, 0.2])])
    o = np.zeros((3, 3)) + [[1.0, 0, 0], [3.0, 0, 0], [10.0, 0, 0]]
    h = cast_rays(w, o, np.array([[1.0, 0, 0], [1.0, 0, 0], [-1.0, 0, 0]]))
    np.testing.assert_allclose(h.distance, [0.5, 0.5, 5.5], atol=2e-3)
    np.testing.assert_allclose(h.normals, [[-1, 0, 0], [-1, 0, 0], [1, 0, 0]], atol=0.1)  # facets


def test_mesh_intersector_is_cached(monkeypatch: pytest.MonkeyPatch) -> None:
    built = []
    real = raycast._intersector_class()

    def counting(*args, **kwargs):
        built.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(raycast, "_intersector_class", lambda: counting)
    a = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
    b = trimesh.creation.box(extents=[1, 1, 1])
    ma, mb = Mesh(a.vertices + [5, 0, 0], a.faces), Mesh(b.vertices + [5, 0, 0], b.faces)
    wa, wb, wab = world_of([ma]), world_of([mb]), world_of([ma, mb])
    o, d = np.zeros((4, 3)), np.tile([1.0, 0, 0], (4, 1))
    for _ in range(3):
        ta, tb = cast_rays(wa, o, d).distance, cast_rays(wb, o, d).distance
        tab = cast_rays(wab, o, d).distance
    assert len(built) == 3  # one per distinct mesh set, not per call
    np.testing.assert_allclose(ta, 4.0, atol=0.01)
    np.testing.assert_allclose(tb, 4.5)
    np.testing.assert_allclose(tab, 4.0, atol=0.01)


# ============================================================================ semantics
@pytest.mark.parametrize("kind", KINDS)
def test_rays_from_inside(kind: str) -> None:
    rng = np.random.default_rng(30 + KINDS.index(kind))
    w = world_of([random_shape(kind, rng)])
    o = inside_points(w, 50, rng)
    d = unit(rng.normal(size=(50, 3)))
    h = cast_rays(w, o, d, max_range=0.5)
    assert h.hit.all()
    np.testing.assert_array_equal(h.distance, 0.0)
    np.testing.assert_allclose(h.points, o)
    np.testing.assert_allclose(h.normals, -d)


def test_origin_on_the_surface_counts_as_inside() -> None:
    w = world_of([Box([0, 0, 0], [2, 2, 2])])
    h = cast_rays(w, np.array([[1.0, 0.3, 0.2]]), np.array([[1.0, 0, 0]]))
    assert h.hit[0] and h.distance[0] == 0.0


def test_max_range() -> None:
    rng = np.random.default_rng(40)
    w = world_of([random_shape(k, rng) for k in KINDS for _ in range(2)])
    o = rng.uniform(-3, 3, (500, 3))
    d = unit(rng.normal(size=(500, 3)))
    full = cast_rays(w, o, d)
    for r in (0.0, 0.3, 1.0, 2.5):
        h = cast_rays(w, o, d, max_range=r)
        np.testing.assert_array_equal(h.hit, full.hit & (full.distance <= r))
        np.testing.assert_array_equal(h.distance[h.hit], full.distance[h.hit])
        assert np.all(h.distance[h.hit] <= r) and np.all(np.isinf(h.distance[~h.hit]))
        assert 0 < h.hit.sum() < 500
    assert full.hit.sum() > cast_rays(w, o, d, max_range=1.0).hit.sum()


def test_batched_equals_per_scene() -> None:
    rng = np.random.default_rng(50)
    ico = trimesh.creation.icosphere(subdivisions=2, radius=0.4)
    scenes = [
        [random_shape("box", rng) for _ in range(3)] + [random_shape("cone", rng)],
        [random_shape("sphere", rng), random_shape("capsule", rng), Mesh(ico.vertices + [0, 0, 1.5], ico.faces)],
        [random_shape(k, rng) for k in KINDS] + [random_shape("box", rng)],
        [PointCloud(rng.normal(size=(10, 3)), rng.normal(size=(10, 3)))],  # a sparse cloud: each point a small sphere
    ]
    worlds = [world_of(s) for s in scenes]
    stacked = CollisionWorld.stack(worlds)
    o = rng.uniform(-3, 3, (4, 300, 3))
    d = unit(rng.normal(size=(4, 300, 3)) - o)  # roughly towards the obstacles
    hb = cast_rays(stacked, o, d, max_range=4.0)
    assert hb.distance.shape == (4, 300) and hb.points.shape == hb.normals.shape == (4, 300, 3)
    for i, w in enumerate(worlds):
        hi = cast_rays(w, o[i], d[i], max_range=4.0)
        for f in ("distance", "points", "normals", "hit"):
            np.testing.assert_array_equal(getattr(hb, f)[i], getattr(hi, f))
    assert hb.hit[:3].mean(1).min() > 0.05
    # directions shared by all scenes may be given once
    hs = cast_rays(stacked, o, d[0])
    np.testing.assert_array_equal(hs.distance[0], cast_rays(worlds[0], o[0], d[0]).distance)


def test_first_hit_is_the_nearest_single_obstacle_hit() -> None:
    """The reduction over obstacles and shape groups: the first hit of a scene is the
    minimum of the hits of its obstacles cast one at a time."""
    rng = np.random.default_rng(60)
    shapes = [random_shape(k, rng) for k in KINDS for _ in range(3)]
    o = rng.uniform(-3, 3, (400, 3))
    d = unit(rng.normal(size=(400, 3)))
    singles = [cast_rays(world_of([s]), o, d) for s in shapes]
    dist = np.stack([s.distance for s in singles])
    k = np.argmin(dist, 0)
    h = cast_rays(world_of(shapes), o, d)
    np.testing.assert_array_equal(h.distance, dist.min(0))
    hit = h.hit
    ref_normals = np.stack([s.normals for s in singles])[k, np.arange(400)]
    np.testing.assert_allclose(h.normals[hit], ref_normals[hit], atol=1e-12)


def test_chunking_does_not_change_results(monkeypatch: pytest.MonkeyPatch) -> None:
    rng = np.random.default_rng(65)
    w = CollisionWorld.stack([world_of([random_shape(k, rng) for k in KINDS * 2]) for _ in range(3)])
    o = rng.uniform(-3, 3, (3, 100, 3))
    d = unit(rng.normal(size=(3, 100, 3)) - o)
    whole = cast_rays(w, o, d)
    monkeypatch.setattr(raycast, "_CHUNK", 50)  # a few rays per chunk
    parts = cast_rays(w, o, d)
    for f in ("distance", "points", "normals", "hit"):
        np.testing.assert_array_equal(getattr(parts, f), getattr(whole, f))
    assert whole.hit.mean() > 0.2


def test_directions_are_normalised() -> None:
    rng = np.random.default_rng(70)
    w = world_of([random_shape(k, rng) for k in KINDS])
    o = rng.uniform(-3, 3, (200, 3))
    d = unit(rng.normal(size=(200, 3)))
    a = cast_rays(w, o, d)
    b = cast_rays(w, o, d * rng.uniform(0.01, 100, (200, 1)))
    np.testing.assert_allclose(b.distance, a.distance, rtol=1e-12)
    np.testing.assert_allclose(b.normals, a.normals, atol=1e-12)


def test_bad_input() -> None:
    w = world_of([Box([0, 0, 0], [1, 1, 1])])
    with pytest.raises(ValueError):
        cast_rays(CollisionWorld.from_shapes([Box([0, 0], [1, 1])], 2), np.zeros((1, 2)), np.ones((1, 2)))
    with pytest.raises(ValueError):
        cast_rays(w, np.zeros((1, 3)), np.zeros((1, 3)))  # zero direction
    with pytest.raises(ValueError):
        cast_rays(w, np.zeros((2, 1, 3)), np.ones((2, 1, 3)))  # batch shape of an unstacked world
    with pytest.raises(ValueError):
        cast_rays(w, np.zeros((1, 3)), np.ones((1, 3)), max_range=-1.0)


def test_padding_and_degenerate_shapes_are_never_hit() -> None:
    """Stacked worlds pad with zero-size shapes at 1e6; rays straight through them miss."""
    w1 = world_of([random_shape(k, np.random.default_rng(80)) for k in KINDS])
    w2 = world_of([Sphere([0, 0, 5], 0.0), Box([0, 0, 7], [0, 0, 0])])  # degenerate shapes
    stacked = CollisionWorld.stack([w1, w2])
    assert stacked.box_c.shape[1] == 1 and stacked.sph_c.shape[1] == 1  # w2 pads the rest
    o = np.array([[0.0, 1e6, 1e6], [1e6, 0.0, 1e6], [1e6, 1e6, 0.0], [0.0, 0.0, 0.0]])
    d = np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0], [0, 0, 1.0]])
    h = cast_rays(stacked, np.stack([o, o]), d)
    assert not h.hit[1].any()
    assert not h.hit[0, :3].any()


def test_empty_world_and_no_rays() -> None:
    empty_mesh = Mesh(np.zeros((0, 3)), np.zeros((0, 3), np.int64))
    h = cast_rays(world_of([empty_mesh]), np.zeros((5, 3)), np.tile([0, 0, 1.0], (5, 1)))
    assert not h.hit.any() and np.isinf(h.distance).all()
    h = cast_rays(world_of([Box([0, 0, 0], [1, 1, 1])]), np.zeros((0, 3)), np.zeros((0, 3)))
    assert h.distance.shape == (0,) and h.points.shape == (0, 3)


# ============================================================================ random scenes
@settings(max_examples=15, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_random_scenes(seed: int) -> None:
    rng = np.random.default_rng(seed)
    shapes = [random_shape(KINDS[i], rng) for i in rng.integers(0, 5, rng.integers(1, 8))]
    w = world_of(shapes)
    o = rng.uniform(-3, 3, (100, 3))
    o = o[solid_dist(w, o) > 1e-3]  # rays from outside
    d = unit(rng.normal(size=o.shape))
    h = cast_rays(w, o, d, max_range=6.0)
    check_normals(h, d)
    hit = h.hit
    # hit points on the surface, nothing before them; misses meet nothing within range
    assert np.all(solid_dist(w, h.points[hit]) < 1e-9)
    s = np.linspace(0, 1, 200)[:-1]
    t = np.where(hit, h.distance, 6.0)
    samples = o[:, None, :] + (t[:, None] * s[None, :])[..., None] * d[:, None, :]
    assert np.all(solid_dist(w, samples.reshape(-1, 3)) > 0)
    assert np.all(solid_dist(w, o[~hit] + 6.0 * d[~hit]) > 0)


def test_compiled_box_kernel_matches_numpy(monkeypatch: pytest.MonkeyPatch) -> None:
    """The numba slab test and the numpy one give the same hits, normals and distances,
    rays in a face plane and axis-parallel rays included."""
    from pointplan.geometry import lie

    rng = np.random.default_rng(3)
    boxes = [
        Box(rng.uniform(-0.4, 0.4, 3), rng.uniform(0.1, 0.5, 3), lie.random_rotations(rng, 1)[0]) for _ in range(6)
    ]
    boxes.append(Box([0.0, 0.0, 0.0], [0.2, 0.2, 0.2]))
    world = CollisionWorld.from_shapes(boxes, 3)
    o = rng.uniform(-0.6, 0.6, (400, 3))
    d = rng.normal(size=(400, 3))
    d[:20] = [1.0, 0.0, 0.0]
    o[:10] = [-0.5, 0.1, 0.0]  # in the plane of a face of the axis-aligned box
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    compiled = cast_rays(world, o, d)
    monkeypatch.setitem(raycast._KERNELS, "box", raycast.box_slabs_reference)
    plain = cast_rays(world, o, d)
    np.testing.assert_array_equal(compiled.hit, plain.hit)
    assert compiled.hit[:10].all()
    np.testing.assert_allclose(compiled.distance[compiled.hit], plain.distance[plain.hit], atol=1e-12)
    np.testing.assert_allclose(compiled.normals[compiled.hit], plain.normals[plain.hit], atol=1e-12)


def test_ray_from_inside_one_mesh_first_meeting_an_overlapping_one() -> None:
    """Box A [1, 1, 1] at the origin, box B [.4, .4, .4] at [.5, 0, 0] (as meshes): a ray
    from inside A meets B's near face first (0.6 away), yet it starts inside: distance 0."""
    a = trimesh.creation.box(extents=[1.0, 1.0, 1.0])
    b = trimesh.creation.box(extents=[0.4, 0.4, 0.4])
    b.apply_translation([0.5, 0.0, 0.0])
    meshes = [Mesh(a.vertices, a.faces), Mesh(b.vertices, b.faces)]
    o = np.array([[-0.3, 0.01, 0.02], [-0.3, 0.01, 0.02], [-0.8, 0.01, 0.02]])
    d = np.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    for order in (meshes, meshes[::-1]):
        h = cast_rays(world_of(order), o, d)
        assert h.hit.all()
        np.testing.assert_allclose(h.distance, [0.0, 0.0, 0.3], atol=1e-9)
        np.testing.assert_allclose(h.normals[:2], -d[:2])
        np.testing.assert_allclose(h.points[0], o[0])
    # from inside B (inside A too), along -x: still 0
    h = cast_rays(world_of(meshes), np.array([[0.6, 0.0, 0.0]]), np.array([[-1.0, 0.0, 0.0]]))
    assert h.distance[0] == 0.0


def test_a_scanned_surface_is_seen_like_the_surface() -> None:
    """Rays cast at a cloud sampled on boxes' surfaces (area-weighted random points, as a
    scan gives them) hit where they hit the boxes themselves (the closed-form slab test),
    within the splat radius, with the face's normal; the rays that miss the boxes miss
    the cloud (but for grazing rays that the splats' thickness catches)."""
    from pointplan.geometry.sampling import area_weighted_points

    rng = np.random.default_rng(0)
    boxes = [Box([0.5, 0.5, 0.5], [0.3, 0.2, 0.4]), Box([0.2, 0.8, 0.3], [0.1, 0.1, 0.5])]
    pts, nrm, _ = area_weighted_points(boxes, 20000, rng)
    wb, wc = world_of(boxes), world_of([PointCloud(pts, nrm)])
    o = np.tile([[0.5, 0.15, 0.45]], (2000, 1))
    d = unit(rng.normal(size=(2000, 3)))
    hb, hc = cast_rays(wb, o, d, 2.0), cast_rays(wc, o, d, 2.0)
    radius = wc.cloud_radius[0]
    assert radius == PointCloud(pts, nrm).point_radius() and 1e-3 < radius < 0.02
    assert hb.hit.sum() > 150 and (hb.hit == hc.hit).mean() > 0.99
    both = hb.hit & hc.hit
    assert both.sum() >= hb.hit.sum() - 2
    err = hb.distance[both] - hc.distance[both]
    # the splats stand slightly proud of the surface
    assert np.percentile(np.abs(err), 99) <= radius * 1.5 and err.min() > -radius
    cos = np.sum(hb.normals[both] * hc.normals[both], -1)
    assert np.mean(cos > 0.99) > 0.98


def test_a_cloud_point_behind_the_origin_is_not_hit() -> None:
    """A ray leaving a point's sphere from just outside it, or from inside it, sees the
    sphere only in front of it: a sphere wholly behind the origin (its centre 1.2 radii
    back) is not hit (it was, at distance 0, until the exit was tested), one ahead is,
    at its entry, and one holding the origin is, at 0."""
    world = CollisionWorld.from_shapes([PointCloud(np.zeros((1, 3)), np.array([[0.0, 1.0, 0.0]]), radius=0.01)], 3)
    o = np.array([[0.0, 0.012, 0.0], [0.0, 0.012, 0.0], [0.0, 0.005, 0.0], [0.003, 0.011, 0.0]])
    d = np.array([[0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [0.0, 1.0, 0.0], [0.0, 1.0, 0.0]])
    hits = cast_rays(world, o, d, 1.0)
    assert hits.hit.tolist() == [False, True, True, False]
    assert hits.distance[1] == pytest.approx(0.002) and hits.distance[2] == 0.0
