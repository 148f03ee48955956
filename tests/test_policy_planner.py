"""The policy as a batch-1 planner: the lean rollout, the numpy network, the goal connection."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
import torch

from pointplan.evaluation import check_path, evaluate
from pointplan.models.inputs import goal_dim, goal_input, obs_input
from pointplan.models.policy import NumpyPointNetActor, Policy, shipped_checkpoint
from pointplan.observers import make_observer
from pointplan.planners import make_planner
from pointplan.planners.edges import edge_free
from pointplan.planners.policy import connect_to_goal, rollout_batch
from pointplan.scenes.scenarios import Narrow2DScenario
from pointplan.scenes.scene import Problem


@pytest.fixture(scope="module")
def problems(narrow2d_test_problems: Callable[[int], list[Problem]]) -> list[Problem]:
    return narrow2d_test_problems(30)


@pytest.fixture(scope="module")
def planner():  # type: ignore[no-untyped-def]
    return make_planner("policy", Narrow2DScenario().robot)


def test_numpy_actor_matches_torch() -> None:
    policy = Policy.from_checkpoint(shipped_checkpoint("disc2d"))
    fast = NumpyPointNetActor.from_actor(policy.actor)
    assert fast is not None
    rng = np.random.default_rng(0)
    obs = rng.normal(size=(5, 64, 4)).astype(np.float32)
    goal = rng.normal(size=(5, 2)).astype(np.float32)
    with torch.no_grad():
        ref = policy.actor.act(torch.as_tensor(obs), torch.as_tensor(goal)).numpy()
    np.testing.assert_allclose(fast(obs, goal), ref, atol=2e-6)
    np.testing.assert_allclose(fast(obs[0], goal[0]), ref[0], atol=2e-6)


def test_observe_one_is_observe_of_one(problems: list[Problem]) -> None:
    robot = Narrow2DScenario().robot
    for n_points in (64, 1000):  # fewer points than asked: padded by duplicates
        a = make_observer("surface-normals", robot, n_points=n_points)
        b = make_observer("surface-normals", robot, n_points=n_points)
        a.bind([problems[0].scene])
        b.bind([problems[0].scene])
        ra, rb = np.random.default_rng(3), np.random.default_rng(3)
        q = problems[0].start
        for _ in range(3):
            assert np.array_equal(a.observe(q[None], ra)[0], b.observe_one(q, rb))
        rb.random(b.draws_one())
        ra.random(b.draws_one())  # keep the streams level
        assert np.array_equal(
            a.observe(q[None], np.random.default_rng(9))[0],
            b.observe_one(q, u=np.random.default_rng(9).random(b.draws_one())),
        )


def test_plan_is_the_batched_rollout(problems: list[Problem]) -> None:
    planner = make_planner("policy", Narrow2DScenario().robot, greedy_goal=False)
    robot = planner.robot
    same = 0
    for p in problems:
        a = planner.plan(p)
        b = rollout_batch(planner.policy, robot, planner.env, [p], planner.horizon)[0]
        assert a.success == b.success
        k = len(b.path)
        if a.nodes == b.nodes and np.allclose(a.path[:k], b.path, atol=1e-5, rtol=0):
            same += 1
        # the policy's own steps are counted as nodes, the goal is not
        assert a.nodes == len(a.path) - 1 - (a.info["end"] == "goal")
        assert a.collision_checks >= b.collision_checks
        assert {"observe", "network", "motion", "steps"} <= set(a.info["time_split"])
    assert same >= len(problems) - 1  # float32 round-off may part a rare failing rollout


def test_greedy_goal_stops_the_same_rollout_early(problems: list[Problem], planner) -> None:  # type: ignore[no-untyped-def]
    """With the greedy goal test (the default) the policy's steps are the first steps of
    the rollout without it; a path that stops early ends with a certified edge to the goal."""
    robot = planner.robot
    plain = make_planner("policy", robot, greedy_goal=False)
    shorter = 0
    for p in problems:
        g, r = planner.plan(p), plain.plan(p)
        k = g.nodes + 1
        assert g.nodes <= r.nodes or not r.success
        np.testing.assert_allclose(g.path[:k], r.path[:k], atol=1e-5, rtol=0)
        if g.info.get("greedy_goal"):
            assert np.array_equal(g.path[-1], p.goal) and check_path(robot, p, g.path, tolerance=1e-9)
        shorter += g.nodes < r.nodes
    assert shorter >= len(problems) // 3


def test_paths_end_at_the_goal_when_free(problems: list[Problem], planner) -> None:  # type: ignore[no-untyped-def]
    robot = planner.robot
    ends = []
    for p in problems:
        r = planner.plan(p)
        ends.append(r.info["end"])
        if r.info["end"] == "goal":
            assert np.array_equal(r.path[-1], p.goal)
            assert check_path(robot, p, r.path, tolerance=1e-9)
        elif r.info["end"] == "near-goal":
            assert r.info["goal_connection"] == "blocked"
            assert check_path(robot, p, r.path)
        else:
            assert not r.success
    assert ends.count("goal") >= len(problems) - 3


def test_connection_blocked_keeps_the_path() -> None:
    from pointplan.geometry.shapes import Box
    from pointplan.planners.base import PlanResult
    from pointplan.scenes.scene import Scene

    robot = Narrow2DScenario().robot
    scene = Scene([Box(center=np.array([0.5, 0.5]), size=np.array([0.02, 0.5]))], np.zeros(2), np.ones(2))
    p = Problem(scene, np.array([0.45, 0.5]), np.array([0.52 + 0.02, 0.5]))
    res = PlanResult(path=p.start[None].copy(), success=True, nodes=0, collision_checks=0, time_s=0.0)
    res = connect_to_goal(robot, p, res)
    assert res.info["end"] == "near-goal" and len(res.path) == 1 and res.collision_checks > 0


def test_evaluator_counts_length_to_the_goal(problems: list[Problem]) -> None:
    from pointplan.planners.base import PlanResult

    robot = Narrow2DScenario().robot
    p = problems[0]

    class Stopper:
        name = "stopper"

        def plan(self, problem: Problem) -> PlanResult:
            # stops 0.05 short of the goal along the straight line, if that is free
            d = problem.goal - problem.start
            end = problem.goal - 0.05 * d / np.linalg.norm(d)
            return PlanResult(np.stack([problem.start, end]), True, 1, 0, 0.0)

    rec = evaluate(Stopper(), [p], robot, progress=False).records[0]
    if rec.success:
        assert rec.path_length == pytest.approx(float(robot.distance(p.start, p.goal)))


def test_single_thread_and_batch_agree(problems: list[Problem], planner) -> None:  # type: ignore[no-untyped-def]
    many = planner.plan_many(problems[:8])
    for p, m in zip(problems[:8], many):
        # the batch draws other point subsets: the same kind of outcome, not the same path
        for r in (planner.plan(p), m):
            assert r.info["end"] in ("goal", "near-goal", "horizon")
            assert (r.info["end"] == "goal") == (r.success and np.array_equal(r.path[-1], p.goal))


def test_goal_and_obs_inputs_unchanged() -> None:
    robot = Narrow2DScenario().robot
    q, g = np.array([0.1, 0.2]), np.array([0.3, 0.5])
    assert np.array_equal(goal_input(robot, q[None], g[None])[0], ((g - q) / robot.action_scale).astype(np.float32))
    obs = np.ones((1, 3, 4), np.float32)
    assert np.allclose(obs_input(robot, obs)[0, :, :2], 1 / 0.07)


@pytest.mark.parametrize("robot_name", ["sphere3d", "sshape", "sshape-oriented"])
def test_one_robot_rollout_in_3d_matches_the_batched_one(robot_name: str) -> None:
    from pointplan.models.actor_critic import Actor, NetConfig
    from pointplan.models.encoders import EncoderConfig
    from pointplan.planners.policy import PolicyPlanner
    from pointplan.scenes.scenarios import make_scenario

    scenario = make_scenario("boxes3d", robot=robot_name)
    robot = scenario.robot
    torch.manual_seed(0)
    actor = Actor(
        (64, 6),
        goal_dim(robot),
        robot.twist_dim,
        NetConfig(EncoderConfig("pointnet", 32, 2), head_width=32, head_layers=2),
    )
    policy = Policy(actor, robot, {"observation": "global", "n_points": 64, "horizon": 12})
    planner = PolicyPlanner(policy, greedy_goal=False, escape=0)  # the rollout itself, to its end
    assert planner.fast is not None
    for i in range(2):
        p = scenario.problem("test", i, seed=0)
        a = planner.plan(p)
        b = rollout_batch(policy, robot, planner.env, [p], planner.horizon)[0]
        assert a.nodes == b.nodes and a.success == b.success
        np.testing.assert_allclose(a.path[: len(b.path)], b.path, atol=1e-5)


def test_numpy_actor_samples_like_torch() -> None:
    """The numpy network's sampled action is the PyTorch actor's tanh(mean + std * noise)."""
    policy = Policy.from_checkpoint(shipped_checkpoint("disc2d"))
    fast = NumpyPointNetActor.from_actor(policy.actor)
    assert fast is not None
    rng = np.random.default_rng(1)
    obs = rng.normal(size=(4, 64, 4)).astype(np.float32)
    goal = rng.normal(size=(4, 2)).astype(np.float32)
    noise = rng.normal(size=(4, 2)).astype(np.float32)
    with torch.no_grad():
        mean, log_std = policy.actor(torch.as_tensor(obs), torch.as_tensor(goal))
        ref = torch.tanh(mean + log_std.exp() * torch.as_tensor(noise)).numpy()
    np.testing.assert_allclose(fast(obs, goal, noise), ref, atol=2e-6)
    np.testing.assert_allclose(policy(obs, np.zeros((4, 2)), np.zeros((4, 2)), noise=noise).shape, (4, 2))
    assert not np.allclose(fast(obs, goal, noise), fast(obs, goal), atol=1e-3)  # the noise is applied
    np.testing.assert_allclose(fast(obs, goal, np.zeros((4, 2), np.float32)), fast(obs, goal), atol=1e-7)


def _weak_sphere_policy(horizon: int = 15):  # type: ignore[no-untyped-def]
    """An untrained PointNet policy for the sphere with a short horizon: its mean action
    fails most problems, so retries have work to do."""
    from pointplan.models.actor_critic import Actor, NetConfig
    from pointplan.models.encoders import EncoderConfig
    from pointplan.scenes.scenarios import make_scenario

    scenario = make_scenario("boxes3d", robot="sphere3d")
    robot = scenario.robot
    torch.manual_seed(1)
    actor = Actor(
        (64, 6),
        goal_dim(robot),
        robot.twist_dim,
        NetConfig(EncoderConfig("pointnet", 32, 2), head_width=32, head_layers=2),
    )
    with torch.no_grad():  # a wide spread, so that sampled attempts go places
        actor.head[-1].bias[robot.twist_dim :] = 0.0
    policy = Policy(actor, robot, {"observation": "global", "n_points": 64, "horizon": horizon})
    return scenario, policy


def test_attempts_retry_failures_with_sampled_actions() -> None:
    from pointplan.planners.policy import PolicyPlanner

    scenario, policy = _weak_sphere_policy()
    robot = scenario.robot
    problems = scenario.problems("val", 12, seed=0)
    plain = PolicyPlanner(policy)
    retry = PolicyPlanner(policy, attempts=4)
    for p in problems:
        a, b = plain.plan(p), retry.plan(p)
        if a.success:  # a success of the mean action is returned as it is
            assert b.success and b.nodes == a.nodes and np.array_equal(a.path, b.path)
            assert "attempts" not in b.info
            continue
        runs = b.info["attempts"]
        steps = b.info["attempt_steps"]
        assert 2 <= runs <= 4 and len(steps) == runs
        assert steps[0] == a.nodes  # the first attempt is the mean-action rollout
        assert b.nodes == sum(steps) and b.collision_checks >= a.collision_checks
        assert runs == 4 or b.success  # it stops at the first success only
        # the returned path is an attempt's own path, checked independently by the evaluator
        assert bool(check_path(robot, p, b.path)) == b.success
        assert b.path.shape[0] >= 2 and np.array_equal(b.path[0], p.start)
    # seeded by (seed, attempt, problem): any order gives the same attempts
    fwd = [retry.plan(p) for p in problems[:4]]
    back = [retry.plan(p) for p in reversed(problems[:4])][::-1]
    for x, y in zip(fwd, back):
        assert x.nodes == y.nodes and np.array_equal(x.path, y.path)
    # another seed draws other actions
    other = PolicyPlanner(policy, attempts=4, seed=5)
    failing = [p for p in problems if not plain.plan(p).success]
    assert failing
    assert any(not np.array_equal(retry.plan(p).path, other.plan(p).path) for p in failing)


def test_attempts_raise_success_and_are_counted_by_the_evaluator() -> None:
    from pointplan.planners.policy import PolicyPlanner

    scenario, policy = _weak_sphere_policy(horizon=25)
    problems = scenario.problems("val", 30, seed=1)
    one = evaluate(PolicyPlanner(policy), problems, scenario.robot, progress=False).metrics()
    six = evaluate(PolicyPlanner(policy, attempts=6), problems, scenario.robot, progress=False).metrics()
    assert six["success_rate"] >= one["success_rate"]
    assert six["success_rate"] > one["success_rate"] or one["success_rate"] == 1.0
    assert six["nodes_mean"] > one["nodes_mean"]  # failed attempts' steps are counted
    assert six["planner_claims_disagree"] == 0


def test_attempts_bad_input() -> None:
    from pointplan.planners.policy import PolicyPlanner
    from pointplan.scenes.scenarios import make_scenario

    _, policy = _weak_sphere_policy()
    with pytest.raises(ValueError, match="attempts"):
        PolicyPlanner(policy, attempts=0)
    with pytest.raises(ValueError, match="action_noise"):
        PolicyPlanner(policy, action_noise=-1.0)
    dyn = make_scenario("dynamic3d", robot="sphere3d").problem("val", 0, seed=0)
    with pytest.raises(ValueError, match="static scenes"):
        PolicyPlanner(policy, attempts=2).plan(dyn)


def test_greedy_goal_applies_to_the_ray_cast_observer_too() -> None:
    """The ray-cast observer plans through the batched core; the greedy goal test applies
    there as well (it once did not: ``local`` policies then rolled out to the tolerance
    while ``global`` ones stopped at the first free edge). Its steps are the first steps of
    the rollout without it, every greedy path ends with a certified edge to the goal, and
    in a moving scene the test is off (an edge free now may be blocked later)."""
    from pointplan.scenes.scenarios import make_scenario

    sc = make_scenario("boxes3d", robot="sshape")
    robot = sc.robot
    greedy = make_planner("policy", robot, observation="local")
    plain = make_planner("policy", robot, observation="local", greedy_goal=False)
    shorter = 0
    for p in sc.problems("test", 10, seed=0):
        g, r = greedy.plan(p), plain.plan(p)
        k = g.nodes + 1
        np.testing.assert_allclose(g.path[:k], r.path[:k], atol=1e-9, rtol=0)
        if g.info.get("greedy_goal"):
            assert g.success and np.array_equal(g.path[-1], p.goal)
            assert check_path(robot, p, g.path, tolerance=1e-9)
            # the planner's certified test found no free edge one step earlier (else it
            # would have stopped there; the exact check may still find a hair of clearance
            # that the certified one, which grows the body, does not grant)
            if g.nodes > 0:
                assert not edge_free(robot, p.scene.world, g.path[-3], p.goal, 0.01, p.scene.low, p.scene.high)[0]
        assert g.success or not r.success
        shorter += g.nodes < r.nodes
    assert shorter >= 2
    dyn = make_scenario("dynamic3d", robot="sshape").problems("val", 2, seed=0)
    for p in dyn:
        res = greedy.plan(p)
        assert not res.info.get("greedy_goal")
    from pointplan.envs.core import EnvConfig
    from pointplan.planners.policy import rollout_batch

    with pytest.raises(ValueError, match="static scenes only"):
        rollout_batch(greedy.policy, robot, EnvConfig(observation="local"), dyn, 80, greedy_goal=True)


@pytest.mark.parametrize("observation", ["global", "local"])
def test_escape_samples_only_after_a_stall(observation: str) -> None:
    """With an escape, the rollout is the mean-action one up to and including the first
    step that left the robot where it was; from there it goes elsewhere. Every success is
    certified by the evaluator's own check, and the escape solves more of these problems
    than the mean action (the cloned S-shape pins itself against obstacles). The point-set
    observer plans through the one-robot rollout, the ray-cast one through the batched
    core: both are covered."""
    from pointplan.planners.policy import Escape, PolicyPlanner
    from pointplan.scenes.scenarios import make_scenario

    sc = make_scenario("boxes3d", robot="sshape")
    robot = sc.robot
    ckpt = shipped_checkpoint("sshape", observation)
    plain = PolicyPlanner(ckpt, robot=robot, escape=0)
    esc = PolicyPlanner(ckpt, robot=robot, escape=Escape(steps=10, noise=2.0, still=0.01))
    assert PolicyPlanner(ckpt, robot=robot).escape == Escape(
        10, 2.0, 0.01, tries=8, lookahead=3
    )  # the S-shape's default
    stalled = solved_plain = solved_esc = 0
    for p in sc.problems("val", 16, seed=0):
        a, b = plain.plan(p), esc.plan(p)
        assert "escapes" not in a.info and b.info["escapes"] >= 0
        for r in (a, b):
            assert bool(check_path(robot, p, r.path)) == r.success
        solved_plain += a.success
        solved_esc += b.success
        walk = a.path[: a.nodes + 1]  # the rollout's own configurations (no goal appended)
        moved = robot.distance(walk[:-1], walk[1:])
        still = np.flatnonzero(moved < 0.01)
        if len(still) == 0:  # never stuck: the same rollout
            assert b.info["escapes"] == 0 and b.nodes == a.nodes
            np.testing.assert_array_equal(a.path, b.path)
            continue
        stalled += 1
        k = int(still[0]) + 2  # configurations up to the end of the first still step
        np.testing.assert_allclose(b.path[:k], a.path[:k], atol=1e-9, rtol=0)
        assert b.info["escapes"] >= 1
        assert b.path.shape != a.path.shape or not np.allclose(b.path, a.path)  # it went elsewhere from there
    assert stalled >= 4
    assert solved_esc > solved_plain


def test_escape_in_a_moving_scene_and_bad_input() -> None:
    from pointplan.planners.policy import Escape, PolicyPlanner
    from pointplan.scenes.scenarios import make_scenario

    sc = make_scenario("dynamic3d", robot="sshape")
    planner = PolicyPlanner(shipped_checkpoint("sshape", "local"), robot=sc.robot, escape=10)
    assert planner.escape.steps == 10
    escapes = 0
    for p in sc.problems("val", 4, seed=0):
        r = planner.plan(p)
        assert bool(check_path(sc.robot, p, r.path)) == r.success
        escapes += r.info["escapes"]
    assert escapes >= 1
    for bad in (dict(steps=-1), dict(steps=2.5), dict(noise=-1.0), dict(still=float("nan"))):
        with pytest.raises(ValueError, match="escape"):
            Escape(**bad)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="escape"):
        PolicyPlanner(shipped_checkpoint("sshape", "local"), escape=-3)
    for bad in (dict(window=0), dict(window=1.5)):
        with pytest.raises(ValueError, match="escape window"):
            Escape(**bad)  # type: ignore[arg-type]
    whole = Escape(steps=10.0, window=6.0)  # type: ignore[arg-type]
    assert type(whole.steps) is int and type(whole.window) is int and whole == Escape(steps=10, window=6)
    sphere = PolicyPlanner(shipped_checkpoint("sphere3d", "local"))
    assert sphere.escape == Escape(steps=10, noise=0.0, still=0.1, window=6, subgoal=True)  # the sphere's default
    # its kind, 4 steps
    assert PolicyPlanner(shipped_checkpoint("sphere3d", "local"), escape=4).escape == Escape(4, 0.0, 0.1, 6, True)
    disc = PolicyPlanner(shipped_checkpoint("disc2d"))
    assert disc.escape.steps == 0  # off for the disc, where validation showed no change


@pytest.mark.parametrize("observation", ["global", "local"])
def test_subgoal_escape_frees_a_dithering_sphere(observation: str) -> None:
    """The sphere's policies fail by dithering in one place. Its escape waits for six steps
    that end within 0.1 of where they started, then heads for a random subgoal: up to that
    step the rollout is the mean-action one, and it solves most of the problems the mean
    action leaves dithering, each success certified by the evaluator's own check. The
    point-set observer plans through the one-robot rollout, the ray-cast one through the
    batched core: both are covered."""
    from pointplan.planners.policy import Escape, PolicyPlanner
    from pointplan.scenes.scenarios import make_scenario

    sc = make_scenario("boxes3d", robot="sphere3d")
    robot = sc.robot
    ckpt = shipped_checkpoint("sphere3d", observation)
    plain = PolicyPlanner(ckpt, robot=robot, escape=0, compiled=False)  # the escape's own (uncompiled) rollout
    # uncompiled too, so the two agree to the last bit (the compiled rollout hands escapes to
    # this one: tests/test_policy_kernels.py)
    esc = PolicyPlanner(
        ckpt, robot=robot, escape=Escape(steps=10, noise=0.0, still=0.1, window=6, subgoal=True), compiled=False
    )
    probs = sc.problems("val", 300, seed=0)
    failed = [(p, r) for p, r in ((p, plain.plan(p)) for p in probs) if not r.success]
    assert len(failed) >= 4  # the mean action leaves some problems unsolved
    freed = 0
    for p, a in failed:
        b = esc.plan(p)
        assert bool(check_path(robot, p, b.path)) == b.success
        freed += b.success
        walk = a.path[: a.nodes + 1]
        back = robot.distance(walk[6:], walk[:-6])  # how far each step ended from 6 steps before
        first = int(np.flatnonzero(back < 0.1)[0]) + 6  # the step that starts the first escape
        assert b.info["escapes"] >= 1
        np.testing.assert_allclose(b.path[: first + 1], walk[: first + 1], atol=1e-9, rtol=0)
    assert freed >= len(failed) / 2, (freed, len(failed))


def test_rollouts_can_go_on_after_a_moving_box_hits_the_robot() -> None:
    """``rollout_batch(crush_ends=False)`` (a comparison with a laxer rule than pointplan's,
    ``experiments/dynamic_crush.py``): where a moving box runs into the robot, the strict rollout
    ends there as a crushed failure; the lax one is the same up to that step, goes on, and
    counts the hits."""
    from pointplan.envs.core import EnvConfig
    from pointplan.planners.policy import rollout_batch
    from pointplan.scenes.scenarios import make_scenario

    sc = make_scenario("dynamic3d", robot="sphere3d")
    ckpt = shipped_checkpoint("sphere3d", "local")
    from pointplan.models.policy import Policy

    policy = Policy.from_checkpoint(ckpt)
    env = EnvConfig(observation="local", n_points=policy.n_points)
    probs = sc.problems("val", 60, seed=0)
    strict = rollout_batch(policy, sc.robot, env, probs, sc.horizon)
    lax = rollout_batch(policy, sc.robot, env, probs, sc.horizon, crush_ends=False)
    crushed = [i for i, r in enumerate(strict) if r.info.get("end") == "crushed"]
    assert crushed  # the local policy is hit in some of these
    for i, (a, b) in enumerate(zip(strict, lax)):
        if i in crushed:
            assert not a.success and b.info["crushed"] >= 1
            k = len(a.path)
            np.testing.assert_array_equal(b.path[:k], a.path)  # the same up to the hit
            assert len(b.path) > k or b.success  # and on from there
        else:
            assert b.info["crushed"] == 0 and a.success == b.success
            np.testing.assert_array_equal(a.path, b.path)


def test_the_oriented_sshape_is_told_the_world_axes_and_shares_the_sshapes_demonstrations(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """``sshape-oriented``: the S-shape's body and motion, and the world's axes in the body
    frame beside the goal vector (checked against scipy's rotations); demonstrations of
    the plain S-shape load for it, a plain S-shape policy is refused."""
    from scipy.spatial.transform import Rotation

    from pointplan.learning.bc import demos_from_paths, load_demos, resample_path, save_demos
    from pointplan.robots import make_robot
    from pointplan.scenes.scenarios import make_scenario

    plain, oriented = make_robot("sshape"), make_robot("sshape-oriented")
    assert oriented.body == plain.body == plain.name == "sshape" and oriented.name == "sshape-oriented"
    assert goal_dim(plain) == 6 and goal_dim(oriented) == 15
    rng = np.random.default_rng(3)
    q = np.concatenate([rng.uniform(-0.5, 0.5, (50, 3)), plain.sample_orientation(rng, 50)], 1)
    g = np.concatenate([rng.uniform(-0.5, 0.5, (50, 3)), plain.sample_orientation(rng, 50)], 1)
    gi = goal_input(oriented, q, g)
    np.testing.assert_array_equal(gi[:, :6], goal_input(plain, q, g))
    to_body = Rotation.from_quat(q[:, 3:]).inv()
    expected = np.concatenate([to_body.apply(np.tile(axis, (50, 1))) for axis in np.eye(3)], 1)
    np.testing.assert_allclose(gi[:, 6:], expected, atol=1e-6)
    np.testing.assert_allclose(oriented.integrate(q, g[:, :6]), plain.integrate(q, g[:, :6]))
    # the plain S-shape's demonstrations serve the oriented one (same configurations)
    sc_plain, sc_oriented = make_scenario("slot", robot="sshape"), make_scenario("slot", robot="sshape-oriented")
    p = sc_plain.problem("train", 0, seed=0)
    demos = demos_from_paths(sc_plain, "train", 0, [(0, resample_path(plain, np.stack([p.start, p.goal])))])
    save_demos(tmp_path / "d.npz", sc_plain, demos, "train", 0)
    loaded = load_demos(tmp_path / "d.npz", sc_oriented)
    np.testing.assert_array_equal(loaded.paths[0][1], demos.paths[0][1])
    with pytest.raises(ValueError, match="demonstrations of"):
        load_demos(tmp_path / "d.npz", make_scenario("slot", robot="sphere3d"))
    # a plain S-shape policy is not one for the oriented S-shape
    from pointplan.planners.policy import PolicyPlanner

    with pytest.raises(ValueError, match="trained for robot 'sshape'"):
        PolicyPlanner(Policy.from_checkpoint(shipped_checkpoint("sshape", "global")), robot=oriented)
