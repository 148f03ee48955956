"""The rollout engine: one step loop behind every stepper, its options validated once."""

from __future__ import annotations

import numpy as np
import pytest

from pointplan.models.policy import Policy, shipped_checkpoint
from pointplan.planners.policy import PolicyPlanner
from pointplan.planners.rollout import ESCAPE_DEFAULTS, Escape, RolloutEngine, RolloutOptions
from pointplan.scenes.scenarios import make_scenario


@pytest.mark.parametrize(("env", "robot", "observation"), [("narrow2d", None, None), ("boxes3d", "sshape", "global")])
def test_lockstep_and_one_robot_steppers_agree(env: str, robot: str | None, observation: str | None) -> None:
    """The same problem through the batched core (``run``) and through the one-robot
    stepper (``plan``, the compiled form off) gives the same rollout: same draws, same
    moves, same goal tests (escape off: the two draw their escape noise differently)."""
    sc = make_scenario(env, robot=robot) if robot else make_scenario(env)
    policy = Policy.from_checkpoint(shipped_checkpoint(sc.robot.name, observation))
    planner = PolicyPlanner(policy, escape=0, compiled=False)
    assert planner.engine.one_robot() and planner.engine.compiled() is None
    agree = 0
    problems = sc.problems("val", 12, seed=3)
    for p in problems:
        a = planner.plan(p)
        (b,) = planner.engine.run([p])
        assert a.success == b.success and a.info["end"] == b.info["end"]
        if a.nodes == b.nodes and a.path.shape == b.path.shape and np.allclose(a.path, b.path, atol=1e-5, rtol=0):
            agree += 1
    assert agree >= len(problems) - 1  # float32 round-off of the numpy network may part a rare rollout


def test_compiled_stepper_is_chosen_by_capability() -> None:
    """The compiled rollout is used for a ball seeing plain point subsets and for a robot
    seeing rays; a perturbed observer (its own observe_one) keeps the one-robot stepper;
    the nearest-rays observer has no one-robot form and goes through the batched core."""
    from pointplan.observers.perturb import perturbation

    sc = make_scenario("boxes3d", robot="sphere3d")
    plain = PolicyPlanner(shipped_checkpoint("sphere3d", "global"))
    assert plain.engine.one_robot() and plain.engine.compiled() is not None
    noisy = PolicyPlanner(shipped_checkpoint("sphere3d", "global"), observer_wrapper=perturbation(noise=0.005))
    assert noisy.engine.one_robot() and noisy.engine.compiled() is None
    rays = PolicyPlanner(shipped_checkpoint("sphere3d", "local"))
    assert rays.engine.one_robot() and rays.engine.compiled() is None and rays.engine.compiled_rays() is not None
    p = sc.problem("val", 0, seed=0)
    assert "compiled" in rays.plan(p).info["time_split"]
    assert "compiled" in plain.plan(p).info["time_split"]
    from pointplan.observers.rays import NearestRays

    assert not NearestRays.one_robot  # its subset is drawn otherwise: the batched core steps it


def test_options_are_validated_once() -> None:
    for bad in (
        {"attempts": 0},
        {"action_noise": -1.0},
        {"noise": float("nan")},
        {"draws": 0},
        {"stall_steps": 0},
        {"horizon": 0},
        {"escape": -2},
    ):
        with pytest.raises(ValueError):
            RolloutOptions(**bad)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="unknown options"):
        PolicyPlanner(shipped_checkpoint("disc2d"), atempts=3)
    opts = RolloutOptions(escape=4)
    assert opts.escape_for("sphere3d") == Escape(4, 0.0, 0.1, 6, True)  # the robot's kind, 4 steps
    assert RolloutOptions().escape_for("sshape") == ESCAPE_DEFAULTS["sshape"]
    # a robot's own default before its body's; a name is looked up as the robot of that name
    from pointplan.planners.rollout import default_escape
    from pointplan.robots import make_robot

    oriented = make_robot("sshape-oriented")
    assert oriented.body == "sshape" and oriented.name != "sshape"
    assert RolloutOptions().escape_for(oriented) == ESCAPE_DEFAULTS["sshape-oriented"] != ESCAPE_DEFAULTS["sshape"]
    assert RolloutOptions().escape_for("sshape-oriented") == ESCAPE_DEFAULTS["sshape-oriented"]
    assert RolloutOptions(escape=4).escape_for(oriented) == Escape(4, 2.0, 0.01, tries=64, lookahead=3, backoff=0.06)
    assert default_escape(make_robot("sshape")) == ESCAPE_DEFAULTS["sshape"]
    assert default_escape("no-such-robot") is None
    assert RolloutOptions().escape_for("disc2d").steps == 0
    assert RolloutOptions(escape=4).escape_for("sshape", 1) == Escape(
        4, 2.0, 0.01, tries=1, lookahead=3
    )  # fewer draws asked for


def test_planner_takes_the_robots_substep_unless_given_an_environment() -> None:
    from pointplan.envs.core import EnvConfig
    from pointplan.planners.rollout import SUBSTEP_DEFAULTS, default_substep

    assert default_substep("sshape-oriented") == SUBSTEP_DEFAULTS["sshape-oriented"] < EnvConfig().substep
    assert default_substep("sshape") is None
    oriented = shipped_checkpoint("sshape-oriented", "local", scene="slot")
    assert PolicyPlanner(oriented).env.substep == SUBSTEP_DEFAULTS["sshape-oriented"]
    assert PolicyPlanner(shipped_checkpoint("sshape", "local")).env.substep == EnvConfig().substep
    given = EnvConfig(observation="local", substep=0.01)
    assert PolicyPlanner(oriented, env=given).env.substep == 0.01
    assert PolicyPlanner(oriented, substep=0.02).env.substep == 0.02  # the keyword before the robot's
    assert PolicyPlanner(oriented, env=given, substep=0.0025).env.substep == 0.0025
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(ValueError, match="substep"):
            PolicyPlanner(oriented, substep=bad)


def test_stall_ends_a_rollout_in_every_stepper() -> None:
    """The stall test is one feature of the loop: the batched core stops a rollout that
    stands still too (it ran to the horizon before)."""
    sc = make_scenario("narrow2d")
    policy = Policy.from_checkpoint(shipped_checkpoint("disc2d"))

    def still(obs: np.ndarray, q: np.ndarray, goal: np.ndarray, noise: object = None) -> np.ndarray:
        return np.zeros((len(q), 2), np.float32)  # a policy that never moves

    opts = RolloutOptions(stall_steps=5, greedy_goal=False, connect_goal=False, escape=0)
    probs = [p for p in sc.problems("val", 20, seed=0) if np.linalg.norm(p.goal - p.start) > 0.2][:3]
    for res in RolloutEngine(still, sc.robot, PolicyPlanner(policy).env, opts).run(probs):
        assert res.info["end"] == "stalled" and res.nodes == 5 and not res.success


def test_screened_escape_takes_the_furthest_free_draw() -> None:
    """With ``tries`` draws an escape step takes the action whose free motion goes
    furthest: recomputed here from the same draws, each motion walked by ``q_free``; the
    rollouts that use it still pass the evaluator's path check."""
    from dataclasses import replace

    from pointplan.envs.core import q_free
    from pointplan.evaluation.evaluate import check_path
    from pointplan.planners.rollout import _OneRobot

    for bad in (0, -1, 2.5):
        with pytest.raises(ValueError, match="tries"):
            Escape(tries=bad)  # type: ignore[arg-type]
    sc = make_scenario("boxes3d", robot="sshape")
    esc = replace(ESCAPE_DEFAULTS["sshape"], tries=6, lookahead=0)
    planner = PolicyPlanner(shipped_checkpoint("sshape", "local"), escape=esc)
    eng = planner.engine
    p = sc.problem("val", 0, seed=0)
    sp = _OneRobot(eng, p, np.random.default_rng(7), sampled=False)
    q = np.asarray(p.start, np.float64)
    obs = eng.observer.observe_one(q, u=eng._uniforms(10_000)[: eng.observer.draws_one()])
    chosen = sp._furthest(obs, q, np.asarray(p.goal, np.float64))
    again = np.random.default_rng(7)
    dist, acts = [], []
    for _ in range(6):
        a = eng._act(obs, q, np.asarray(p.goal, np.float64), esc.noise * again.standard_normal(eng.action_dim))
        tw = np.clip(np.asarray(a, np.float64), -1, 1) * np.asarray(sc.robot.action_scale)
        q1, _, _ = q_free(
            sc.robot, p.scene.world, q[None], tw[None], p.scene.low[None], p.scene.high[None], eng.env.substep
        )
        dist.append(float(np.asarray(sc.robot.distance(q1, q[None]))[0]))
        acts.append(a)
    assert np.allclose(chosen, acts[int(np.argmax(dist))])
    assert sp.pending_checks > 0  # the draws' motion checks wait to be counted with the step
    escaped = 0
    for prob in sc.problems("val", 40, seed=0):
        res = planner.plan(prob)
        escaped += res.info.get("escapes", 0) > 0
        if res.success:
            assert check_path(sc.robot, prob, res.path)
    assert escaped > 0


def test_screened_escape_in_lockstep_among_moving_obstacles() -> None:
    """The batched stepper screens the escaping robots' draws too (against the obstacles
    as they are at the step's start): an escaping robot moves at least as far as its
    first draw would take it, the others keep their first draw; plans stay certified."""
    from dataclasses import replace

    from pointplan.evaluation.evaluate import check_path
    from pointplan.planners.rollout import _Lockstep, _Rows

    sc = make_scenario("dynamic3d", robot="sshape")
    esc = replace(ESCAPE_DEFAULTS["sshape"], tries=6, lookahead=0)
    planner = PolicyPlanner(shipped_checkpoint("sshape", "local"), escape=esc)
    eng = planner.engine
    probs = sc.problems("val", 4, seed=0)
    sp = _Lockstep(eng.act, sc.robot, eng.env, probs, np.random.default_rng(0), np.random.default_rng(1), 0.0, esc)
    obs = sp.core.observe(np.random.default_rng(2))["observation"]
    target = sp.core.goal.copy()
    first = np.asarray(eng.act(obs, sp.core.q.copy(), target.copy(), noise=esc.noise * np.ones((4, 6))), np.float32)
    escaping = np.array([True, False, True, False])
    q0, every = sp.core.q.copy(), _Rows(sp.core, np.arange(4))
    before = np.asarray(sc.robot.distance(sp._free_move(first, q0, every)[0], q0))
    chosen = sp._furthest(obs, target, escaping, first.copy())
    after = np.asarray(sc.robot.distance(sp._free_move(chosen, q0, every)[0], q0))
    assert np.all(after[escaping] >= before[escaping] - 1e-12)
    np.testing.assert_array_equal(chosen[~escaping], first[~escaping])
    assert np.all(sp.pending_checks[escaping] > 0) and np.all(sp.pending_checks[~escaping] == 0)
    for p in probs:
        res = planner.plan(p)
        assert bool(check_path(sc.robot, p, res.path)) == res.success


def test_escape_lookahead_takes_the_draw_the_mean_action_carries_furthest() -> None:
    """With a lookahead, an escape step takes the draw from whose free end the mean action
    carries the robot furthest: recomputed here from the same draws, every move walked by
    ``q_free`` and every observation made at the pose it is from. The compiled rollout
    looks ahead in its own kernel (a second implementation): the same plans as the step
    loop's."""
    from dataclasses import replace

    from pointplan.envs.core import q_free
    from pointplan.evaluation.evaluate import check_path
    from pointplan.planners.rollout import _OneRobot

    with pytest.raises(ValueError, match="lookahead"):
        Escape(lookahead=-1)
    sc = make_scenario("boxes3d", robot="sshape")
    esc = replace(ESCAPE_DEFAULTS["sshape"], tries=5, lookahead=2)
    planner = PolicyPlanner(shipped_checkpoint("sshape", "local"), escape=esc)
    eng = planner.engine
    p = sc.problem("val", 1, seed=0)
    goal, scene = np.asarray(p.goal, np.float64), p.scene
    sp = _OneRobot(eng, p, np.random.default_rng(5), sampled=False)
    u = eng._uniforms(10_000)[: eng.observer.draws_one()]
    q = np.asarray(p.start, np.float64)
    obs = eng.observer.observe_one(q, u=u)
    chosen = sp._furthest(obs, q, goal)

    def walk(q0: np.ndarray, a: np.ndarray) -> np.ndarray:
        tw = np.clip(np.asarray(a, np.float64), -1, 1) * np.asarray(sc.robot.action_scale)
        return q_free(sc.robot, scene.world, q0[None], tw[None], scene.low[None], scene.high[None], eng.env.substep)[0][
            0
        ]

    again, scores, own, acts = np.random.default_rng(5), [], [], []
    for _ in range(5):
        a = eng._act(obs, q, goal, esc.noise * again.standard_normal(eng.action_dim))
        qk = walk(q, a)
        own.append(float(np.asarray(sc.robot.distance(qk[None], q[None]))[0]))
        for _ in range(2):
            qk = walk(qk, eng._act(eng.observer.observe_one(qk, u=u), qk, goal, None))
        scores.append(float(np.asarray(sc.robot.distance(qk[None], q[None]))[0]))
        acts.append(a)
    assert np.allclose(chosen, acts[int(np.argmax(scores))])
    assert np.argmax(own) != np.argmax(scores)  # here the lookahead, not the draw's own motion, decides
    compiled, plain = planner, PolicyPlanner(shipped_checkpoint("sshape", "local"), escape=esc, compiled=False)
    assert compiled.engine.compiled_rays() is not None
    same = escaped = 0
    probs = sc.problems("val", 12, seed=0)
    for prob in probs:
        a, b = compiled.plan(prob), plain.plan(prob)
        escaped += a.info.get("escapes", 0) > 0
        assert "compiled" in a.info["time_split"] and "compiled" not in b.info["time_split"]
        assert a.info["time_split"]["observe"] == 0.0  # no step of it went through the step loop
        same += a.path.shape == b.path.shape and np.allclose(a.path, b.path, atol=1e-5, rtol=0)
        assert a.success == bool(check_path(sc.robot, prob, a.path))
    assert escaped > 0 and same >= len(probs) - 1


def test_escape_lookahead_in_lockstep() -> None:
    """The batched stepper looks ahead too (observing each draw's lookahead through the
    batched observer, among the obstacles as they are at the step's start): an escaping
    robot's choice changes with it, the others keep their first draw, its checks are
    counted, and the plans through moving obstacles stay certified."""
    from dataclasses import replace

    from pointplan.evaluation.evaluate import check_path
    from pointplan.planners.rollout import _Lockstep

    sc = make_scenario("dynamic3d", robot="sshape")
    plain = replace(ESCAPE_DEFAULTS["sshape"], tries=6, lookahead=0)
    ahead = replace(plain, lookahead=3)
    eng = PolicyPlanner(shipped_checkpoint("sshape", "local"), escape=ahead).engine
    probs = sc.problems("val", 6, seed=0)
    escaping = np.array([True, False, True, True, False, True])
    chosen = {}
    for esc in (plain, ahead):
        sp = _Lockstep(eng.act, sc.robot, eng.env, probs, np.random.default_rng(0), np.random.default_rng(1), 0.0, esc)
        obs = sp.core.observe(np.random.default_rng(2))["observation"]
        target = sp.core.goal.copy()
        first = np.asarray(eng.act(obs, sp.core.q.copy(), target.copy(), noise=2.0 * np.ones((6, 6))), np.float32)
        chosen[esc.lookahead] = sp._furthest(obs, target, escaping, first.copy())
        np.testing.assert_array_equal(chosen[esc.lookahead][~escaping], first[~escaping])
        assert np.all(sp.pending_checks[~escaping] == 0)
        if esc.lookahead:
            assert np.all(sp.pending_checks[escaping] > 6 * 3)  # the lookahead's moves are checked and counted
    assert not np.allclose(chosen[0][escaping], chosen[3][escaping])
    planner = PolicyPlanner(shipped_checkpoint("sshape", "local"), escape=ahead)
    for p, res in zip(probs, planner.engine.run(probs)):
        assert bool(check_path(sc.robot, p, res.path)) == res.success


def test_lockstep_escape_draws_for_the_escaping_robots_alone() -> None:
    """The batched stepper's screened escape works on its escaping robots apart from the
    batch: the same choices and the same counted checks as a batch of those problems
    alone, all escaping, from the same observations and random streams (moving obstacles,
    robots at different time steps)."""
    from dataclasses import replace

    from pointplan.planners.rollout import _Lockstep

    sc = make_scenario("dynamic3d", robot="sshape")
    esc = replace(ESCAPE_DEFAULTS["sshape"], tries=5, lookahead=2)
    eng = PolicyPlanner(shipped_checkpoint("sshape", "local"), escape=esc).engine
    probs = sc.problems("val", 5, seed=0)
    escaping = np.array([False, True, False, True, True])
    steppers = {}
    for name, batch in (("all", probs), ("alone", [p for p, e in zip(probs, escaping) if e])):
        sp = _Lockstep(eng.act, sc.robot, eng.env, batch, np.random.default_rng(0), np.random.default_rng(1), 0.0, esc)
        sp.core.t[:] = np.arange(len(batch)) * 3 if name == "all" else np.flatnonzero(escaping) * 3
        steppers[name] = sp
    obs = steppers["all"].core.observe(np.random.default_rng(2))["observation"]
    target = steppers["all"].core.goal.copy()
    first = np.asarray(eng.act(obs, steppers["all"].core.q.copy(), target.copy()), np.float32)
    chosen = steppers["all"]._furthest(obs, target, escaping, first.copy())
    alone = steppers["alone"]._furthest(obs[escaping], target[escaping], np.ones(3, bool), first[escaping].copy())
    np.testing.assert_array_equal(chosen[escaping], alone)
    np.testing.assert_array_equal(chosen[~escaping], first[~escaping])
    np.testing.assert_array_equal(steppers["all"].pending_checks[escaping], steppers["alone"].pending_checks)
    assert np.all(steppers["all"].pending_checks[~escaping] == 0) and np.all(steppers["alone"].pending_checks > 0)
    assert not np.array_equal(chosen[escaping], first[escaping])  # the escape chose other draws


def test_escape_backs_off_where_every_draw_is_refused(one_torch_thread: None) -> None:
    """Wedged in a Slot opening a fraction of a millimetre from a wall, every escape draw
    is refused; with ``backoff`` the step heads back along the robot's own path instead:
    the action toward the latest pose more than ``backoff`` away (recomputed here from the
    robot's exponential map), the same in the one-robot stepper and the batched one, and
    the plan it gives is certified by the evaluator (the compiled kernel's back-off:
    tests/test_rigid_kernels.py)."""
    from dataclasses import replace

    from pointplan.envs.core import q_free
    from pointplan.evaluation.evaluate import check_path
    from pointplan.planners.rollout import _back_off, _Lockstep, _OneRobot

    for bad in (-0.1, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="backoff"):
            Escape(tries=8, backoff=bad)
    sc = make_scenario("slot", robot="sshape-oriented")
    robot = sc.robot
    scale = np.asarray(robot.action_scale, np.float64)
    # the helper: a pose within one step's reach is reached exactly; a far one in a step
    # as long as the action box allows, in the same direction
    p = sc.problem("val", 487, seed=1)  # frozen in the opening without the back-off
    rng = np.random.default_rng(0)
    q = robot.sample_uniform(rng, 1, p.scene.low, p.scene.high)[0]
    near = robot.integrate(q[None], (0.3 * scale * rng.uniform(-1, 1, len(scale)))[None])[0]
    far = robot.integrate(q[None], (4.0 * scale * rng.uniform(-1, 1, len(scale)))[None])[0]
    past = np.stack([far, near, q])
    a = _back_off(robot, past, q, 0.0)
    assert a is not None and np.allclose(robot.integrate(q[None], (a * scale)[None])[0], near, atol=1e-5)
    b = _back_off(robot, past, q, float(robot.distance(near[None], q[None])[0]) + 1e-6)
    twist = np.asarray(robot.log(q[None], far[None]))[0] / scale
    assert (
        b is not None
        and np.isclose(np.max(np.abs(b)), 1.0)
        and np.allclose(b, twist / np.max(np.abs(twist)), atol=1e-5)
    )
    assert _back_off(robot, past, q, 1e3) is None

    policy = Policy.from_checkpoint("src/pointplan/data/slot_sshape_oriented_local_policy.pt")
    esc = replace(ESCAPE_DEFAULTS["sshape-oriented"], backoff=0.0)
    stuck = PolicyPlanner(policy, robot=robot, escape=esc, compiled=False).plan(p)
    assert not stuck.success and stuck.info["escapes"] > 0
    path, wedged = stuck.path, stuck.path[-1]
    if np.allclose(wedged, p.goal):  # (a failed plan's path ends where the rollout stopped)
        path, wedged = path[:-1], path[-2]
    eng = PolicyPlanner(policy, robot=robot, escape=replace(esc, backoff=0.03), compiled=False).engine
    goal = np.asarray(p.goal, np.float64)
    sp = _OneRobot(eng, p, np.random.default_rng(3), sampled=False)
    obs = eng.observer.observe_one(wedged, u=eng._uniforms(10_000)[: eng.observer.draws_one()])
    drawn = sp._furthest(obs, wedged, goal)  # no path: the best draw
    tw = np.clip(np.asarray(drawn, np.float64), -1, 1) * scale
    q1 = q_free(robot, p.scene.world, wedged[None], tw[None], p.scene.low[None], p.scene.high[None], eng.env.substep)[0]
    assert float(robot.distance(q1, wedged[None])[0]) < 1e-3  # every draw refused
    expected = _back_off(robot, path, wedged, 0.03)
    assert expected is not None
    sp = _OneRobot(eng, p, np.random.default_rng(3), sampled=False)
    np.testing.assert_allclose(sp._furthest(obs, wedged, goal, path), expected, atol=1e-6)
    lock = _Lockstep(eng.act, robot, eng.env, [p], np.random.default_rng(0), np.random.default_rng(1), 0.0, eng.escape)
    lock.core.q[0] = wedged
    lobs = lock.core.observe(np.random.default_rng(2))["observation"]
    first = np.asarray(eng.act(lobs, lock.core.q.copy(), goal[None].copy(), noise=2.0 * np.ones((1, 6))), np.float32)
    chosen = lock._furthest(lobs, goal[None].copy(), np.array([True]), first.copy(), path[:, None])
    np.testing.assert_allclose(chosen[0], expected, atol=1e-6)

    backed = PolicyPlanner(policy, robot=robot, escape=replace(esc, backoff=0.03)).plan(p)
    assert backed.success and check_path(robot, p, backed.path)
