"""Geometry: Lie groups, frame transforms, collision against the coal oracle, q_free.

Collision answers of the closed-form kernels are checked pair by pair against coal
(``coal.collide``); cases that coal finds within 1e-6 of touching are skipped because
either answer is right there.
"""

from __future__ import annotations

from functools import cache

import coal
import numpy as np
import pytest
import trimesh
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from pointplan.envs.core import q_free
from pointplan.geometry import lie
from pointplan.geometry.collision import CollisionWorld
from pointplan.geometry.shapes import (
    Box,
    Capsule,
    Cone,
    Cylinder,
    Mesh,
    PointCloud,
    Sphere,
)
from pointplan.robots import Disc2D, SShape
from pointplan.scenes import narrow2d

TOUCH = 1e-6
seeds = st.integers(0, 2**32 - 1)
fast = settings(max_examples=25, deadline=None)


# ============================================================================ helpers
def unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def rot2(a: float) -> np.ndarray:
    return np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])


def embed_rot(r2: np.ndarray) -> np.ndarray:
    r = np.eye(3)
    r[:2, :2] = r2
    return r


def z_to(axis: np.ndarray) -> np.ndarray:
    """A rotation taking the z axis to ``axis`` (Rodrigues), written independently of the
    package so the oracle does not share its helpers."""
    z = np.array([0.0, 0.0, 1.0])
    a = axis / np.linalg.norm(axis)
    v = np.cross(z, a)
    s, c = np.linalg.norm(v), float(z @ a)
    if s < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    k = lie.hat3(v / s)
    return np.eye(3) + s * k + (1 - c) * k @ k


def tf(r: np.ndarray, t: np.ndarray) -> coal.Transform3s:
    return coal.Transform3s(np.asarray(r, np.float64), np.asarray(t, np.float64))


def oracle(g1, t1, g2, t2) -> tuple[bool, float]:
    """coal's verdict and signed distance for one pair."""
    hit = coal.collide(g1, t1, g2, t2, coal.CollisionRequest(), coal.CollisionResult())
    dist = coal.distance(g1, t1, g2, t2, coal.DistanceRequest(), coal.DistanceResult())
    return bool(hit), float(dist)


def coal_obstacle(s) -> tuple[object, coal.Transform3s]:
    """An obstacle shape as a coal geometry + transform (2D shapes lie in the plane z=0;
    2D boxes get a thick z side)."""
    if isinstance(s, Box):
        if s.dim == 2:
            return coal.Box(s.size[0], s.size[1], 10.0), tf(embed_rot(s.rotation), np.r_[s.center, 0.0])
        return coal.Box(*s.size), tf(s.rotation, s.center)
    if isinstance(s, Sphere):
        return coal.Sphere(s.radius), tf(np.eye(3), np.r_[s.center, [0.0] * (3 - s.dim)])
    if isinstance(s, Capsule):
        a, b = (np.r_[x, [0.0] * (3 - s.dim)] for x in (s.a, s.b))
        return coal.Capsule(s.radius, float(np.linalg.norm(b - a))), tf(z_to(b - a), (a + b) / 2)
    if isinstance(s, Cylinder):
        return coal.Cylinder(s.radius, s.length), tf(s.rotation, s.center)
    if isinstance(s, Cone):
        return coal.Cone(s.radius, s.length), tf(s.rotation, s.center)
    raise TypeError(type(s))


def random_obstacles(rng: np.random.Generator, kind: str, dim: int, n: int) -> list:
    """``n`` obstacles of one kind near the origin, sizes 0.05 .. 0.6."""
    out = []
    for _ in range(n):
        c = rng.uniform(-0.5, 0.5, dim)
        if kind == "box":
            rot = rot2(rng.uniform(-np.pi, np.pi)) if dim == 2 else lie.random_rotations(rng, 1)[0]
            out.append(Box(c, rng.uniform(0.05, 0.6, dim), rot))
        elif kind == "sphere":
            out.append(Sphere(c, rng.uniform(0.05, 0.3)))
        elif kind == "capsule":
            d = unit(rng.normal(size=dim)) * rng.uniform(0.0, 0.6)
            out.append(Capsule(c - d / 2, c + d / 2, rng.uniform(0.03, 0.2)))
        elif kind == "cylinder":
            out.append(Cylinder(c, rng.uniform(0.03, 0.3), rng.uniform(0.05, 0.6), lie.random_rotations(rng, 1)[0]))
        elif kind == "cone":
            out.append(Cone(c, rng.uniform(0.03, 0.3), rng.uniform(0.05, 0.6), lie.random_rotations(rng, 1)[0]))
        else:
            raise ValueError(kind)
    return out


# ============================================================================ Lie groups
twist_vals = st.floats(-3.0, 3.0, allow_nan=False)


@given(seeds)
@fast
def test_se3_exp_log_round_trip(seed: int) -> None:
    rng = np.random.default_rng(seed)
    xi = rng.uniform(-2.0, 2.0, (64, 6))
    w = xi[:, 3:]
    # rotation angle in [0, pi): rescale the rotation part, include tiny and zero angles
    ang = np.concatenate([rng.uniform(0, np.pi - 1e-3, 56), [0.0, 1e-9, 1e-6, 1e-4, 2e-4, 1e-2, 3.0, 3.14]])
    xi[:, 3:] = unit(w) * ang[:, None]
    t = lie.se3_exp(xi)
    np.testing.assert_allclose(lie.se3_log(t), xi, atol=1e-8)
    # exp is a proper rigid motion
    r = t[:, :3, :3]
    np.testing.assert_allclose(r @ np.swapaxes(r, 1, 2), np.broadcast_to(np.eye(3), r.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(r), 1.0, atol=1e-12)
    # and exp(log(T)) = T for arbitrary poses
    t2 = np.zeros((64, 4, 4))
    t2[:, :3, :3] = lie.random_rotations(rng, 64)
    t2[:, :3, 3] = rng.normal(size=(64, 3))
    t2[:, 3, 3] = 1
    np.testing.assert_allclose(lie.se3_exp(lie.se3_log(t2)), t2, atol=1e-9)


@given(st.lists(st.tuples(twist_vals, twist_vals, st.floats(-np.pi + 1e-6, np.pi - 1e-6)), min_size=1, max_size=8))
@fast
def test_se2_exp_log_round_trip(xis: list) -> None:
    xi = np.array(xis)
    xi = np.concatenate([xi, [[0.3, -0.2, 0.0], [0.1, 0.2, 1e-9], [1.0, 1.0, 1e-7]]])
    t = lie.se2_exp(xi)
    np.testing.assert_allclose(lie.se2_log(t), xi, atol=1e-9)
    np.testing.assert_allclose(lie.se2_exp(lie.se2_log(t)), t, atol=1e-12)
    # the 2D exponential is the 3D one restricted to the plane
    xi3 = np.zeros((len(xi), 6))
    xi3[:, :2], xi3[:, 5] = xi[:, :2], xi[:, 2]
    t3 = lie.se3_exp(xi3)
    np.testing.assert_allclose(t3[:, :2, :2], t[:, :2, :2], atol=1e-12)
    np.testing.assert_allclose(t3[:, :2, 3], t[:, :2, 2], atol=1e-12)


@given(seeds)
@fast
def test_quaternion_matrix_round_trip(seed: int) -> None:
    rng = np.random.default_rng(seed)
    q = unit(rng.normal(size=(64, 4)))
    # include the axes and the half-turns, where the largest-component branch switches
    q = np.concatenate([q, np.eye(4), unit(np.array([[1, 1, 0, 0], [0, 1, 1, 1e-9], [1, 0, 0, 1e-12]], float))])
    r = lie.quat_to_matrix(q)
    np.testing.assert_allclose(r @ np.swapaxes(r, 1, 2), np.broadcast_to(np.eye(3), r.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(r), 1.0, atol=1e-12)
    back = lie.matrix_to_quat(r)
    assert np.all(back[:, 3] >= 0)
    # q and -q are one rotation: compare up to sign
    err = np.minimum(np.abs(back - q).max(1), np.abs(back + q).max(1))
    assert err.max() < 1e-9
    np.testing.assert_allclose(lie.quat_to_matrix(back), r, atol=1e-12)
    # the quaternion of exp(w) is (sin(t/2) axis, cos(t/2))
    w = rng.normal(size=(16, 3))
    th = np.linalg.norm(w, axis=1, keepdims=True) % (2 * np.pi)
    w = unit(w) * np.where(th > np.pi, th - 2 * np.pi, th)
    th = np.linalg.norm(w, axis=1)
    qw = np.concatenate([unit(w) * np.sin(th / 2)[:, None], np.cos(th / 2)[:, None]], 1)
    np.testing.assert_allclose(lie.quat_to_matrix(qw), lie.so3_exp(w), atol=1e-12)


@given(seeds, st.sampled_from([0.0, 1e-12, 1e-9, 1e-7, 1e-5, 1e-4, 9e-4, 2e-3, 1e-2]))
@fast
def test_so3_log_near_pi(seed: int, gap: float) -> None:
    rng = np.random.default_rng(seed)
    axis = unit(rng.normal(size=(16, 3)))
    axis = np.concatenate([axis, np.eye(3), -np.eye(3)])
    ang = np.pi - gap
    r = lie.so3_exp(axis * ang)
    w = lie.so3_log(r)
    assert np.all(np.isfinite(w))
    # the angle comes from arccos of the trace, which near pi is good to ~sqrt(eps) only
    np.testing.assert_allclose(np.linalg.norm(w, axis=1), ang, rtol=0, atol=1e-7)
    np.testing.assert_allclose(lie.so3_exp(w), r, rtol=0, atol=1e-7)
    if gap > 1e-5:  # the axis sign is well defined away from pi
        np.testing.assert_allclose(w, axis * ang, atol=1e-7)


def random_poses(rng: np.random.Generator, n: int, dim: int) -> np.ndarray:
    if dim == 2:
        return lie.se2_exp(np.c_[rng.normal(size=(n, 2)), rng.uniform(-np.pi, np.pi, n)])
    t = np.zeros((n, 4, 4))
    t[:, :3, :3] = lie.random_rotations(rng, n)
    t[:, :3, 3] = rng.normal(size=(n, 3))
    t[:, 3, 3] = 1.0
    return t


@pytest.mark.parametrize("dim", [2, 3])
@given(seed=seeds)
@fast
def test_geodesic(dim: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    t0, t1 = random_poses(rng, 32, dim), random_poses(rng, 32, dim)
    np.testing.assert_allclose(lie.geodesic(t0, t1, np.zeros(32)), t0, atol=1e-12)
    np.testing.assert_allclose(lie.geodesic(t0, t1, np.ones(32)), t1, atol=1e-8)
    xi = lie.relative_twist(t0, t1)
    d = lie.geodesic_distance(t0, t1)
    np.testing.assert_allclose(d, np.linalg.norm(xi, axis=-1), atol=1e-12)
    # the twist carries T0 onto T1, and points on the geodesic split the distance
    np.testing.assert_allclose(t0 @ lie.se_exp(xi), t1, atol=1e-8)
    s = rng.uniform(0, 1, 32)
    mid = lie.geodesic(t0, t1, s)
    np.testing.assert_allclose(lie.geodesic_distance(t0, mid), s * d, atol=1e-7)
    np.testing.assert_allclose(lie.geodesic_distance(mid, t1), (1 - s) * d, atol=1e-7)
    # symmetric
    np.testing.assert_allclose(lie.geodesic_distance(t1, t0), d, atol=1e-7)


@pytest.mark.parametrize("dim", [2, 3])
@given(seed=seeds)
@fast
def test_distance_is_left_invariant(dim: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    t0, t1, g = random_poses(rng, 32, dim), random_poses(rng, 32, dim), random_poses(rng, 32, dim)
    np.testing.assert_allclose(lie.geodesic_distance(g @ t0, g @ t1), lie.geodesic_distance(t0, t1), atol=1e-7)
    np.testing.assert_allclose(lie.relative_twist(g @ t0, g @ t1), lie.relative_twist(t0, t1), atol=1e-7)


@given(seeds)
@fast
def test_sshape_group_operations(seed: int) -> None:
    rng = np.random.default_rng(seed)
    robot = SShape()
    q0 = robot.sample_uniform(rng, 32, -np.ones(3), np.ones(3))
    v = rng.uniform(-1, 1, (32, 6)) * robot.action_scale
    q1 = robot.integrate(q0, v)
    np.testing.assert_allclose(robot.log(q0, q1), v, atol=1e-9)
    np.testing.assert_allclose(robot.distance(q0, q1), np.linalg.norm(v, axis=1), atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(q1[:, 3:], axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(robot.interpolate(q0, q1, 0.0)[:, :3], q0[:, :3], atol=1e-12)
    end = robot.interpolate(q0, q1, 1.0)
    np.testing.assert_allclose(robot.to_matrix(end), robot.to_matrix(q1), atol=1e-9)


# ============================================================================ frames
@given(seeds)
@fast
def test_body_frame_round_trip_disc(seed: int) -> None:
    rng = np.random.default_rng(seed)
    robot = Disc2D()
    q = rng.uniform(0, 1, (5, 2))
    pts = rng.normal(size=(5, 9, 2))
    nrm = unit(rng.normal(size=(5, 9, 2)))
    p, n = robot.to_body_frame(q, pts, nrm)
    back = np.einsum("bij,bnj->bni", robot.rotations(q), p) + robot.positions(q)[:, None]
    np.testing.assert_allclose(back, pts, atol=1e-12)
    np.testing.assert_allclose(n, nrm, atol=1e-12)  # no rotation
    # the generic implementation of the base class agrees with the disc's shortcut
    p2, n2 = super(type(robot), robot).to_body_frame(q, pts, nrm)
    np.testing.assert_allclose(p2, p, atol=1e-12)


@given(seeds)
@fast
def test_body_frame_round_trip_sshape(seed: int) -> None:
    rng = np.random.default_rng(seed)
    robot = SShape()
    q = robot.sample_uniform(rng, 5, -np.ones(3), np.ones(3))
    pts = rng.normal(size=(5, 9, 3))
    nrm = unit(rng.normal(size=(5, 9, 3)))
    p, n = robot.to_body_frame(q, pts, nrm)
    rot, pos = robot.rotations(q), robot.positions(q)
    back = np.einsum("bij,bnj->bni", rot, p) + pos[:, None]
    np.testing.assert_allclose(back, pts, atol=1e-12)
    np.testing.assert_allclose(np.einsum("bij,bnj->bni", rot, n), nrm, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(n, axis=-1), 1.0, atol=1e-12)
    # the body frame is the pose's inverse applied to the points
    t_inv = lie.se3_inv(robot.to_matrix(q))
    ph = np.einsum("bij,bnj->bni", t_inv[:, :3, :3], pts) + t_inv[:, None, :3, 3]
    np.testing.assert_allclose(p, ph, atol=1e-12)
    # a body-frame point of the robot itself lands where world_parts puts it
    _, bc, _, _ = robot.world_parts(q)
    pb, _ = robot.to_body_frame(q, bc)
    np.testing.assert_allclose(pb, np.broadcast_to(robot.parts.box_centers, pb.shape), atol=1e-12)


# ============================================================================ collision vs coal
def check_spheres(obstacles: list, centers: np.ndarray, radii: np.ndarray) -> int:
    """Compare sphere queries against coal, pair by pair and for the whole scene."""
    dim = centers.shape[1]
    expect = np.zeros((len(centers), len(obstacles)), bool)
    touching = np.zeros(len(centers), bool)
    for k, s in enumerate(obstacles):
        g, t = coal_obstacle(s)
        for m, (c, r) in enumerate(zip(centers, radii)):
            hit, dist = oracle(coal.Sphere(float(r)), tf(np.eye(3), np.r_[c, [0.0] * (3 - dim)]), g, t)
            expect[m, k] = hit
            touching[m] |= abs(dist) < TOUCH
    keep = ~touching
    # pair by pair: one scene per obstacle, stacked, answers (K, M)
    stacked = CollisionWorld.stack([CollisionWorld.from_shapes([s], dim) for s in obstacles])
    k = len(obstacles)
    got = stacked.spheres_collide(
        np.broadcast_to(centers, (k,) + centers.shape), np.broadcast_to(radii, (k, len(radii)))
    )
    for kk in range(k):
        bad = np.flatnonzero(keep & (got[kk] != expect[:, kk]))
        assert not len(bad), f"{obstacles[kk]} vs sphere {centers[bad[0]]} r={radii[bad[0]]}: coal {expect[bad[0], kk]}"
    # the whole scene at once
    world = CollisionWorld.from_shapes(obstacles, dim)
    np.testing.assert_array_equal(world.spheres_collide(centers, radii)[keep], expect.any(1)[keep])
    return int(expect[keep].sum())


def check_boxes(obstacles: list, centers: np.ndarray, rots: np.ndarray, halfs: np.ndarray) -> int:
    """Compare 3D box queries against coal, pair by pair and for the whole scene."""
    expect = np.zeros((len(centers), len(obstacles)), bool)
    touching = np.zeros(len(centers), bool)
    for k, s in enumerate(obstacles):
        g, t = coal_obstacle(s)
        for m in range(len(centers)):
            hit, dist = oracle(coal.Box(*(2 * halfs[m])), tf(rots[m], centers[m]), g, t)
            expect[m, k] = hit
            touching[m] |= abs(dist) < TOUCH
    keep = ~touching
    for kk, s in enumerate(obstacles):
        got = CollisionWorld.from_shapes([s], 3).boxes_collide(centers, rots, halfs)
        bad = np.flatnonzero(keep & (got != expect[:, kk]))
        assert not len(bad), f"{s} vs box c={centers[bad[0]]} h={halfs[bad[0]]}: coal {expect[bad[0], kk]}"
    world = CollisionWorld.from_shapes(obstacles, 3)
    np.testing.assert_array_equal(world.boxes_collide(centers, rots, halfs)[keep], expect.any(1)[keep])
    return int(expect[keep].sum())


@pytest.mark.parametrize("kind", ["box", "sphere", "capsule"])
@given(seed=seeds)
@fast
def test_disc_2d_vs_coal(kind: str, seed: int) -> None:
    rng = np.random.default_rng(seed)
    obstacles = random_obstacles(rng, kind, 2, 4)
    centers = rng.uniform(-0.9, 0.9, (40, 2))
    radii = rng.uniform(0.005, 0.2, 40)
    check_spheres(obstacles, centers, radii)


@pytest.mark.parametrize("kind", ["box", "sphere", "capsule", "cylinder", "cone"])
@given(seed=seeds)
@fast
def test_sphere_3d_vs_coal(kind: str, seed: int) -> None:
    rng = np.random.default_rng(seed)
    obstacles = random_obstacles(rng, kind, 3, 4)
    centers = rng.uniform(-0.8, 0.8, (40, 3))
    radii = rng.uniform(0.005, 0.25, 40)
    check_spheres(obstacles, centers, radii)


def test_oracle_cases_are_mixed() -> None:
    """The random cases above are not all hits or all misses."""
    rng = np.random.default_rng(0)
    for kind in ["box", "sphere", "capsule", "cylinder", "cone"]:
        hits = check_spheres(
            random_obstacles(rng, kind, 3, 4), rng.uniform(-0.8, 0.8, (200, 3)), rng.uniform(0.005, 0.25, 200)
        )
        assert 20 < hits < 180, (kind, hits)


@pytest.mark.parametrize("kind", ["box", "sphere", "capsule", "cylinder", "cone"])
@given(seed=seeds)
@fast
def test_box_3d_vs_coal(kind: str, seed: int) -> None:
    """Robot boxes (OBBs) against obstacles: SAT for boxes, closed form for spheres, the
    coal fallback for capsules and cylinders."""
    rng = np.random.default_rng(seed)
    obstacles = random_obstacles(rng, kind, 3, 3)
    n = 30
    centers = rng.uniform(-0.8, 0.8, (n, 3))
    rots = lie.random_rotations(rng, n)
    rots[:5] = np.eye(3)  # axis-aligned boxes too: parallel edges are the SAT's corner case
    halfs = rng.uniform(0.01, 0.3, (n, 3))
    check_boxes(obstacles, centers, rots, halfs)


def test_box_box_parallel_and_edge_cases() -> None:
    """Axis-aligned boxes (degenerate cross products) separated along one axis."""
    world = CollisionWorld.from_shapes([Box([0, 0, 0], [1, 1, 1])], 3)
    eye = np.broadcast_to(np.eye(3), (4, 3, 3))
    c = np.array([[1.01, 0, 0], [0.99, 0, 0], [0, 0, 0.6 + 0.05 + 1e-3], [0.7, 0.7, 0]])
    h = np.array([[0.5, 0.1, 0.1], [0.5, 0.1, 0.1], [0.05, 0.05, 0.05], [0.1, 0.1, 0.1]])
    np.testing.assert_array_equal(world.boxes_collide(c, eye, h), [False, True, False, False])
    # a box rotated 45 degrees about z, its edge just clear of / just into a face
    r = lie.so3_exp(np.array([0, 0, np.pi / 4]))
    s = 0.1 * np.sqrt(2)
    c = np.array([[0.5 + s + 1e-3, 0, 0], [0.5 + s - 1e-3, 0, 0]])
    got = world.boxes_collide(c, np.broadcast_to(r, (2, 3, 3)), np.full((2, 3), 0.1))
    np.testing.assert_array_equal(got, [False, True])


def sshape_coal_parts(robot: SShape, q: np.ndarray) -> list[tuple[object, coal.Transform3s]]:
    """The five bars as coal boxes, posed from the configuration independently of
    ``world_parts``."""
    r = lie.quat_to_matrix(q[3:])
    return [
        (coal.Box(*(2 * h)), tf(r @ br, r @ c + q[:3]))
        for c, br, h in zip(robot.parts.box_centers, robot.parts.box_rotations, robot.parts.box_halfs)
    ]


@pytest.mark.parametrize("kind", ["box", "sphere", "capsule", "cylinder", "cone"])
@given(seed=seeds)
@settings(max_examples=15, deadline=None)
def test_sshape_vs_coal(kind: str, seed: int) -> None:
    rng = np.random.default_rng(seed)
    robot = SShape()
    obstacles = random_obstacles(rng, kind, 3, 4)
    q = robot.sample_uniform(rng, 30, -np.full(3, 0.7), np.full(3, 0.7))
    expect = np.zeros(len(q), bool)
    touching = np.zeros(len(q), bool)
    coal_obs = [coal_obstacle(s) for s in obstacles]
    for m in range(len(q)):
        for g1, t1 in sshape_coal_parts(robot, q[m]):
            for g2, t2 in coal_obs:
                hit, dist = oracle(g1, t1, g2, t2)
                expect[m] |= hit
                touching[m] |= abs(dist) < TOUCH
    world = CollisionWorld.from_shapes(obstacles, 3)
    got = robot.collides(world, q)
    assert got.shape == (len(q),)
    bad = np.flatnonzero(~touching & (got != expect))
    assert not len(bad), f"q={q[bad[0]]}: coal {expect[bad[0]]}"
    # any leading batch shape works for a single world
    np.testing.assert_array_equal(robot.collides(world, q.reshape(5, 6, 7)), got.reshape(5, 6))


def test_sshape_bars() -> None:
    """Five 0.2 x 0.036 x 0.036 bars that join end to end at the S's corners."""
    parts = SShape().parts
    assert len(parts.box_centers) == 5
    for h in parts.box_halfs:
        np.testing.assert_allclose(np.sort(2 * h), [0.036, 0.036, 0.2])
    world = CollisionWorld.from_shapes([Sphere([0.0, 0.0, 0.0], 0.0)], 3)
    assert world.batch_shape == ()


# ============================================================================ stacking
def random_scene_shapes(rng: np.random.Generator) -> list:
    shapes: list = []
    for kind in ["box", "sphere", "capsule", "cylinder"]:
        shapes += random_obstacles(rng, kind, 3, int(rng.integers(0, 4)))
    if rng.random() < 0.5:
        p = rng.uniform(-0.5, 0.5, (int(rng.integers(1, 30)), 3))
        shapes.append(PointCloud(p, unit(rng.normal(size=p.shape))))
    return shapes


@given(seeds, st.integers(1, 5))
@settings(max_examples=15, deadline=None)
def test_stacked_world_matches_each_scene(seed: int, n_scenes: int) -> None:
    rng = np.random.default_rng(seed)
    scenes = [random_scene_shapes(rng) for _ in range(n_scenes)]
    worlds = [CollisionWorld.from_shapes(s, 3) for s in scenes]
    stacked = CollisionWorld.stack(worlds)
    assert stacked.batch_shape == (n_scenes,)
    m = 25
    # spheres
    c = rng.uniform(-0.8, 0.8, (n_scenes, m, 3))
    c[:, :3] = rng.uniform(-0.05, 0.05, (n_scenes, 3, 3))  # padding must not sit at the origin
    r = rng.uniform(0.01, 0.2, (n_scenes, m))
    got = stacked.spheres_collide(c, r)
    want = np.stack([w.spheres_collide(c[i], r[i]) for i, w in enumerate(worlds)])
    np.testing.assert_array_equal(got, want)
    # boxes
    rot = lie.random_rotations(rng, n_scenes * m).reshape(n_scenes, m, 3, 3)
    h = rng.uniform(0.01, 0.2, (n_scenes, m, 3))
    got = stacked.boxes_collide(c, rot, h)
    want = np.stack([w.boxes_collide(c[i], rot[i], h[i]) for i, w in enumerate(worlds)])
    np.testing.assert_array_equal(got, want)
    # the S-shape
    robot = SShape()
    q = robot.sample_uniform(rng, n_scenes * 8, -np.full(3, 0.7), np.full(3, 0.7)).reshape(n_scenes, 8, 7)
    got = robot.collides(stacked, q)
    want = np.stack([robot.collides(w, q[i]) for i, w in enumerate(worlds)])
    np.testing.assert_array_equal(got, want)


@given(st.lists(st.integers(0, 10_000), min_size=1, max_size=6))
@settings(max_examples=10, deadline=None)
def test_stacked_narrow2d_matches_each_scene(indices: list[int]) -> None:
    scenes = [narrow_ws(i) for i in indices]
    stacked = CollisionWorld.stack([s.world for s in scenes])
    robot = Disc2D()
    rng = np.random.default_rng(indices[0])
    q = rng.uniform(0, 1, (len(scenes), 200, 2))
    got = robot.collides(stacked, q)
    want = np.stack([robot.collides(s.world, q[i]) for i, s in enumerate(scenes)])
    np.testing.assert_array_equal(got, want)
    assert want.any() and not want.all()


# ============================================================================ meshes
def box_mesh(b: Box) -> Mesh:
    t = np.eye(4)
    t[:3, :3], t[:3, 3] = b.rotation, b.center
    m = trimesh.creation.box(extents=b.size, transform=t)
    return Mesh(m.vertices, m.faces)


@given(seeds)
@settings(max_examples=8, deadline=None)
def test_mesh_box_matches_box(seed: int) -> None:
    rng = np.random.default_rng(seed)
    boxes = random_obstacles(rng, "box", 3, 2)
    box_world = CollisionWorld.from_shapes(boxes, 3)
    mesh_world = CollisionWorld.from_shapes([box_mesh(b) for b in boxes], 3)
    c = rng.uniform(-0.8, 0.8, (60, 3))
    r = rng.uniform(0.005, 0.15, 60)
    # well away from touching: the signed distance to each box differs from r by > 1e-3
    margin = np.full(60, np.inf)
    for b in boxes:
        g, t = coal_obstacle(b)
        for m in range(60):
            d = coal.distance(
                coal.Sphere(1e-9), tf(np.eye(3), c[m]), g, t, coal.DistanceRequest(), coal.DistanceResult()
            )
            margin[m] = min(margin[m], abs(d - r[m]))
    keep = margin > 1e-3
    want = box_world.spheres_collide(c, r)
    np.testing.assert_array_equal(mesh_world.spheres_collide(c, r)[keep], want[keep])
    # spheres deep inside a box, and a box inside a big sphere, collide with the mesh too
    inside = np.array([b.center for b in boxes])
    assert mesh_world.spheres_collide(inside, 1e-3).all()
    big = CollisionWorld.from_shapes([box_mesh(Box([0, 0, 0], [0.1, 0.1, 0.1]))], 3)
    assert big.spheres_collide(np.zeros((1, 3)), 5.0).all()
    # the mesh world stacks like any other
    stacked = CollisionWorld.stack([mesh_world, box_world])
    got = stacked.spheres_collide(np.stack([c, c]), np.stack([r, r]))
    np.testing.assert_array_equal(got[0][keep], want[keep])
    np.testing.assert_array_equal(got[1], want)


def test_mesh_box_matches_box_for_sshape() -> None:
    rng = np.random.default_rng(3)
    robot = SShape()
    b = Box([0.1, -0.05, 0.0], [0.9, 0.8, 0.85], lie.random_rotations(rng, 1)[0])
    q = robot.sample_uniform(rng, 40, -np.full(3, 1.0), np.full(3, 1.0))
    q[:3, :3] = b.center  # wholly inside the box: no bar touches its surface
    want = robot.collides(CollisionWorld.from_shapes([b], 3), q)
    got = robot.collides(CollisionWorld.from_shapes([box_mesh(b)], 3), q)
    assert want.any() and not want.all()
    np.testing.assert_array_equal(got, want)


# ============================================================================ q_free
@cache
def narrow_ws(i: int):  # type: ignore[no-untyped-def]
    return narrow2d.workspace("train", i)


@given(
    indices=st.lists(st.integers(0, 10_000), min_size=1, max_size=6),
    seed=seeds,
    scale=st.sampled_from([0.07, 0.01, 1e-3, 1e-5]),
)
@settings(max_examples=40, deadline=None)
def test_q_free_stays_free_and_in_bounds(indices: list[int], seed: int, scale: float) -> None:
    rng = np.random.default_rng(seed)
    robot = Disc2D()
    scenes = [narrow_ws(i) for i in indices]
    e = len(scenes)
    low = np.stack([s.low for s in scenes])
    high = np.stack([s.high for s in scenes])
    q = np.concatenate([robot.sample_free(s.world, rng, 1, s.low, s.high) for s in scenes])
    # push some starts against the border (where still free) so that the bounds matter
    pushed = np.clip(q, 0.003, 0.997)
    pushed_free = np.array([not robot.collides(s.world, pushed[i]) for i, s in enumerate(scenes)])
    q = np.where(((rng.random(e) < 0.5) & pushed_free)[:, None], pushed, q)
    twist = rng.uniform(-scale, scale, (e, 2))
    # the stacked world, and each scene's own world one environment at a time
    runs = [(CollisionWorld.stack([s.world for s in scenes]), slice(None))]
    runs += [(s.world, slice(i, i + 1)) for i, s in enumerate(scenes)]
    for world, rows in runs:
        q0, v, lo, hi = q[rows], twist[rows], low[rows], high[rows]
        new_q, collided, checks = q_free(robot, world, q0, v, lo, hi)
        assert new_q.shape == q0.shape and collided.shape == checks.shape == (len(q0),)
        assert np.all(new_q >= lo) and np.all(new_q <= hi)
        for j, i in enumerate(range(e)[rows]):
            assert not robot.collides(scenes[i].world, new_q[j])
        assert np.all(checks >= 1)
        # a move that did not collide ends at its target clipped into the bounds
        end = np.clip(q0 + v, lo, hi)
        np.testing.assert_allclose(new_q[~collided], end[~collided], atol=1e-12)
        # and every move ends on the segment towards that target (the one that was checked)
        d = end - q0
        s_along = np.einsum("ij,ij->i", new_q - q0, d) / np.maximum(np.einsum("ij,ij->i", d, d), 1e-18)
        np.testing.assert_allclose(new_q, q0 + s_along[:, None] * d, atol=1e-12)
        assert np.all((s_along >= -1e-9) & (s_along <= 1 + 1e-9))
        # nothing moves further than its twist
        step = np.linalg.norm(new_q - q0, axis=1)
        assert np.all(step <= np.linalg.norm(v, axis=1) + 1e-12)
        # without clipping the target, the bounds stop a move on its commanded segment instead
        stop_q, stop_col, _ = q_free(robot, world, q0, v, lo, hi, clip_target=False)
        assert np.all(stop_q >= lo) and np.all(stop_q <= hi)
        s_cmd = np.einsum("ij,ij->i", stop_q - q0, v) / np.maximum(np.einsum("ij,ij->i", v, v), 1e-18)
        np.testing.assert_allclose(stop_q, q0 + s_cmd[:, None] * v, atol=1e-12)
        inside = np.all((q0 + v >= lo) & (q0 + v <= hi), axis=1)
        assert np.all(s_cmd[~inside & ~stop_col] < 1)


def test_finer_substeps_certify_moves_closer_to_an_obstacle() -> None:
    """The motion check grows the body by half a sub-step's sweep: in an opening 2.1 bars
    wide (2 mm each side of the S-shape's bar), a turning move that the exact evaluator
    finds free (2-3 mm from the walls) is stopped short with sub-steps of 0.01 and taken
    whole with 0.005, the Slot planner's sub-step."""
    from pointplan.evaluation.clearance import Clearance, advance
    from pointplan.robots import make_robot

    robot = make_robot("sshape")
    width, bar = 2.1 * 0.036, 0.036
    walls = [Box(center=[0, s * (width / 2 + 0.5), 0], size=[bar, 1.0, 2.0]) for s in (1, -1)]
    world = CollisionWorld.from_shapes(walls, 3)
    q0 = np.array([0.073, 0.082, -0.009, 0, 0, 0, 1.0])  # the first bar through the opening
    low, high = np.full((1, 3), -2.0), np.full((1, 3), 2.0)
    exact = Clearance(robot, walls)
    assert abs(exact(q0) - (width - bar) / 2) < 1e-6
    moves = [[-0.0426, 0.0033, 0.012, 0.0018, 0.0195, -0.0008], [-0.0398, 0.0024, 0.007, -0.0198, -0.0075, 0.0202]]
    for tw in np.array(moves):
        end = robot.integrate(q0[None], tw[None])[0]
        free, low_clearance = advance(exact, robot, q0, end)
        assert free and 0.002 < low_clearance < 0.004
        coarse, stopped, _ = q_free(robot, world, q0[None], tw[None], low, high, substep=0.01)
        fine, fine_stopped, _ = q_free(robot, world, q0[None], tw[None], low, high, substep=0.005)
        assert stopped[0] and robot.distance(coarse, end[None])[0] > 0.005
        assert not fine_stopped[0]
        np.testing.assert_allclose(fine[0], end, atol=1e-9)


@given(
    index=st.integers(0, 10_000),
    box=st.integers(0, 4),
    side=st.integers(0, 3),
    t=st.floats(0.1, 0.9),
    gap=st.floats(1e-4, 4e-3),
    move=st.floats(5e-3, 9.9e-3),
)
@settings(max_examples=60, deadline=None)
def test_q_free_tiny_move_into_box_collides(index: int, box: int, side: int, t: float, gap: float, move: float) -> None:
    """A start just outside a wall, a move shorter than one sub-step into it: collided."""
    scene = narrow_ws(index)
    robot = Disc2D()
    boxes = [b for b in scene.obstacles if isinstance(b, Box)]
    b = boxes[box % len(boxes)]
    axis, sign = side // 2, (-1.0, 1.0)[side % 2]
    normal = np.zeros(2)
    normal[axis] = sign
    start = b.center + normal * (b.half[axis] + robot.radius + gap)
    start[1 - axis] = b.center[1 - axis] + (t - 0.5) * 2 * b.half[1 - axis]
    assume(np.all(start > 0) and np.all(start < 1))
    assume(not robot.collides(scene.world, start))
    assert move > gap
    twist = -normal * move
    new_q, collided, checks = q_free(robot, scene.world, start[None], twist[None], scene.low[None], scene.high[None])
    assert collided[0]
    assert checks[0] >= 2  # the start and the end (and the start's fallback check)
    np.testing.assert_array_equal(new_q[0], start)
    # the same move away from the wall is free and taken in full when the disc, grown as
    # the certified check grows it at its samples (by at most sqrt(r^2 + (move / 2)^2) - r
    # plus a contact margin of 1e-5: docs/reference/design.md, "Certified motions"), is free at both
    # ends; closer to the wall the conservative check may refuse it
    new_q, collided, _ = q_free(robot, scene.world, start[None], -twist[None], scene.low[None], scene.high[None])
    grown = Disc2D(radius=float(np.sqrt(robot.radius**2 + (move / 2) ** 2)) + 1e-5 + 1e-7)
    end = np.clip(start - twist, 0, 1)
    if not grown.collides(scene.world, np.stack([start, end])).any():
        assert not collided[0]
        np.testing.assert_allclose(new_q[0], end)


def test_q_free_clips_to_bounds() -> None:
    scene = narrow_ws(0)
    robot = Disc2D()
    q = robot.sample_free(scene.world, np.random.default_rng(0), 64, scene.low, scene.high)
    q = np.clip(q, 0.02, 0.98)
    q = q[~robot.collides(scene.world, q)]
    twist = np.where(q > 0.5, 0.07, -0.07)  # straight out of the square
    new_q, collided, _ = q_free(robot, scene.world, q, twist, np.zeros((len(q), 2)), np.ones((len(q), 2)))
    assert np.all(new_q >= 0) and np.all(new_q <= 1)
    assert not robot.collides(scene.world, new_q).any()
    # a free move ends on the border it was pushed against
    np.testing.assert_allclose(new_q[~collided], np.clip(q + twist, 0, 1)[~collided], atol=1e-12)
