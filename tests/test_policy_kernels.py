"""The compiled kernels of the batch-1 policy planner against the code they replace."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from pointplan.models.policy import NumpyPointNetActor, Policy, shipped_checkpoint
from pointplan.planners import _policy_kernels as K
from pointplan.planners import make_planner
from pointplan.planners.edges import edge_free
from pointplan.robots.motion import intervals
from pointplan.scenes.scenarios import Narrow2DScenario
from pointplan.scenes.scene import Problem


@pytest.fixture(scope="module")
def problems(narrow2d_test_problems: Callable[[int], list[Problem]]) -> list[Problem]:
    return narrow2d_test_problems(20)


def _boxes(problem: Problem) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    w = problem.scene.world
    return np.ascontiguousarray(w.box_c), np.ascontiguousarray(w.box_r), np.ascontiguousarray(w.box_h)


def test_motion_check_is_check_motions(problems: list[Problem]) -> None:
    robot = Narrow2DScenario().robot
    rng = np.random.default_rng(0)
    kinds = set()
    for p in problems:
        low, high = p.scene.low, p.scene.high
        q0 = rng.uniform(low - 0.02, high + 0.02, size=(60, 2))
        tw = rng.normal(size=(60, 2)) * rng.choice([0.005, 0.05, 0.3], size=(60, 1))
        n = intervals(np.linalg.norm(tw, axis=-1), 0.01)
        ref = robot.check_motions(p.scene.world, q0, tw, n, low, high)
        for i in range(60):
            free, hit, checks, end = K.ball_motion(q0[i], tw[i], int(n[i]), robot.radius, low, high, *_boxes(p))
            assert (free, hit, checks) == (int(ref.free[i]), bool(ref.collided[i]), int(ref.checks[i]))
            if free > 0:
                assert np.array_equal(end, ref.configs[i, free])
            kinds.add((free == n[i], hit, free < 0))
    assert len(kinds) >= 3  # free, stopped by a box, stopped by the bounds or at the start


def test_edge_check_is_edge_free_and_the_quick_test_is_necessary(problems: list[Problem]) -> None:
    robot = Narrow2DScenario().robot
    rng = np.random.default_rng(1)
    seen = {True: 0, False: 0}
    for p in problems:
        boxes = _boxes(p)
        for _ in range(40):
            a = rng.uniform(p.scene.low, p.scene.high)
            b = a if rng.random() < 0.05 else rng.uniform(p.scene.low, p.scene.high)
            ok, n = edge_free(robot, p.scene, a, b, 0.01)
            assert K.ball_edge_free(a, b, robot.radius, 0.01, p.scene.low, p.scene.high, *boxes) == (ok, n)
            hit, _ = K.ball_segment_hits_boxes_count(a, b, robot.radius * (1 - 1e-9), 0.01, *boxes)
            if hit:
                assert not ok
            seen[ok] += 1
    assert seen[True] > 20 and seen[False] > 20


@pytest.mark.parametrize("env", ["synthetic3d", "narrow2d+discs+capsules"])
def test_the_quick_goal_test_is_necessary_among_primitives(env: str) -> None:
    """Among spheres, capsules, cylinders and cones (3D-Synthetic; discs and capsules in
    the plane) too, a segment the quick test rules out is one the certified edge check
    finds blocked."""
    from pointplan.scenes.scenarios import make_scenario

    sc = make_scenario(env.split("+")[0])
    rng = np.random.default_rng(2)
    problems = sc.problems("test", 8, seed=0)
    if "+" in env:
        problems = [_with_discs_and_capsules(p, rng) for p in problems]
    robot, seen = sc.robot, {True: 0, False: 0}
    for p in problems:
        world = p.scene.world
        assert not world.boxes_only and world.primitives_only
        for _ in range(60):
            a, b = rng.uniform(p.scene.low, p.scene.high, size=(2, robot.dim))
            ok, _ = edge_free(robot, p.scene, a, b, 0.01)
            hit, _ = K.ball_segment_hits_boxes_count(
                a, b, robot.radius * (1 - 1e-9), 0.01, *_boxes(p), world.ball_prims()
            )
            assert not (hit and ok)
            seen[bool(hit)] += 1
    assert seen[True] > 50 and seen[False] > 50


def test_compiled_action_matches_the_numpy_actor(problems: list[Problem]) -> None:
    robot = Narrow2DScenario().robot
    planner = make_planner("policy", robot)
    planner.plan(problems[0])  # binds the observer
    policy = Policy.from_checkpoint(shipped_checkpoint("disc2d"))
    fast = NumpyPointNetActor.from_actor(policy.actor)
    assert fast is not None
    compiled = planner.engine.compiled()
    assert compiled is not None
    wflat, layout, scale = compiled.args[:3]
    obs_ = planner.engine.observer
    rng = np.random.default_rng(2)
    worst = 0.0
    for p in problems[:10]:
        obs_.set_scene(0, p.scene)
        pts, nrm = obs_.points_one()
        for _ in range(5):
            q = rng.uniform(p.scene.low, p.scene.high)
            u = rng.random(obs_.draws_one())
            ref = planner.engine._act(obs_.observe_one(q, u=u), q, p.goal, None)  # numpy actor on the built observation
            got = K.pointnet_action(
                q, p.goal, u, obs_.n_points, pts, nrm, float(np.float32(0.07)), wflat, layout, scale, 2
            )
            worst = max(worst, float(np.abs(got - ref).max()))
    assert worst < 1e-5


def test_compiled_rollout_is_the_python_one(problems: list[Problem]) -> None:
    robot = Narrow2DScenario().robot
    for greedy in (True, False):
        a = make_planner("policy", robot, greedy_goal=greedy)
        b = make_planner("policy", robot, greedy_goal=greedy, compiled=False)
        same = 0
        for p in problems:
            ra, rb = a.plan(p), b.plan(p)
            assert "compiled" in ra.info["time_split"] and "compiled" not in rb.info["time_split"]
            assert ra.success == rb.success
            if (
                ra.nodes == rb.nodes
                and ra.path.shape == rb.path.shape
                and np.allclose(ra.path, rb.path, atol=1e-5, rtol=0)
                and ra.info["end"] == rb.info["end"]
            ):
                same += 1
        assert same >= len(problems) - 1  # float32 round-off may part a rare failing rollout


def test_the_sphere_among_primitives_rolls_out_compiled_as_the_step_loop() -> None:
    """In 3D-Synthetic (spheres, capsules, cylinders and cones) the sphere's compiled
    rollout applies (goal tests, moves and edges among the primitives) and gives the step
    loop's results: the same ends, nodes, checks and paths; with its escape and without."""
    from pointplan.scenes.scenarios import make_scenario

    sc = make_scenario("synthetic3d", robot="sphere3d")
    problems = sc.problems("test", 12, seed=1)
    assert any(not p.scene.world.boxes_only for p in problems)
    for kw in ({"escape": 0}, {}):
        a = make_planner("policy", sc.robot, observation="global", **kw)
        b = make_planner("policy", sc.robot, observation="global", compiled=False, **kw)
        same = 0
        for p in problems:
            ra, rb = a.plan(p), b.plan(p)
            assert "compiled" in ra.info["time_split"] and "compiled" not in rb.info["time_split"]
            assert ra.success == rb.success
            same += (ra.nodes, ra.collision_checks, ra.info["end"], ra.path.shape) == (
                rb.nodes,
                rb.collision_checks,
                rb.info["end"],
                rb.path.shape,
            ) and np.allclose(ra.path, rb.path, atol=1e-5, rtol=0)
        assert same >= len(problems) - 1  # float32 round-off may part a rare rollout, as among boxes


def test_compiled_plan_keeps_no_state_between_problems(problems: list[Problem]) -> None:
    """The compiled path keeps the last scene's arguments: planning a problem again, after
    other scenes or in the same scene, gives the same result; so does a start given as
    float32 (converted as before)."""
    robot = Narrow2DScenario().robot
    planner = make_planner("policy", robot)
    first = [planner.plan(p) for p in problems[:6]]
    again = [planner.plan(p) for p in reversed(problems[:6])][::-1]
    for prob, a, b in zip(problems[:6], first, again, strict=True):
        assert "compiled" in a.info["time_split"]
        assert np.array_equal(a.path, b.path) and (a.success, a.nodes, a.collision_checks) == (
            b.success,
            b.nodes,
            b.collision_checks,
        )
        assert {k: v for k, v in a.info.items() if k != "time_split"} == {
            k: v for k, v in b.info.items() if k != "time_split"
        }
        if a.info["end"] == "goal":
            assert np.array_equal(a.path[-1], prob.goal)
    p = problems[0]
    c = planner.plan(Problem(p.scene, p.start.astype(np.float32).astype(np.float64), p.goal))
    d = planner.plan(Problem(p.scene, p.start.astype(np.float32), p.goal))
    assert np.array_equal(c.path, d.path)


def test_compiled_rollout_hands_an_escape_over_to_the_numpy_one() -> None:
    """With an escape (the sphere's default), the compiled rollout runs up to the step
    that starts the first escape and the numpy rollout goes on from there: the same
    paths, successes, step counts and escapes as the numpy rollout from the start."""
    from pointplan.planners.policy import PolicyPlanner
    from pointplan.planners.rollout_compiled import END_NAMES
    from pointplan.scenes.scenarios import make_scenario

    assert (
        END_NAMES[K.END_ESCAPE] == "escape"
        and END_NAMES[K.END_GREEDY] == "goal"
        and END_NAMES[K.END_STALLED] == "stalled"
    )
    sc = make_scenario("boxes3d", robot="sphere3d")
    ckpt = shipped_checkpoint("sphere3d", "global")
    a = PolicyPlanner(ckpt, robot=sc.robot)
    b = PolicyPlanner(ckpt, robot=sc.robot, compiled=False)
    assert a.escape.steps > 0 and a.escape.subgoal
    handed = same = 0
    probs = sc.problems("val", 150, seed=0)
    for p in probs:
        ra, rb = a.plan(p), b.plan(p)
        assert "compiled" in ra.info["time_split"] and "compiled" not in rb.info["time_split"]
        handed += ra.info["escapes"] > 0
        if (
            (ra.success, ra.nodes, ra.info["end"], ra.info["escapes"])
            == (rb.success, rb.nodes, rb.info["end"], rb.info["escapes"])
            and ra.path.shape == rb.path.shape
            and np.allclose(ra.path, rb.path, atol=1e-5, rtol=0)
        ):
            same += 1
    assert handed >= 3, handed  # some rollouts escaped, so the hand-over was exercised
    assert same >= len(probs) - 1, same  # float32 round-off may part a rare rollout


def _with_discs_and_capsules(problem: Problem, rng: np.random.Generator) -> Problem:
    """``problem`` (2D) with three discs and three capsules added, none over its ends."""
    from pointplan.geometry.collision import CollisionWorld
    from pointplan.geometry.shapes import Capsule, Shape, Sphere
    from pointplan.scenes.scene import Scene

    scene, extra = problem.scene, list[Shape]()
    ends = np.stack([problem.start, problem.goal])
    while len(extra) < 6:
        a = rng.uniform(scene.low, scene.high)
        r = float(rng.uniform(0.01, 0.05))
        shape = Sphere(a, r) if len(extra) % 2 else Capsule(a, a + rng.normal(size=2) * 0.1, r)
        if not CollisionWorld.from_shapes([shape], 2).spheres_collide(ends, 0.03).any():
            extra.append(shape)
    return Problem(Scene([*scene.obstacles, *extra], scene.low, scene.high), problem.start, problem.goal)


@pytest.mark.parametrize("env", ["narrow2d", "boxes3d", "synthetic3d", "narrow2d+discs+capsules"])
def test_ball_motion_checks_and_march_are_the_numpy_ones(env: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """The balls' compiled check_motions (one scene; stacked scenes, one motion each),
    march and shortcuts against the numpy and Python ones on the same robot: the same
    answers, counts, samples and nodes; Bi-RRT plans the same paths either way. Among
    boxes, and among the other primitives (3D-Synthetic's spheres, capsules, cylinders and
    cones; discs and capsules in the plane)."""
    from pointplan.geometry.collision import CollisionWorld
    from pointplan.planners.base import march
    from pointplan.planners.birrt import BiRRT
    from pointplan.robots.base import Robot
    from pointplan.scenes.scenarios import make_scenario

    sc = make_scenario(env.split("+")[0])
    robot = sc.robot

    class Plain(type(robot)):  # type: ignore[misc]
        def check_motions(self, *a: object, **k: object):  # type: ignore[no-untyped-def]
            return Robot.check_motions(self, *a, **k)  # type: ignore[arg-type]

        def march_compiled(self, *a: object) -> None:
            return None

        def shortcut_compiled(self, *a: object) -> None:
            return None

    from pointplan.robots import _ball_kernels, point

    ran: dict[str, int] = {}

    def spy(name: str, fn: Callable[..., object]) -> Callable[..., object]:
        def counted(*a: object) -> object:
            ran[name] = ran.get(name, 0) + 1
            return fn(*a)

        return counted

    for name in ("check_motions_balls", "march_balls"):
        monkeypatch.setattr(_ball_kernels, name, spy(name, getattr(_ball_kernels, name)))
    monkeypatch.setattr(point, "shortcut_path", spy("shortcut_path", point.shortcut_path))
    plain = Plain()
    problems = sc.problems("test", 6, seed=3)
    rng = np.random.default_rng(5)
    if "+" in env:
        problems = [_with_discs_and_capsules(p, rng) for p in problems]
    d = robot.dim
    kinds = set()
    for p in problems:
        world, low, high = p.scene.world, p.scene.low, p.scene.high
        # the compiled checks apply (boxes alone, or with the other primitives)
        assert world.primitives_only and world.boxes_only == (env in ("narrow2d", "boxes3d"))
        assert len(world.ball_prims()) == (0 if world.boxes_only else 13)
        q0 = rng.uniform(low - 0.02, high + 0.02, size=(50, d))
        tw = rng.normal(size=(50, d)) * rng.choice([0.005, 0.05, 0.3], size=(50, 1))
        n = intervals(np.linalg.norm(tw, axis=-1), 0.01)
        fb = rng.random(50) < 0.7
        for args in ((), (low, high), (low, high, fb)):
            a, b = robot.check_motions(world, q0, tw, n, *args), plain.check_motions(world, q0, tw, n, *args)
            assert np.array_equal(a.free, b.free) and np.array_equal(a.collided, b.collided)
            assert np.array_equal(a.checks, b.checks) and np.array_equal(a.configs, b.configs)
            kinds |= set(zip((a.free == n).tolist(), a.collided.tolist()))
        for i in range(20):
            step = float(rng.choice([0.07, 0.3, 1e12]))
            budget = None if i % 3 else int(rng.integers(1, 4))
            ma, mb = (
                march(robot, p, q0[i], q0[i + 1], step, 0.01, budget),
                march(plain, p, q0[i], q0[i + 1], step, 0.01, budget),
            )
            # (nodes to the last bit or two: numpy's and the compiler's vector code may round
            # a product differently on some CPUs; answers and counts exactly)
            assert ma.nodes.shape == mb.nodes.shape and np.allclose(ma.nodes, mb.nodes, rtol=0, atol=1e-13)
            assert (ma.reached, ma.checks) == (mb.reached, mb.checks)
    assert len(kinds) >= 3
    stacked = CollisionWorld.stack([p.scene.world for p in problems])
    q0 = np.stack([rng.uniform(p.scene.low, p.scene.high) for p in problems])
    tw = rng.normal(size=q0.shape) * 0.1
    lows, highs = np.stack([p.scene.low for p in problems]), np.stack([p.scene.high for p in problems])
    a = robot.check_motions(stacked, q0, tw, np.full(len(problems), 10), lows, highs)
    b = plain.check_motions(stacked, q0, tw, np.full(len(problems), 10), lows, highs)
    assert (
        np.array_equal(a.free, b.free) and np.array_equal(a.checks, b.checks) and np.array_equal(a.configs, b.configs)
    )
    shortened = 0
    for p in problems[:3]:
        ra = BiRRT(robot, max_nodes=2000, shortcut_probes=0).plan(p)
        rb = BiRRT(plain, max_nodes=2000, shortcut_probes=0).plan(p)
        assert ra.success == rb.success and ra.collision_checks == rb.collision_checks
        assert ra.path.shape == rb.path.shape and np.allclose(ra.path, rb.path, rtol=0, atol=1e-12)
        shortened += ra.success and len(ra.path) < len(ra.raw_path)
    assert shortened > 0
    # the compiled checks, march and shortcuts ran (the robot's; the plain one has none)
    assert set(ran) == {"check_motions_balls", "march_balls", "shortcut_path"}, ran


@pytest.mark.parametrize("dim", [2, 3])
def test_ball_against_primitives_decides_ties_as_numpy(dim: int) -> None:
    """The compiled ball-against-primitive test (``_hits_prims``) and
    ``CollisionWorld.spheres_collide`` give the same verdict on balls that just touch a
    sphere, capsule, cylinder or cone (radii found by bisection on numpy's test, so that the
    last bit of the distance decides): both compute in the same order."""
    from pointplan.geometry import lie
    from pointplan.geometry.collision import CollisionWorld
    from pointplan.geometry.shapes import Capsule, Cone, Cylinder, Shape, Sphere
    from pointplan.robots._ball_kernels import _hits_prims

    rng = np.random.default_rng(11)
    kinds = ["sphere", "capsule"] + (["cylinder", "cone"] if dim == 3 else [])
    hits = 0
    for kind in kinds:
        for _ in range(400):
            c, rot = rng.normal(size=dim), lie.random_rotations(rng, 1)[0]
            size, length = float(rng.uniform(0.0, 0.3)), float(rng.uniform(0.05, 0.6))
            shape: Shape
            if kind == "sphere":
                shape = Sphere(c, size)
            elif kind == "capsule":
                shape = Capsule(c, c + rng.normal(size=dim) * 0.3, size)
            else:
                shape = (Cylinder if kind == "cylinder" else Cone)(c, size + 0.01, length, rot)
            world = CollisionWorld.from_shapes([shape], dim)
            p = c + rng.normal(size=dim) * 0.5
            # the radius at which the ball starts to touch, to the last bit, by numpy's test
            lo, hi = 0.0, 3.0
            for _ in range(64):
                mid = (lo + hi) / 2
                lo, hi = (lo, mid) if world.spheres_collide(p[None], mid)[0] else (mid, hi)
            for r in (lo, hi, np.nextafter(lo, 0.0), np.nextafter(hi, 4.0)):
                want = bool(world.spheres_collide(p[None], r)[0])
                assert bool(_hits_prims(p, float(r), float(r) * float(r), world.ball_prims(), False)) == want, (kind, r)
                hits += want
    assert hits > 0
