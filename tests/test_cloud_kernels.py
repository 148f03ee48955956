"""The S-shape's compiled checks against point clouds (robots/_cloud_kernels.py, the grid
of ``CollisionWorld.cloud_grid``) against the numpy ones through the k-d tree
(``boxes_contain_cloud_points``) and the brute force: the same answers for boxes, the same
collisions, motion checks, marches and Bi-RRT paths for the body, in scenes given as
clouds of 3D-Boxes workspaces (alone or with some of the boxes)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from pointplan.geometry.collision import (
    _MAX_GRID_CELLS,
    CollisionWorld,
    boxes_contain_cloud_points,
    cloud_grid_arrays,
    sphere_box_sqdist,
)
from pointplan.geometry.sampling import area_weighted_points
from pointplan.geometry.shapes import PointCloud, Sphere
from pointplan.robots._cloud_kernels import boxes_contain_cloud_points_compiled
from pointplan.robots.base import Robot
from pointplan.robots.sshape import SShape
from pointplan.scenes.scenarios import make_scenario
from pointplan.scenes.scene import Problem, Scene


def _brute(pts: np.ndarray, c: np.ndarray, rot: np.ndarray, h: np.ndarray, margin: float) -> np.ndarray:
    return np.any(sphere_box_sqdist(pts, c, rot, h) <= margin * margin, 0)


def _boxes_and_points(seed: int, m: int = 400) -> tuple[np.ndarray, ...]:
    """Random boxes (bars, plates, cubes) and a cloud: uniform points, and points on the
    boxes' faces, edges and corners, and at about the margin outside them."""
    rng = np.random.default_rng(seed)
    c = rng.uniform(0, 1, (m, 3))
    rot = Rotation.random(m, random_state=seed).as_matrix()
    rot[: m // 8] = np.eye(3)  # some axis-aligned: exact zeros in the rotations
    h = np.stack([rng.uniform(0.05, 0.15, m), rng.uniform(0.003, 0.02, m), rng.uniform(0.003, 0.1, m)], -1)
    k = rng.integers(0, m, 300)
    # each coordinate on a face (+-1), inside (uniform) or a margin-ish beyond: faces, edges, corners
    s = rng.choice([-1.0, 1.0], (300, 3)) * np.where(rng.random((300, 3)) < 0.7, 1.0, rng.uniform(0, 1, (300, 3)))
    local = h[k] * s + np.sign(s) * rng.choice([0.0, 0.004, 0.00399, 0.00401, 0.00283], (300, 3))
    near = c[k] + np.einsum("kij,kj->ki", rot[k], local)
    pts = np.concatenate([rng.uniform(-0.1, 1.1, (3000, 3)), near])
    # a box holding the whole cloud, boxes far off it, one on its bounding box's corner
    c = np.concatenate([c, [[0.5, 0.5, 0.5], [1e6, 0.5, 0.5], [-3.0, -3.0, -3.0], pts.min(0)]])
    rot = np.concatenate([rot, np.eye(3)[None].repeat(4, 0)])
    h = np.concatenate([h, [[5.0, 5.0, 5.0], [0.1, 0.1, 0.1], [1.0, 1.0, 1.0], [0.001, 0.001, 0.001]]])
    return pts, c, rot, h


@pytest.mark.parametrize("seed", range(3))
def test_grid_is_the_tree_and_the_brute_force(seed: int) -> None:
    pts, c, rot, h = _boxes_and_points(seed)
    tree = cKDTree(pts)
    for margin in (0.0, 0.004):
        expect = _brute(pts, c, rot, h, margin)
        assert 0 < expect.sum() < len(c)
        np.testing.assert_array_equal(boxes_contain_cloud_points(tree, c, rot, h, margin), expect)
        for cell in (0.004, 0.03, 0.25, 10.0):  # cells far smaller than the boxes, about them, far larger
            got = boxes_contain_cloud_points_compiled(cloud_grid_arrays(pts, cell, margin), c, rot, h)
            np.testing.assert_array_equal(got, expect)


def test_grid_answers_at_the_boundary() -> None:
    """A point exactly on a face, an edge or a corner of the closed box, or exactly the
    radius off a face, touches it; a hair further does not (as in the numpy test)."""
    c, rot, h = np.array([[0.25, 0.5, 0.75]]), np.eye(3)[None], np.array([[0.125, 0.25, 0.0625]])
    hair, d = 2.0**-30, 0.125 / np.sqrt(2.0)
    cases = [  # (point, radius, touches: None where round-off decides)
        ([0.375, 0.5, 0.75], 0.0, True),  # a face
        ([0.375, 0.25, 0.75], 0.0, True),  # an edge
        ([0.125, 0.75, 0.8125], 0.0, True),  # a corner
        ([0.375 + hair, 0.5, 0.75], 0.0, False),
        ([0.125, 0.75, 0.8125 + hair], 0.0, False),
        ([0.5, 0.5, 0.75], 0.125, True),  # the radius off a face
        ([0.5, 0.25, 0.75], 0.125, True),
        ([0.5 + hair, 0.5, 0.75], 0.125, False),
        ([0.375 + d, 0.75 + d, 0.75], 0.125, None),  # the radius off an edge, diagonally
        ([0.375 + d + hair, 0.75 + d, 0.75], 0.125, False),
        ([0.125 - d, 0.25 - d, 0.8125], 0.125, None),
    ]
    for point, margin, touches in cases:
        pts = np.array([point, [5.0, 5.0, 5.0]])
        expect = _brute(pts, c, rot, h, margin)
        assert touches is None or bool(expect[0]) == touches
        np.testing.assert_array_equal(boxes_contain_cloud_points(cKDTree(pts), c, rot, h, margin), expect)
        for cell in (0.01, 0.125, 1.0):
            got = boxes_contain_cloud_points_compiled(cloud_grid_arrays(pts, cell, margin), c, rot, h)
            np.testing.assert_array_equal(got, expect)


def test_cloud_grid_layout_and_cache() -> None:
    rng = np.random.default_rng(2)
    pts = rng.uniform(-1, 2, (500, 3))
    sorted_pts, starts, origin, dims, params, cum = cloud_grid_arrays(pts, 0.3, 0.01)
    assert sorted(map(tuple, sorted_pts)) == sorted(map(tuple, pts))
    cells = np.floor((sorted_pts - origin) * params[0]).astype(np.int64)
    rows = (cells[:, 0] * dims[1] + cells[:, 1]) * dims[2] + cells[:, 2]
    counts = np.diff(starts)
    np.testing.assert_array_equal(np.repeat(np.arange(len(counts)), counts), rows)
    assert cum.reshape(tuple(dims + 1))[-1, -1, -1] == len(pts) and np.all(counts >= 0)
    assert len(cloud_grid_arrays(pts, 1e-6, 0.0)[1]) - 1 <= _MAX_GRID_CELLS  # the cells widened to fit
    world = CollisionWorld.from_shapes([PointCloud(pts, np.zeros_like(pts))], 3)
    grid = world.cloud_grid(0.3)
    assert grid is not None and world.cloud_grid(0.3) is grid and world.cloud_grid(0.2) is not grid
    assert grid[4][2] == world.cloud_radius[0] > 0
    other = CollisionWorld.from_shapes([PointCloud(pts + 1.0, np.zeros_like(pts))], 3)
    assert other.cloud_grid(0.3) is not grid
    empty = CollisionWorld.from_shapes([PointCloud(np.zeros((0, 3)), np.zeros((0, 3)))], 3)
    assert empty.cloud_grid(0.3) is None
    assert world.boxes_and_clouds_only and not world.boxes_only and empty.boxes_and_clouds_only
    assert not CollisionWorld.from_shapes([PointCloud(pts, pts), Sphere([0, 0, 0], 0.1)], 3).boxes_and_clouds_only


class _PlainSShape(SShape):
    """The S-shape with every check in numpy through the k-d tree (the same integrate and
    log)."""

    def collides(self, *args: object, **kw: object):  # type: ignore[no-untyped-def]
        return Robot.collides(self, *args, **kw)  # type: ignore[arg-type]

    def check_motions(self, *args: object, **kw: object):  # type: ignore[no-untyped-def]
        return Robot.check_motions(self, *args, **kw)  # type: ignore[arg-type]

    def march_compiled(self, *args: object) -> None:
        return None

    def shortcut_compiled(self, *args: object) -> None:
        return None


@pytest.fixture(scope="module")
def cloud_problems() -> list[Problem]:
    """3D-Boxes test problems in their scenes given as clouds of the boxes' surfaces: alone
    (4000 and 12000 points) and with two of the boxes kept as boxes."""
    out = []
    rng = np.random.default_rng(5)
    for k, p in enumerate(make_scenario("boxes3d", robot="sshape").problems("test", 6, seed=2026)):
        obstacles = p.scene.obstacles
        pts, nrm, _ = area_weighted_points(obstacles if k % 3 != 2 else obstacles[2:], 4000 + 8000 * (k % 2), rng)
        kept = list(obstacles[:2]) if k % 3 == 2 else []
        out.append(Problem(Scene([PointCloud(pts, nrm), *kept], p.scene.low, p.scene.high), p.start, p.goal))
    return out


def test_compiled_collides_is_the_numpy_one(cloud_problems: list[Problem]) -> None:
    fast, plain = SShape(), _PlainSShape()
    rng = np.random.default_rng(3)
    for p in cloud_problems:
        world = p.scene.world
        assert world.boxes_and_clouds_only and not world.boxes_only
        q = fast.sample_uniform(rng, 300, p.scene.low, p.scene.high).reshape(3, 100, 7)
        halfs = fast.parts.box_halfs + rng.uniform(0, 0.02, (3, 100, 1, 1))
        for h in (None, halfs):
            a, b = fast.collides(world, q, halfs=h), plain.collides(world, q, halfs=h)
            assert a.shape == (3, 100) and 0 < a.sum() < a.size
            np.testing.assert_array_equal(a, b)


def test_compiled_motion_checks_on_clouds_are_the_numpy_ones(cloud_problems: list[Problem]) -> None:
    """SShape.check_motions in scenes of clouds (and boxes) against the numpy check: the
    same certified sub-steps, collisions, counts and samples, with and without bounds and
    the start fallback; a stacked world of clouds takes the numpy check."""
    fast, plain = SShape(), _PlainSShape()
    rng = np.random.default_rng(7)
    kinds = set()
    for p in cloud_problems:
        scene = p.scene
        q0 = np.concatenate([fast.sample_free(scene.world, rng, 30, scene.low, scene.high),
                             fast.sample_uniform(rng, 10, scene.low - 0.05, scene.high + 0.05)])  # fmt: skip
        tw = rng.normal(size=(40, 6)) * rng.choice([0.01, 0.07, 0.4], size=(40, 1))
        n = rng.integers(1, 30, 40)
        fb = rng.random(40) < 0.7
        for args in ((), (scene.low, scene.high), (scene.low, scene.high, fb)):
            a = fast.check_motions(scene.world, q0, tw, n, *args)
            b = plain.check_motions(scene.world, q0, tw, n, *args)
            assert np.array_equal(a.free, b.free) and np.array_equal(a.collided, b.collided)
            assert np.array_equal(a.checks, b.checks) and np.array_equal(a.configs, b.configs)
            kinds |= set(zip((a.free == n).tolist(), a.collided.tolist(), (a.free < 0).tolist()))
    assert len(kinds) >= 4
    stacked = CollisionWorld.stack([p.scene.world for p in cloud_problems[:3]])
    q0 = np.stack([fast.sample_uniform(rng, 1, p.scene.low, p.scene.high)[0] for p in cloud_problems[:3]])
    tw = rng.normal(size=(3, 6)) * 0.1
    a = fast.check_motions(stacked, q0, tw, np.full(3, 10))
    b = plain.check_motions(stacked, q0, tw, np.full(3, 10))
    assert np.array_equal(a.free, b.free) and np.array_equal(a.configs, b.configs)


def test_compiled_march_and_birrt_on_clouds_are_the_numpy_ones(cloud_problems: list[Problem]) -> None:
    """march and Bi-RRT (its shortcuts included) compiled against a cloud, against numpy:
    the same nodes, answers, counts and paths."""
    from pointplan.planners.base import march
    from pointplan.planners.birrt import BiRRT

    fast, plain = SShape(), _PlainSShape()
    rng = np.random.default_rng(11)
    kinds = set()
    for k, p in enumerate(cloud_problems[:4]):
        qs = fast.sample_free(p.scene.world, np.random.default_rng(20 + k), 10, p.scene.low, p.scene.high)
        for i in range(len(qs) - 1):
            step = float(rng.choice([0.07, 0.3, 1e12]))
            budget = None if i % 3 else int(rng.integers(1, 5))
            a = march(fast, p, qs[i], qs[i + 1], step, 0.01, budget)
            b = march(plain, p, qs[i], qs[i + 1], step, 0.01, budget)
            # (the same nodes up to the last bit or two: numpy's and the compiler's vector
            # code may round a product differently on some CPUs)
            assert a.nodes.shape == b.nodes.shape and np.allclose(a.nodes, b.nodes, rtol=0, atol=1e-13)
            assert (a.reached, a.checks) == (b.reached, b.checks)
            kinds.add((a.reached, len(a.nodes) > 0))
    assert len(kinds) >= 3
    shortened = 0
    for p in cloud_problems[1:5]:
        a = BiRRT(fast, max_nodes=300, shortcut_probes=0).plan(p)
        b = BiRRT(plain, max_nodes=300, shortcut_probes=0).plan(p)
        assert a.success == b.success and a.collision_checks == b.collision_checks
        assert a.path.shape == b.path.shape and np.allclose(a.path, b.path, rtol=0, atol=1e-12)
        shortened += a.success and len(a.path) < len(a.raw_path)
    assert shortened > 0


def test_the_points_policy_on_a_cloud_is_compiled_and_the_step_loop(
    cloud_problems: list[Problem], same_rollout: Callable[[object, object], bool]
) -> None:
    """The S-shape's global policy plans a scanned scene through the compiled rollout (its
    checks against the cloud's grid): the step loop's rollouts, paths free of the cloud."""
    import torch

    from pointplan.evaluation import check_path
    from pointplan.planners import make_planner

    torch.set_num_threads(1)
    fast = make_planner("policy", SShape(), observation="global")
    ref = make_planner("policy", SShape(), observation="global", compiled=False)
    same = 0
    for p in cloud_problems:
        a, b = fast.plan(p), ref.plan(p)
        assert "compiled" in a.info["time_split"]
        same += same_rollout(a, b)
        if a.success:
            assert check_path(SShape(), p, a.path)
    assert same >= len(cloud_problems) - 1


@pytest.mark.parametrize(("n_points", "cell"), [(20000, 0.036), (1500, 0.036), (20000, 0.006), (20000, 0.0128)])
def test_rays_hit_the_grid_as_the_brute_force(n_points: int, cell: float) -> None:
    """``ray_hits_cloud`` (the cells along the ray) against ``_first_cloud_hits`` over every
    point of the cloud: the same distance, the same point (the lowest index of equally near
    ones), for rays from anywhere (inside points' spheres, outside the grid, along the
    axes), with a point radius under a cell, over one (a sparse cloud) and over several
    cells (small cells)."""
    from pointplan.geometry.raycast import _first_cloud_hits
    from pointplan.robots._cloud_kernels import ray_hits_cloud

    p = make_scenario("boxes3d", robot="sshape").problems("test", 1, seed=2026)[0]
    rng = np.random.default_rng(n_points)
    pts, nrm, _ = area_weighted_points(p.scene.obstacles, n_points, rng)
    pts[:5] = pts[5]  # equally near points
    world = CollisionWorld.from_shapes([PointCloud(pts, nrm)], 3)
    got = world.cloud_ray_grid(cell)
    assert got is not None
    grid, normals, oid = got
    assert np.array_equal(world.cloud_trees[0].data[oid], grid[0])
    assert np.array_equal(world.cloud_normals[0][oid], normals)
    r, n = float(world.cloud_radius[0]), 2000
    o = rng.uniform(-0.9, 0.9, (n, 3))
    o[:300] = pts[rng.integers(0, n_points, 300)] + rng.normal(0, r / 2, (300, 3))
    o[300:310] = pts[5]
    d = rng.normal(size=(n, 3))
    d[:200, 0] = 0.0
    d[200:260, 1:] = 0.0
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    limit = rng.choice([np.inf, 0.2, 1.0], n)
    best, which = limit.copy(), np.full(n, -1)
    _first_cloud_hits(o, d, world.cloud_trees[0].data, r, best, which)
    bound, hits = 0.7, 0
    for i in range(n):
        t, k = ray_hits_cloud(o[i], d[i], grid, oid, limit[i], bound)
        if best[i] <= bound:
            hits += which[i] >= 0
            assert t == best[i] and (k >= 0) == (which[i] >= 0)
            assert k < 0 or oid[k] == which[i]
        else:
            assert t > bound
    assert hits > n // 5


def test_the_rays_policy_on_a_cloud_is_compiled_and_the_step_loop(
    cloud_problems: list[Problem], same_rollout: Callable[[object, object], bool]
) -> None:
    """The S-shape's local policy sees a scanned scene through the compiled rollout too
    (its rays against the cloud's grid): the step loop's observations and rollouts (its
    rays through ``cast_rays``), paths free of the cloud."""
    import torch

    from pointplan.evaluation import check_path
    from pointplan.planners import make_planner

    torch.set_num_threads(1)
    fast = make_planner("policy", SShape(), observation="local")
    ref = make_planner("policy", SShape(), observation="local", compiled=False)
    same, moved = 0, 0
    for p in cloud_problems:
        a, b = fast.plan(p), ref.plan(p)
        assert "compiled" in a.info["time_split"]
        moved += len(a.path) > 3
        same += same_rollout(a, b)
        if a.success:
            assert check_path(SShape(), p, a.path)
    assert same >= len(cloud_problems) - 1 and moved >= 2


def test_sphere_queries_on_the_grid_match_a_kd_tree() -> None:
    """``grid_point_within`` (through ``CollisionWorld.spheres_collide``) and
    ``grid_nearest_bound`` against scipy's k-d tree on a cloud and random spheres: the same
    hits, the nearest distance where it is within the cap, a lower bound at least the cap
    where it is not."""
    from pointplan.geometry._kernels import grid_nearest_bound

    rng = np.random.default_rng(4)
    pts = rng.uniform(-0.5, 0.5, (3000, 3)) * [1.0, 1.0, 0.1]  # a thick sheet of points
    cloud = PointCloud(pts, np.tile([0.0, 0.0, 1.0], (len(pts), 1)), radius=0.004)
    scene = Scene([cloud], np.full(3, -1.0), np.full(3, 1.0))
    world = scene.world
    c = rng.uniform(-0.7, 0.7, (4000, 3))
    r = rng.uniform(0.0, 0.08, 4000)
    tree = cKDTree(pts)
    dist, _ = tree.query(c)
    assert np.array_equal(world.spheres_collide(c, r), dist <= r + 0.004)
    assert 200 < (dist <= r + 0.004).sum() < 3800
    grid = world.sphere_grid()
    assert grid is not None
    p, starts, origin, dims, params, _ = grid
    cap = 0.15
    got = np.array([grid_nearest_bound(x, y, z, cap, p, starts, origin, dims, params) for x, y, z in c])
    near = dist <= cap
    assert np.allclose(got[near], dist[near], rtol=0, atol=1e-12)
    assert np.all(got[~near] >= cap) and np.all(got[~near] <= dist[~near] + 1e-12)
    assert near.sum() > 500 and (~near).sum() > 500
