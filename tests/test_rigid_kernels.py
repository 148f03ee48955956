"""The compiled rollout of the S-shape seeing rays (planners/_rigid_kernels.py) against the
numpy code it replaces: each piece with the same inputs, then whole rollouts against the
step loop through the batched core (PyTorch network)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from pointplan.envs.core import q_free
from pointplan.evaluation import check_path
from pointplan.models.policy import NumpyPointNetActor
from pointplan.observers.rays import LocalRays, WideRays
from pointplan.planners import _rigid_kernels as RK
from pointplan.planners import make_planner
from pointplan.planners._policy_kernels import _workspace, pack_weights
from pointplan.planners.edges import edge_free
from pointplan.planners.rollout_compiled import CompiledRays
from pointplan.robots import _body_kernels as BK
from pointplan.robots.motion import CONTACT_MARGIN
from pointplan.robots.sshape import SShape
from pointplan.scenes.scenarios import make_scenario
from pointplan.scenes.scene import Problem


@pytest.fixture(scope="module")
def problems() -> list[Problem]:
    return make_scenario("boxes3d", robot="sshape").problems("test", 16, seed=2026)


@pytest.fixture(scope="module")
def planner(one_torch_thread: None) -> object:
    return make_planner("policy", SShape(), observation="local")


def _scene_args(planner: object, p: Problem) -> tuple:
    compiled = planner.engine.compiled_rays()  # type: ignore[attr-defined]
    assert isinstance(compiled, CompiledRays)
    return compiled, *compiled._scene_inputs(p.scene)


def _free_configs(p: Problem, n: int, seed: int) -> np.ndarray:
    robot = SShape()
    rng = np.random.default_rng(seed)
    return robot.sample_free(p.scene.world, rng, n, p.scene.low, p.scene.high)


def test_grown_boxes_are_grown_parts() -> None:
    robot = SShape()
    rng = np.random.default_rng(0)
    body = (robot.parts.box_centers, robot.parts.box_halfs, np.ascontiguousarray(robot._corner_velocity))
    out = np.empty((5, 3))
    for _ in range(50):
        seg = rng.normal(size=6) * rng.choice([1e-3, 1e-2, 0.1])
        for reach in (0.0, 0.5, 1.0):
            BK._grow(seg, reach, body[1], body[2], out)
            ref = robot.grown_parts(seg, reach)[1] + CONTACT_MARGIN
            np.testing.assert_allclose(out, ref, rtol=0, atol=1e-15)


@pytest.mark.parametrize("observer_cls", [LocalRays, WideRays])
def test_observation_is_local_rays(problems: list[Problem], observer_cls: type) -> None:
    """The compiled observation of one robot from a block of draws equals
    ``LocalRays.observe`` with a generator that gives the same draws, to the last bit
    (positions in steps, as the network reads them)."""
    robot = SShape()
    observer = observer_cls(robot)
    rays = (np.ascontiguousarray(observer.body_origins), np.ascontiguousarray(observer.body_dirs))
    s0 = np.float32(robot.action_scale[0])
    counts = []
    for k, p in enumerate(problems[:6]):
        observer.bind([p.scene])
        rw = observer.ray_world(p.scene)
        rboxes = (rw.box_c, rw.box_r, rw.box_h, np.any(rw.box_h > 0, -1))
        ows = RK._obs_scratch(len(rays[0]), len(rw.box_c))
        obs = np.empty((observer.n_points, 6), np.float32)
        qs = _free_configs(p, 20, k)
        qs[:3, :3] = p.scene.low + 0.01  # origins of the body poke out of the bounds
        for i, q in enumerate(qs):
            u = np.random.default_rng([k, i]).random(len(rays[0]) + observer.n_points)
            ref = observer.observe(q[None], np.random.default_rng([k, i]))[0]
            ref[:, :3] /= s0
            count = RK._observe(
                q,
                RK.BODY,
                u,
                rays,
                rboxes,
                p.scene.low,
                p.scene.high,
                observer.max_range,
                observer.spacing,
                s0,
                obs,
                ows,
            )
            assert np.array_equal(obs, ref)
            counts.append(count)
    assert min(counts) < observer.n_points < max(counts)  # padded with duplicates and subsets both


def test_moves_and_edges_are_q_free_and_edge_free(planner: object, problems: list[Problem]) -> None:
    robot = SShape()
    rng = np.random.default_rng(3)
    kinds = set()
    for k, p in enumerate(problems[:8]):
        compiled, boxes, rboxes, _, _, low, high = _scene_args(planner, p)
        ws = BK._scratch(5, len(boxes[0]))
        qs = _free_configs(p, 25, 10 + k)
        for i, q in enumerate(qs):
            tw = rng.uniform(-1, 1, 6) * robot.action_scale * rng.choice([0.1, 1.0, 3.0])
            ref_q, ref_hit, ref_n = q_free(robot, p.scene.world, q[None], tw[None], low[None], high[None], 0.01)
            new_q = np.empty(7)
            hit, n = RK._move(q, tw, 0.01, True, low, high, compiled.body, boxes, ws, new_q, robot.action_scale)
            assert (hit, n) == (bool(ref_hit[0]), int(ref_n[0]))
            assert np.array_equal(new_q, ref_q[0])
            b = qs[(i + 1) % len(qs)] if i % 5 else q
            ok, c = edge_free(robot, p.scene.world, q, b, 0.01, low, high)
            assert RK._edge_free(q, b, 0.01, low, high, compiled.body, boxes, ws) == (ok, c)
            kinds.add((hit, np.array_equal(new_q, q), ok))
    assert len(kinds) >= 4  # moves that collide, that are stopped at once, free edges and blocked ones


def test_network_is_the_numpy_actor(planner: object, problems: list[Problem]) -> None:
    fast: NumpyPointNetActor = planner.engine.fast  # type: ignore[attr-defined]
    wflat, layout = pack_weights(fast.inp, fast.hidden, fast.head)
    rng = np.random.default_rng(4)
    compiled, boxes, rboxes, pts, nrm, low, high = _scene_args(planner, problems[0])
    observer = planner.engine.observer  # type: ignore[attr-defined]
    nws = _workspace(observer.n_points, layout, 6)
    ows4 = RK._obs_scratch(len(compiled.rays[0]), len(rboxes[0]))
    ows = (*ows4, np.empty((observer.n_points, 6), np.float32), np.empty(observer.n_points, np.int64))
    fparams = np.zeros(RK.F_BACKOFF + 1)
    fparams[[RK.F_S0, RK.F_RANGE, RK.F_SPACING]] = 0.07, observer.max_range, observer.spacing
    iparams = np.zeros(RK.I_AXES + 1, np.int64)
    iparams[RK.I_ACTION_DIM], iparams[RK.I_ROBOT] = 6, RK.BODY
    robot = SShape()
    for q in _free_configs(problems[0], 10, 5):
        goal = _free_configs(problems[0], 1, int(rng.integers(1000)))[0]
        u = rng.random(len(compiled.rays[0]) + observer.n_points)
        noise = rng.normal(size=6).astype(np.float32)
        for sampled in (False, True):
            a = RK._act(q, goal, u, noise, sampled, compiled.rays, rboxes, pts, nrm, low, high, fparams, iparams,
                        compiled.scale, wflat, layout, ows, nws).copy()  # fmt: skip
            obs_in = ows[4].copy()
            goal_in = (robot.log(q, goal) / robot.action_scale).astype(np.float32)
            ref = fast(obs_in, goal_in, noise if sampled else None)
            np.testing.assert_allclose(a, ref, rtol=0, atol=2e-6)


def test_rollouts_are_the_step_loops(
    planner: object, problems: list[Problem], same_rollout: Callable[[object, object], bool]
) -> None:
    """Whole rollouts (greedy goal test, escapes, goal connection) against the one-robot
    step loop with the numpy network: the networks differ by float32 round-off, so a
    rollout may part where that decides a step; nearly all agree, and every compiled
    success is a path the evaluator accepts."""
    ref = make_planner("policy", SShape(), observation="local", compiled=False)
    same, escapes, solved = 0, 0, 0
    for p in problems:
        a, b = planner.plan(p), ref.plan(p)  # type: ignore[attr-defined]
        assert "compiled" in a.info["time_split"] and "compiled" not in b.info["time_split"]
        if a.success:
            solved += 1
            assert check_path(SShape(), p, a.path)
        if same_rollout(a, b):
            same += 1
            assert a.collision_checks == b.collision_checks
            assert {k: v for k, v in a.info.items() if k != "time_split"} == {
                k: v for k, v in b.info.items() if k != "time_split"
            }
        escapes += a.info["escapes"]
    assert same >= len(problems) - 2
    assert escapes > 0 and solved >= len(problems) // 2


def test_sampled_attempts_are_the_step_loops(
    problems: list[Problem], one_torch_thread: None, same_rollout: Callable[[object, object], bool]
) -> None:
    kw = {"observation": "local", "attempts": 3}
    fast = make_planner("policy", SShape(), **kw)
    ref = make_planner("policy", SShape(), compiled=False, **kw)
    same, retried = 0, 0
    for p in problems[:10]:
        a, b = fast.plan(p), ref.plan(p)
        retried += a.info.get("attempts", 1) > 1
        same += same_rollout(a, b)
    assert retried > 0 and same >= 8


def test_the_sphere_seeing_rays_is_the_step_loop(
    one_torch_thread: None, same_rollout: Callable[[object, object], bool]
) -> None:
    """The sphere's local policy: compiled up to where its first escape (toward a random
    subgoal) starts, then the step loop; against the step loop all the way."""
    from pointplan.robots.point import Sphere3D

    problems = make_scenario("boxes3d", robot="sphere3d").problems("test", 30, seed=2026)
    fast = make_planner("policy", Sphere3D(), observation="local")
    ref = make_planner("policy", Sphere3D(), observation="local", compiled=False)
    same, handed = 0, 0
    for p in problems:
        a, b = fast.plan(p), ref.plan(p)
        assert "compiled" in a.info["time_split"]
        handed += a.info["escapes"] > 0
        same += same_rollout(a, b)
        if a.success:
            assert check_path(Sphere3D(), p, a.path)
    assert same >= len(problems) - 2 and handed > 0


def test_other_obstacles_go_through_the_step_loop(planner: object) -> None:
    """A scene with obstacles other than boxes is not compiled: the step loop plans it."""
    p = make_scenario("synthetic3d", robot="sshape").problems("test", 1, seed=0)[0]
    assert not all(type(o).__name__ == "Box" for o in p.scene.obstacles)
    res = planner.plan(p)  # type: ignore[attr-defined]
    assert "compiled" not in res.info.get("time_split", {})


def test_plan_many_plans_one_by_one(planner: object, problems: list[Problem]) -> None:
    """plan_many plans the ray-cast policy one by one (compiled in scenes of boxes, the
    one-robot step loop elsewhere): the results of plan, in order."""
    other = make_scenario("synthetic3d", robot="sshape").problems("test", 2, seed=0)
    mixed = [problems[0], other[0], problems[1], other[1]]
    many = planner.plan_many(mixed)  # type: ignore[attr-defined]
    for i, p in enumerate(mixed):
        one = planner.plan(p)  # type: ignore[attr-defined]
        assert np.array_equal(many[i].path, one.path)
        assert ("compiled" in many[i].info["time_split"]) == (i % 2 == 0)


def test_compiled_motion_checks_are_the_numpy_ones(problems: list[Problem]) -> None:
    """SShape.check_motions in scenes of boxes (one scene, and stacked scenes one motion
    each) against the numpy check (``Robot.check_motions`` with the same robot): the same
    certified sub-steps, collisions, counts and samples, with and without bounds and the
    start fallback."""
    from pointplan.geometry.collision import CollisionWorld
    from pointplan.robots.base import Robot

    fast = SShape()

    class ref:  # noqa: N801 (the numpy check on the same robot)
        check_motions = staticmethod(lambda *a: Robot.check_motions(fast, *a))

    rng = np.random.default_rng(7)
    kinds = set()
    scenes = [p.scene for p in problems[:6]]
    for scene in scenes:
        assert scene.world.boxes_only
        q0 = np.concatenate([_free_configs(Problem(scene, problems[0].start, problems[0].goal), 30, 1),
                             fast.sample_uniform(rng, 10, scene.low - 0.05, scene.high + 0.05)])  # fmt: skip
        tw = rng.normal(size=(40, 6)) * rng.choice([0.01, 0.07, 0.4], size=(40, 1))
        n = rng.integers(1, 30, 40)
        fb = rng.random(40) < 0.7
        for args in ((), (scene.low, scene.high), (scene.low, scene.high, fb)):
            a = fast.check_motions(scene.world, q0, tw, n, *args)
            b = ref.check_motions(scene.world, q0, tw, n, *args)
            assert np.array_equal(a.free, b.free) and np.array_equal(a.collided, b.collided)
            assert np.array_equal(a.checks, b.checks) and np.array_equal(a.configs, b.configs)
            kinds |= set(zip((a.free == n).tolist(), a.collided.tolist(), (a.free < 0).tolist()))
    stacked = CollisionWorld.stack([s.world for s in scenes])
    q0 = np.stack([fast.sample_uniform(rng, 1, s.low, s.high)[0] for s in scenes])
    tw = rng.normal(size=(len(scenes), 6)) * 0.1
    lows, highs = np.stack([s.low for s in scenes]), np.stack([s.high for s in scenes])
    a = fast.check_motions(stacked, q0, tw, np.full(len(scenes), 10), lows, highs)
    b = ref.check_motions(stacked, q0, tw, np.full(len(scenes), 10), lows, highs)
    assert (
        np.array_equal(a.free, b.free) and np.array_equal(a.checks, b.checks) and np.array_equal(a.configs, b.configs)
    )
    assert len(kinds) >= 3


def test_a_padded_body_grows_from_its_own_corners() -> None:
    """A padded copy made after the body's corner map was built computes its own (the
    copy used to keep the unpadded corners, and grew its boxes too little)."""
    robot = SShape()
    seg = np.full(6, 0.01)
    robot.grown_parts(seg, 0.5)  # builds the corner map
    padded = robot.padded(0.05)
    fresh = SShape()
    fresh.parts = padded.parts
    np.testing.assert_array_equal(padded.grown_parts(seg, 0.5)[1], fresh.grown_parts(seg, 0.5)[1])


class _PlainSShape(SShape):
    """The S-shape with every check in numpy (the same integrate and log)."""

    def check_motions(self, *args: object, **kw: object):  # type: ignore[no-untyped-def]
        from pointplan.robots.base import Robot

        return Robot.check_motions(self, *args, **kw)  # type: ignore[arg-type]

    def march_compiled(self, *args: object) -> None:
        return None

    def shortcut_compiled(self, *args: object) -> None:
        return None

    def nearest(self, nodes: np.ndarray, q: np.ndarray) -> tuple[int, np.ndarray]:
        from pointplan.robots.base import Robot

        return Robot.nearest(self, nodes, q)


def test_compiled_march_and_nearest_are_the_numpy_ones(problems: list[Problem]) -> None:
    """march (Bi-RRT's extend and connect, the edges of every planner), the nearest node
    and the shortcuts, compiled for the S-shape among boxes, against numpy and Python:
    the same nodes, answers and counts; and Bi-RRT plans the same paths either way."""
    from pointplan.planners.base import march
    from pointplan.planners.birrt import BiRRT

    fast, plain = SShape(), _PlainSShape()
    rng = np.random.default_rng(11)
    kinds = set()
    for k, p in enumerate(problems[:5]):
        qs = _free_configs(p, 24, 20 + k)
        for i in range(len(qs) - 1):
            step = float(rng.choice([0.07, 0.3, 1e12]))
            budget = None if i % 3 else int(rng.integers(1, 5))
            a = march(fast, p, qs[i], qs[i + 1], step, 0.01, budget)
            b = march(plain, p, qs[i], qs[i + 1], step, 0.01, budget)
            # (nodes to the last bit or two: numpy's and the compiler's vector code may round
            # a product differently on some CPUs; answers and counts exactly)
            assert a.nodes.shape == b.nodes.shape and np.allclose(a.nodes, b.nodes, rtol=0, atol=1e-13)
            assert (a.reached, a.checks) == (b.reached, b.checks)
            kinds.add((a.reached, len(a.nodes) > 0))
        i, v = fast.nearest(qs, qs[0] * 0.9 + 0.1)
        j, w = plain.nearest(qs, qs[0] * 0.9 + 0.1)
        assert i == j and np.allclose(v, w, rtol=0, atol=1e-15)
    assert len(kinds) >= 3
    shortened = 0
    for p in problems[:3]:
        a = BiRRT(fast, max_nodes=2000, shortcut_probes=0).plan(p)
        b = BiRRT(plain, max_nodes=2000, shortcut_probes=0).plan(p)
        assert a.success == b.success and a.collision_checks == b.collision_checks
        assert a.path.shape == b.path.shape and np.allclose(a.path, b.path, rtol=0, atol=1e-12)
        shortened += a.success and len(a.path) < len(a.raw_path)
    assert shortened > 0


def test_the_sshape_seeing_points_is_the_step_loop(
    problems: list[Problem], one_torch_thread: None, same_rollout: Callable[[object, object], bool]
) -> None:
    """The S-shape's global policy (a subset of the scene's surface points), compiled,
    against the one-robot step loop with the numpy network: escapes included."""
    fast = make_planner("policy", SShape(), observation="global")
    ref = make_planner("policy", SShape(), observation="global", compiled=False)
    assert fast.engine.compiled_rays() is not None  # type: ignore[attr-defined]
    same, escapes = 0, 0
    for p in problems[:12]:
        a, b = fast.plan(p), ref.plan(p)
        assert "compiled" in a.info["time_split"] and "compiled" not in b.info["time_split"]
        escapes += a.info["escapes"]
        same += same_rollout(a, b)
        if a.success:
            assert check_path(SShape(), p, a.path)
    assert same >= 10 and escapes > 0


def test_back_off_is_the_step_loops(
    problems: list[Problem], one_torch_thread: None, same_rollout: Callable[[object, object], bool]
) -> None:
    """The escape's back-off in the kernel against ``rollout._back_off`` on random paths
    (the body and the ball), then whole rollouts: with escape draws of no spread each draw
    is the mean action that just failed to move, so every escape step backs off; the
    compiled plans are the step loop's, differ from those without the back-off, and every
    success is certified."""
    from dataclasses import replace

    from pointplan.planners.rollout import ESCAPE_DEFAULTS, _back_off
    from pointplan.robots.point import Sphere3D

    rng = np.random.default_rng(4)
    for robot, kind in ((SShape(), RK.BODY), (Sphere3D(), RK.BALL)):
        scale = np.asarray(robot.action_scale, np.float64)
        low, high = np.full(3, -1.0), np.full(3, 1.0)
        fired = 0
        for _ in range(30):
            q = robot.sample_uniform(rng, 1, low, high)[0]
            steps = rng.uniform(-1, 1, (6, len(scale))) * scale * rng.choice([0.3, 1.0, 3.0])
            path = [q]
            for tw in steps:
                path.append(robot.integrate(path[-1][None], tw[None])[0])
            path = np.stack(path[::-1])  # the last row is where the robot is
            backoff = float(rng.choice([0.0, 0.03, 0.3, 10.0]))
            ref = _back_off(robot, path[:-1], path[-1], backoff)
            best = np.full(len(scale), 7.0, np.float32)
            RK._back_off(kind, path, len(path) - 1, backoff, scale, np.empty(6), best)
            if ref is None:
                assert np.all(best == 7.0)
            else:
                fired += 1
                np.testing.assert_allclose(best, ref, atol=1e-6)
        assert 0 < fired < 30

    esc = replace(ESCAPE_DEFAULTS["sshape"], noise=0.0, tries=2, lookahead=0)
    plans = {}
    for backoff in (0.0, 0.03):
        for compiled in (True, False):
            pl = make_planner(
                "policy", SShape(), observation="local", compiled=compiled, escape=replace(esc, backoff=backoff)
            )
            plans[backoff, compiled] = [pl.plan(p) for p in problems[:12]]  # type: ignore[attr-defined]
    same = sum(same_rollout(a, b) for a, b in zip(plans[0.03, True], plans[0.03, False]))
    assert same >= 11
    assert any(not same_rollout(a, b) for a, b in zip(plans[0.0, True], plans[0.03, True]))
    for p, a in zip(problems[:12], plans[0.03, True]):
        assert "compiled" in a.info["time_split"]
        if a.success:
            assert check_path(SShape(), p, a.path)


def test_the_sshape_told_its_orientation_is_the_step_loop(
    one_torch_thread: None, same_rollout: Callable[[object, object], bool]
) -> None:
    """The S-shape told its orientation (the world's axes in the body frame beside the goal
    twist, ``I_AXES``) takes the compiled rollout: its goal input and action are the numpy
    actor's, and its Slot plans (the back-off, 64 draws and the lookahead of its default
    escape, sub-steps of 0.005) are the step loop's, every success certified."""
    from pointplan.models.inputs import goal_input
    from pointplan.robots.sshape import OrientedSShape

    sc = make_scenario("slot", robot="sshape-oriented")
    robot = sc.robot
    assert isinstance(robot, OrientedSShape)
    fast_planner = make_planner("policy", robot, scene="slot")
    ref = make_planner("policy", robot, scene="slot", compiled=False)
    eng = fast_planner.engine  # type: ignore[attr-defined]
    compiled = eng.compiled_rays()
    assert isinstance(compiled, CompiledRays) and compiled.axes
    problems = sc.problems("val", 10, seed=5)
    boxes, rboxes, pts, nrm, low, high = compiled._scene_inputs(problems[0].scene)
    fast = eng.fast
    wflat, layout = pack_weights(fast.inp, fast.hidden, fast.head)
    nws = _workspace(eng.observer.n_points, layout, 15)
    ows4 = RK._obs_scratch(len(compiled.rays[0]), len(rboxes[0]))
    ows = (*ows4, np.empty((eng.observer.n_points, 6), np.float32), np.empty(eng.observer.n_points, np.int64))
    fparams, iparams = compiled._params(False)
    rng = np.random.default_rng(1)
    for p in problems[:4]:
        q, goal = np.asarray(p.start, np.float64), np.asarray(p.goal, np.float64)
        u = rng.random(len(compiled.rays[0]) + eng.observer.n_points)
        a = RK._act(q, goal, u, np.zeros(6, np.float32), False, compiled.rays, rboxes, pts, nrm, low, high, fparams,
                    iparams, compiled.scale, wflat, layout, ows, nws).copy()  # fmt: skip
        np.testing.assert_allclose(a, fast(ows[4].copy(), goal_input(robot, q, goal), None), rtol=0, atol=2e-6)
    same = solved = 0
    for p in problems:
        a, b = fast_planner.plan(p), ref.plan(p)  # type: ignore[attr-defined]
        assert "compiled" in a.info["time_split"] and "compiled" not in b.info["time_split"]
        same += same_rollout(a, b)
        if a.success:
            solved += 1
            assert check_path(robot, p, a.path)
    assert same >= len(problems) - 1 and solved >= len(problems) // 2
