"""A learned policy as a planner: roll it out, one node per step.

``rollout_batch`` plays many problems at once through the batched environment core
(deterministic actions); ``PolicyPlanner`` wraps a trained :class:`~pointplan.models.policy.Policy`
behind the :class:`Planner` protocol. Nodes are policy steps; collision checks are the
sub-configurations ``q_free`` checked.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..envs.core import BatchedCore, EnvConfig
from ..robots.base import Robot
from ..scenes.scenarios import Scenario
from ..scenes.scene import Problem, Scene
from .base import PlanResult

ActFn = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]


class _GivenProblems(Scenario):
    """A scenario that only plays the problems it is handed."""

    name = "given"

    def __init__(self, robot: Robot, horizon: int) -> None:
        self.robot = robot
        self.horizon = horizon

    def scene(self, split: str, index: int) -> Scene:
        raise RuntimeError("rollouts play given problems only")


def rollout_batch(act: ActFn, robot: Robot, env: EnvConfig, problems: Sequence[Problem], horizon: int, seed: int = 0, chunk: int = 100) -> list[PlanResult]:
    """Roll ``act(obs, q, goal) -> actions`` out on every problem, ``chunk`` at a time.
    The time of a chunk is shared equally by its problems."""
    results: list[PlanResult] = []
    env = replace(env, horizon=horizon)
    for c0 in range(0, len(problems), chunk):
        probs = list(problems[c0 : c0 + chunk])
        n = len(probs)
        t0 = time.perf_counter()
        rng = np.random.default_rng(np.random.SeedSequence([seed, c0]))
        core = BatchedCore(_GivenProblems(robot, horizon), n, env)
        core.reset_envs(range(n), rng, probs)
        paths = np.zeros((horizon + 1, n, robot.config_dim))
        paths[0] = core.q
        length = np.ones(n, np.int64)
        checks = np.zeros(n, np.int64)
        active = np.ones(n, bool)
        success = np.zeros(n, bool)
        for t in range(horizon):
            obs = core.observe(rng)["observation"]  # (at each problem's own time step)
            a = np.asarray(act(obs, core.q.copy(), core.goal.copy()), np.float32)
            a[~active] = 0.0  # finished problems stand still
            _, term, _, info = core.step(a)
            paths[t + 1] = core.q
            length += active
            checks += np.where(active, info["collision_checks"], 0)
            success |= term & active
            active &= ~(term | info["crushed"])  # a moving obstacle that hits the robot ends it
            if not active.any():
                break
        dt = (time.perf_counter() - t0) / n
        for i in range(n):
            k = int(length[i])
            results.append(PlanResult(path=paths[:k, i].copy(), success=bool(success[i]), nodes=k - 1, collision_checks=int(checks[i]), time_s=dt))
    return results


class PolicyPlanner:
    """Plan by rolling out a trained policy (deterministic mean actions)."""

    name = "policy"

    def __init__(self, policy: object, robot: Robot | None = None, horizon: int | None = None, env: EnvConfig | None = None) -> None:
        from ..models.policy import Policy

        if isinstance(policy, (str, Path)):
            policy = Policy.from_checkpoint(policy)
        assert isinstance(policy, Policy)
        self.policy = policy
        self.robot = robot or policy.robot
        if self.robot.name != policy.robot.name:
            raise ValueError(f"the policy was trained for robot {policy.robot.name!r}, not {self.robot.name!r}")
        self.env = env or EnvConfig(observation=policy.observation, n_points=policy.n_points)
        if self.env.observation != policy.observation:
            raise ValueError(f"the policy was trained on {policy.observation!r} observations, not {self.env.observation!r}")
        self.horizon = int(horizon or policy.meta.get("horizon") or 50)

    def plan(self, problem: Problem) -> PlanResult:
        return rollout_batch(self.policy, self.robot, self.env, [problem], self.horizon)[0]

    def plan_many(self, problems: Sequence[Problem]) -> list[PlanResult]:
        """All problems at once (much faster than one by one)."""
        return rollout_batch(self.policy, self.robot, self.env, problems, self.horizon)
