"""3D scenarios: ids, determinism, disjoint splits, free starts and goals, moving obstacles,
observations (global and ray-cast), Bi-RRT in every static scene."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import pointplan  # noqa: F401  (registers the ids)
from pointplan.envs import ENV_IDS
from pointplan.evaluation.evaluate import check_path, densify, timed_path
from pointplan.geometry.collision import (
    point_cone_sqdist,
    point_cylinder_sqdist,
    point_segment_sqdist,
)
from pointplan.geometry.shapes import Box, Capsule, Cone, Cylinder, Mesh, Sphere
from pointplan.planners import make_planner
from pointplan.robots import make_robot
from pointplan.scenes.registry import SCENARIOS_3D
from pointplan.scenes.scenarios import make_scenario
from pointplan.scenes.scene import DynamicScene
from pointplan.scenes.scenes3d import SlotConfig, SlotMovingScenario, SlotScenario

#: 3D-YCB loads and decimates meshes: its cases are slow
SCENES = [pytest.param(s, marks=pytest.mark.slow) if s == "ycb3d" else s for s in SCENARIOS_3D]
STATIC = [s for s in SCENES if s != "dynamic3d"]


def surface_gap(s, p: np.ndarray) -> np.ndarray:
    """Distance of points to the surface of a shape (0 on it), independently of the sampler."""
    if isinstance(s, Box):
        local = np.abs((p - s.center) @ s.rotation) - s.half
        outside = np.linalg.norm(np.maximum(local, 0), axis=1)
        return np.where(outside > 0, outside, -local.max(1))
    if isinstance(s, Sphere):
        return np.abs(np.linalg.norm(p - s.center, axis=1) - s.radius)
    raise TypeError(type(s))


@pytest.mark.parametrize("name", SCENES)
def test_ids_pass_check_env_and_are_seeded(name: str) -> None:
    env_id = ENV_IDS[name]
    for robot in ("sphere3d", "sshape"):
        env = gym.make(env_id, robot=robot)
        check_env(env.unwrapped, skip_render_check=True)
        a = env.reset(seed=3)[0]
        b = env.reset(seed=3)[0]
        for k in a:
            np.testing.assert_array_equal(a[k], b[k])
        obs, _, _, _, info = env.step(env.action_space.sample())
        assert obs["observation"].shape == (256, 6)
        assert set(info) >= {"collided", "is_success", "collision_checks"}
        assert env.unwrapped.robot.name == robot
    local = gym.make(env_id, robot="sshape", observation="local")
    check_env(local.unwrapped, skip_render_check=True)
    assert local.reset(seed=0)[0]["observation"].shape == (64, 6)


@pytest.mark.parametrize("name", SCENES)
def test_workspaces_deterministic_disjoint_problems_free(name: str) -> None:
    sc = make_scenario(name)
    other = make_scenario(name)
    a, b = sc.scene("test", 4), other.scene("test", 4)
    assert len(a.obstacles) == len(b.obstacles)
    for s, t in zip(a.obstacles, b.obstacles):
        assert type(s) is type(t)
        if isinstance(s, Box):
            np.testing.assert_array_equal(s.center, t.center)
    fingerprints = {}
    for split in ("train", "val", "test"):
        for i in range(20):
            obs = sc.scene(split, i).obstacles
            fingerprints[(split, i)] = tuple(
                np.round(
                    np.concatenate([np.ravel(getattr(o, "center", getattr(o, "vertices", np.zeros(1)))) for o in obs]),
                    9,
                )
            )
    if name != "qureshi3d":  # Qureshi layouts are 10! permutations: collisions possible but rare
        assert len(set(fingerprints.values())) == len(fingerprints)
    for robot in ("sphere3d", "sshape"):
        sc = make_scenario(name, robot=robot)
        for p in sc.problems("test", 4):
            assert np.all(p.start[:3] >= p.scene.low) and np.all(p.start[:3] <= p.scene.high)
            assert not sc.robot.collides(p.scene.world_at(0), p.start)
            assert not sc.robot.collides(p.scene.world_at(0), p.goal)


def test_boxes_layout_matches_the_paper() -> None:
    sc = make_scenario("boxes3d")
    counts = []
    for i in range(60):
        boxes = sc.scene("train", i).obstacles
        counts.append(len(boxes))
        for b in boxes:
            assert isinstance(b, Box)
            assert np.all((b.size >= 0.15) & (b.size <= 0.5))
            assert np.all(np.abs(b.center) <= 0.45)
            np.testing.assert_allclose(b.rotation @ b.rotation.T, np.eye(3), atol=1e-12)
    assert min(counts) == 3 and max(counts) == 9
    assert sc.horizon == 80


def test_synthetic_shapes_are_never_boxes() -> None:
    sc = make_scenario("synthetic3d")
    kinds = {type(o) for i in range(30) for o in sc.scene("test", i).obstacles}
    assert kinds == {Capsule, Cylinder, Sphere, Cone}


def test_slot_width_and_sides() -> None:
    sc = SlotMovingScenario()
    assert sc.robot.name == "sshape"
    widths = []
    for i in range(30):
        scene = sc.scene("test", i)
        slot = scene.__dict__["slot"]
        widths.append(slot["width"])
        # the opening is free: a thin probe through the slot's centre does not collide
        probe = np.array([[x, *slot["center"][1:]] for x in np.linspace(-0.1, 0.1, 21)])
        assert not scene.world.spheres_collide(probe, slot["width"] / 2 - 1e-3).any()
        # but next to the slot the wall is solid
        side = slot["center"].copy()
        side[3 - slot["long_axis"]] += slot["width"] / 2 + 0.01
        assert scene.world.spheres_collide(side[None], 0.005).all()
    assert min(widths) >= 2 * 0.036 and max(widths) <= 8 * 0.036
    for p in sc.problems("test", 6):
        assert p.start[0] <= -0.3 and p.goal[0] >= 0.3


def test_the_paper_slot_has_the_gate_fixed_and_keeps_its_problems_across_the_rename() -> None:
    """``slot`` (the paper's reading): the opening centred, long along y, only its width
    random, start and goal on opposite sides; its problems are the ones drawn under its
    former name (``slotfixed``), and ``slotmoving``'s those drawn as ``slot``."""
    sc = SlotScenario()
    assert sc.name == "slot" and sc.robot.name == "sshape"
    widths = []
    for i in range(20):
        slot = sc.scene("test", i).__dict__["slot"]
        assert np.array_equal(slot["center"], np.zeros(3)) and slot["long_axis"] == 1
        widths.append(slot["width"])
    assert min(widths) >= 2 * 0.036 and max(widths) <= 8 * 0.036 and max(widths) - min(widths) > 3 * 0.036
    for p in sc.problems("test", 4):
        assert p.start[0] <= -0.3 and p.goal[0] >= 0.3

    # the other Slot variants keep streams of their own names
    assert [make_scenario(n).stream_name for n in ("slotwide", "slotclassic")] == ["slotwide", "slotclassic"]

    class Former(SlotMovingScenario):
        stream = None  # seeded from its name, as before the rename

    for former, now in (("slotfixed", sc), ("slot", make_scenario("slotmoving"))):
        old = Former(config=now.slot)
        old.name = former
        for i in range(3):
            a, b = old.problem("val", i, seed=1), now.problem("val", i, seed=1)
            assert np.array_equal(a.start, b.start) and np.array_equal(a.goal, b.goal)
            assert a.scene.__dict__["slot"]["width"] == b.scene.__dict__["slot"]["width"]


def test_slotwide_draws_only_wide_slots_from_its_own_workspaces() -> None:
    wide, slot = make_scenario("slotwide"), make_scenario("slotmoving")
    assert wide.robot.name == "sshape"
    widths = [wide.scene("train", i).__dict__["slot"]["width"] for i in range(40)]
    assert min(widths) >= 4 * 0.036 and max(widths) <= 8 * 0.036
    assert max(widths) - min(widths) > 2 * 0.036  # the range is used, not one width
    # its own stream: the same index is not Slot's workspace with another width
    assert not np.allclose(
        wide.scene("train", 0).__dict__["slot"]["center"], slot.scene("train", 0).__dict__["slot"]["center"]
    )


def test_qureshi_sizes_are_permuted_at_fixed_centres() -> None:
    sc = make_scenario("qureshi3d")
    a, b = sc.scene("test", 0).obstacles, sc.scene("test", 1).obstacles
    np.testing.assert_array_equal([o.center for o in a], [o.center for o in b])
    assert sorted(map(tuple, (o.size for o in a))) == sorted(map(tuple, (o.size for o in b)))
    assert any(not np.array_equal(x.size, y.size) for x, y in zip(a, b))
    assert all(np.array_equal(o.rotation, np.eye(3)) for o in a)

    # only 10! layouts exist: the splits own disjoint sets of them
    def layout(scene):
        return tuple(tuple(o.size) for o in scene.obstacles)

    test = {layout(sc.scene("test", i)) for i in range(200)}
    train = {layout(sc.scene("train", i)) for i in range(2000)}
    assert not test & train


def test_dynamic_period_one_way_reaches_the_second_placement_at_the_horizon() -> None:
    """``period=2 * horizon``: the same two placements, the second reached at the horizon;
    a period under one step is refused."""
    from pointplan.scenes.scenes3d import Dynamic3DScenario

    default, one_way = Dynamic3DScenario(), Dynamic3DScenario(period=160)
    a, b = default.scene("test", 2), one_way.scene("test", 2)
    assert isinstance(b, DynamicScene) and a.period == 80 and b.period == 160
    np.testing.assert_array_equal(a.obstacles[0].center, b.obstacles[0].center)
    np.testing.assert_array_equal(a.targets[0].center, b.targets[0].center)
    np.testing.assert_allclose(b.obstacles_at(80)[0].center, b.targets[0].center, atol=1e-12)
    np.testing.assert_allclose(b.obstacles_at(40)[0].center, a.obstacles_at(20)[0].center, atol=1e-12)
    with pytest.raises(ValueError, match="period"):
        Dynamic3DScenario(period=0)


def test_dynamic_obstacles_follow_the_clock() -> None:
    sc = make_scenario("dynamic3d")
    scene = sc.scene("test", 2)
    assert isinstance(scene, DynamicScene)
    b0, b1 = scene.obstacles[0], scene.targets[0]
    half = scene.period // 2
    at = scene.obstacles_at(half)[0]
    np.testing.assert_allclose(at.center, b1.center, atol=1e-12)
    np.testing.assert_allclose(at.rotation, b1.rotation, atol=1e-9)
    np.testing.assert_allclose(scene.obstacles_at(scene.period)[0].center, b0.center, atol=1e-12)
    quarter = scene.obstacles_at(half // 2)[0]
    np.testing.assert_allclose(quarter.center, (b0.center + b1.center) / 2, atol=1e-12)
    # the env checks collisions against the obstacles at the next time step
    env = gym.make(ENV_IDS["dynamic3d"]).unwrapped
    env.reset(seed=0)
    core = env.core
    scene = core.scenes[0]
    for t in range(3):
        c, _ = scene.poses_at(t + 1)
        core.q[0] = c[0]  # put the robot inside box 0 where it will be at t + 1 ...
        core.q[0] = np.clip(core.q[0], -0.6, 0.6)
        inside_next = bool(core.robot.collides(scene.world_at(t + 1), core.q[0]))
        _, _, _, _, info = env.step(np.zeros(3, np.float32))
        assert info["collided"] == inside_next  # ... a zero move collides there
    # the global observation moves with the boxes: every observed point lies on a box at t
    env = gym.make(ENV_IDS["dynamic3d"], observation="global").unwrapped
    obs, _ = env.reset(seed=1)
    for _ in range(5):
        obs, *_ = env.step(env.action_space.sample())
    t = int(env.core.t[0])
    world_pts = obs["observation"][:, :3] + env.core.q[0]
    boxes = env.core.scenes[0].obstacles_at(t)
    gap = np.min([surface_gap(b, world_pts) for b in boxes], axis=0)
    assert gap.max() < 1e-5


def test_global_points_lie_on_surfaces_with_outward_normals() -> None:
    sc = make_scenario("boxes3d")
    env = gym.make(ENV_IDS["boxes3d"], observation="global").unwrapped
    obs, _ = env.reset(seed=5, options={"problem": sc.problem("test", 0)})
    p = obs["observation"][:, :3] + env.core.q[0]
    n = obs["observation"][:, 3:]
    boxes = sc.scene("test", 0).obstacles
    gaps = np.stack([surface_gap(b, p) for b in boxes])
    assert gaps.min(0).max() < 1e-5
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-5)
    # outward: a small step along the normal leaves every box
    out = p + 1e-3 * n
    for b in boxes:
        assert not np.any(np.all(np.abs((out - b.center) @ b.rotation) < b.half - 1e-9, axis=1))
    # area-weighted: the share of points on each box tracks its share of the area
    many = np.concatenate(
        [env.core.observer.observe(env.core.q, np.random.default_rng(k), env.core.t)[0] for k in range(20)]
    )
    owner = np.argmin(np.stack([surface_gap(b, many[:, :3] + env.core.q[0]) for b in boxes]), 0)
    share = np.bincount(owner, minlength=len(boxes)) / len(owner)
    area = np.array([2 * (b.size[0] * b.size[1] + b.size[1] * b.size[2] + b.size[0] * b.size[2]) for b in boxes])
    assert np.abs(share - area / area.sum()).max() < 0.12  # overlaps hide some area


@pytest.mark.parametrize("robot", ["sphere3d", "sshape"])
def test_local_rays_hit_surfaces_facing_the_rays(robot: str) -> None:
    sc = make_scenario("synthetic3d", robot=robot)
    env = gym.make(ENV_IDS["synthetic3d"], robot=robot, observation="local").unwrapped
    obs_space = env.observation_space["observation"]
    assert obs_space.shape == (64, 6)
    problem = sc.problem("test", 1)
    env.reset(seed=0, options={"problem": problem})
    observer = env.core.observer
    pts, nrm, ok = observer.cast(env.core.q, env.core.t)
    assert ok.any()
    p, n = pts[0][ok[0]], nrm[0][ok[0]]
    shapes = list(problem.scene.obstacles) + __import__("pointplan.observers.rays", fromlist=["wall_slabs"]).wall_slabs(
        problem.scene.low, problem.scene.high
    )
    d2 = []
    for s in shapes:
        if isinstance(s, (Box, Sphere)):
            d2.append(surface_gap(s, p) ** 2)
        elif isinstance(s, Capsule):
            d2.append((np.sqrt(point_segment_sqdist(p, s.a[None], s.b[None])[:, 0]) - s.radius) ** 2)
        elif isinstance(s, Cylinder):
            # on the surface: inside the slightly grown cylinder, outside the shrunk one
            grown = point_cylinder_sqdist(
                p, s.center[None], s.rotation[None], np.array([s.radius + 1e-6]), np.array([s.length / 2 + 1e-6])
            )[:, 0]
            shrunk = point_cylinder_sqdist(
                p, s.center[None], s.rotation[None], np.array([s.radius - 1e-6]), np.array([s.length / 2 - 1e-6])
            )[:, 0]
            d2.append(np.where((grown <= 0) & (shrunk > 0), 0.0, 1.0))
        elif isinstance(s, Cone):
            grown = point_cone_sqdist(
                p, s.center[None], s.rotation[None], np.array([s.radius]), np.array([s.length / 2])
            )[:, 0]
            d2.append(np.where(grown <= 1e-10, 0.0, 1.0))
        elif isinstance(s, Mesh):
            continue
    assert np.min(d2, axis=0).max() < 1e-8
    # normals are unit and face the ray that found them
    origins = np.einsum("ij,rj->ri", env.robot.rotations(env.core.q[0]), observer.body_origins) + env.robot.positions(
        env.core.q[0]
    )
    dirs = np.einsum("ij,rj->ri", env.robot.rotations(env.core.q[0]), observer.body_dirs)[ok[0]]
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-6)
    assert np.all(np.einsum("ri,ri->r", n, dirs) <= 1e-9)
    assert np.all(np.linalg.norm(p - origins[ok[0]], axis=1) <= 0.7 + 1e-9)
    # the observation is 64 of those hits, thinned, in the robot frame
    obs = env.core.observer.observe(env.core.q, np.random.default_rng(0), env.core.t)[0]
    back = np.einsum("ij,nj->ni", env.robot.rotations(env.core.q[0]), obs[:, :3]) + env.robot.positions(env.core.q[0])
    dist = np.min(np.linalg.norm(back[:, None] - p[None], axis=-1), axis=1)
    assert dist.max() < 1e-5


@pytest.mark.parametrize("name", STATIC)
def test_birrt_solves_fixed_problems_and_paths_pass_the_check(name: str) -> None:
    robots = ["sshape"] if name.startswith("slot") else ["sphere3d", "sshape"]
    for robot in robots:
        # Slot: the widest slot (8 bars) keeps the test fast; narrow ones take 1e4+ nodes
        sc = (
            SlotMovingScenario(config=SlotConfig(min_width_bars=8, max_width_bars=8))
            if name.startswith("slot")
            else make_scenario(name, robot=robot)
        )
        planner = make_planner("birrt", sc.robot, seed=0, max_nodes=20000)
        problems = sc.problems("test", 2)
        for p in problems:
            res = planner.plan(p)
            assert res.success, (name, robot, p.tag)
            assert check_path(sc.robot, p, res.path)
            # and the checker can fail: a path cut through the middle of an obstacle does not pass
            bad = np.array([p.start, p.goal])
            if sc.robot.collides(p.scene.world, densify(sc.robot, bad, 0.01)).any():
                assert not check_path(sc.robot, p, bad)


def test_straight_line_in_3d_and_timed_paths() -> None:
    sc = make_scenario("boxes3d", robot="sshape")
    straight = make_planner("straight", sc.robot)
    results = [straight.plan(p) for p in sc.problems("test", 10)]
    assert all(
        r.success == bool(check_path(sc.robot, p, r.path))
        for r, p in zip(results, sc.problems("test", 10))
        if r.success
    )
    robot = make_robot("sshape")
    path = np.array([[0, 0, 0, 0, 0, 0, 1.0], [0.2, 0, 0, 0, 0, 0, 1.0]])
    timed = timed_path(robot, path)
    assert len(timed) == 4  # 0.2 / 0.07 -> 3 moves
    steps = robot.log(timed[:-1], timed[1:])
    assert np.all(np.abs(steps) <= robot.action_scale + 1e-12)


def test_3d_ids_reject_2d_robots_and_unknown_names() -> None:
    with pytest.raises(ValueError, match="3D"):
        make_scenario("boxes3d", robot="disc2d")
    with pytest.raises(ValueError, match="unknown environment"):
        make_scenario("boxes4d")
    with pytest.raises(ValueError, match="unknown robot"):
        gym.make(ENV_IDS["slot"], robot="cube")


@pytest.mark.parametrize("name", ["boxes3d", "dynamic3d"])
@pytest.mark.parametrize("robot", ["sphere3d", "sshape"])
def test_env_and_evaluator_agree_on_noisy_rollouts(name: str, robot: str) -> None:
    """A noisy go-to-goal controller rolled out in the env: the evaluator's independent
    re-check of each path says success exactly when the env did (moving obstacles, the
    bounds and the S-shape's curved moves included)."""
    from pointplan.envs.core import EnvConfig
    from pointplan.planners.policy import rollout_batch

    sc = make_scenario(name, robot=robot)
    r = sc.robot
    rng = np.random.default_rng(1)

    def act(obs: np.ndarray, q: np.ndarray, goal: np.ndarray) -> np.ndarray:
        v = r.log(q, goal) / r.action_scale
        v = v / np.maximum(1.0, np.abs(v).max(-1, keepdims=True))
        return np.clip(v + rng.normal(0.0, 0.5, v.shape), -1, 1).astype(np.float32)

    problems = sc.problems("test", 24)
    results = rollout_batch(act, r, EnvConfig(observation="global"), problems, 80)
    verdicts = [bool(check_path(r, p, x.path)) for p, x in zip(problems, results)]
    assert [x.success for x in results] == verdicts
    assert 0 < sum(verdicts) < len(verdicts)  # both outcomes occur, so the comparison means something


@pytest.mark.parametrize("robot", ["sphere3d", "sshape"])
def test_local_near_keeps_the_nearest_thinned_hits(robot: str) -> None:
    from pointplan.observers import make_observer
    from pointplan.observers.rays import thin_grid

    sc = make_scenario("boxes3d", robot=robot)
    r = sc.robot
    for i in range(4):
        problem = sc.problem("val", i)
        q = problem.start[None]
        near = make_observer("local-near", r, n_points=16)
        near.bind([problem.scene])
        pts, nrm, ok = near.cast(q)
        kept = thin_grid(pts, nrm, ok, near.spacing)[0]
        origins = np.einsum("ij,rj->ri", r.rotations(q[0]), near.body_origins) + r.positions(q[0])
        d = np.linalg.norm(pts[0] - origins, axis=1)[kept]  # every thinned hit's ray length
        assert kept.sum() > 16
        obs = near.observe(q, np.random.default_rng(i))[0]
        back = np.einsum("ij,nj->ni", r.rotations(q[0]), obs[:, :3]) + r.positions(q[0])
        # each observed point is one of the thinned hits, no two the same, and together they
        # are the 16 hits with the shortest rays
        j = np.argmin(np.linalg.norm(back[:, None] - pts[0][kept][None], axis=-1), axis=1)
        np.testing.assert_allclose(back, pts[0][kept][j], atol=1e-5)
        assert len(set(j.tolist())) == 16
        np.testing.assert_allclose(np.sort(d[j]), np.sort(d)[:16], atol=1e-9)
        # the default observer draws a random subset instead: over draws it reaches farther
        rand = make_observer("local", r, n_points=16)
        rand.bind([problem.scene])
        far = [np.linalg.norm(rand.observe(q, np.random.default_rng(k))[0][:, :3], axis=1).max() for k in range(5)]
        assert max(far) > np.linalg.norm(obs[:, :3], axis=1).max()
    # fewer hits than points: every hit once, the rest duplicates of hits
    near = make_observer("local-near", r, n_points=400)
    problem = sc.problem("val", 0)
    near.bind([problem.scene])
    obs = near.observe(problem.start[None], np.random.default_rng(0))[0]
    assert len(np.unique(obs.round(6), axis=0)) == thin_grid(*near.cast(problem.start[None]), near.spacing)[0].sum()


def test_local_wide_sees_through_slots_opening_and_its_points_lie_on_surfaces() -> None:
    from pointplan.observers import make_observer
    from pointplan.observers.rays import wall_slabs

    sc = make_scenario("slot", robot="sshape")
    r = sc.robot
    wide, local = make_observer("local-wide", r), make_observer("local", r)
    assert wide.space.shape == (128, 6) and len(wide.body_dirs) == 6 * (1024 // 6)
    behind = {"wide": 0, "local": 0}
    for i in range(8):
        problem = sc.problem("val", i)
        q = problem.start[None]
        boxes = list(problem.scene.obstacles) + wall_slabs(problem.scene.low, problem.scene.high)
        for name, obs_ in (("wide", wide), ("local", local)):
            obs_.bind([problem.scene])
            obs = obs_.observe(q, np.random.default_rng(i))[0]
            pts = np.einsum("ij,nj->ni", r.rotations(q[0]), obs[:, :3]) + r.positions(q[0])
            # every point is on the surface of a box (axis-aligned here): closed-form
            # signed distance, independent of the ray caster
            d = np.full(len(pts), np.inf)
            for b in boxes:
                assert np.allclose(b.rotation, np.eye(3))
                e = np.abs(pts - b.center) - b.size / 2
                sd = np.linalg.norm(np.maximum(e, 0.0), axis=1) + np.minimum(e.max(axis=1), 0.0)
                d = np.minimum(d, np.abs(sd))
            assert d.max() < 1e-6
            # the start is on the x < -0.3 side: a point beyond the wall was seen through the opening
            behind[name] += int(np.sum(pts[:, 0] > 0.03))
    assert behind["wide"] > 0 and behind["local"] == 0
