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
    assert RolloutOptions().escape_for("disc2d").steps == 0


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
