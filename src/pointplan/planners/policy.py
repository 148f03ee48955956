"""A learned policy as a planner: roll it out, one node per step.

:class:`PolicyPlanner` wraps a trained :class:`~pointplan.models.policy.Policy` behind the
:class:`~pointplan.planners.base.Planner` protocol; every rollout goes through the one
rollout engine (:mod:`pointplan.planners.rollout`), whose options
(:class:`~pointplan.planners.rollout.RolloutOptions`) are the planner's. Nodes are policy
steps; collision checks are the sub-configurations ``q_free`` checked, plus those of the
goal tests and the final connection to the goal.

With ``greedy_goal`` (the default) ``plan`` stops at the first configuration from which
the straight edge to the goal is certified free and ends the path at the goal
(``info["greedy_goal"]``), in static scenes. The environment stops a rollout anywhere
within ``goal_tolerance`` of the goal; the planner then tries the last step to the goal
itself (checked like a Bi-RRT edge): when it is free the path ends at the goal
(``info["end"] == "goal"``), otherwise where the policy stopped (``"near-goal"``). A
rollout that does not get there ends with ``"horizon"`` (or ``"stalled"``,
``"crushed"``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import fields, replace
from pathlib import Path
from typing import Any

from ..envs.core import EnvConfig
from ..robots.base import Robot
from ..scenes.scene import Problem
from .base import PlanResult
from .rollout import (
    ESCAPE_DEFAULTS,
    Escape,
    RolloutEngine,
    RolloutOptions,
    connect_to_goal,
    default_substep,
    rollout_batch,
    torch_threads,
)

_OPTION_NAMES = frozenset(f.name for f in fields(RolloutOptions))


class PolicyPlanner:
    """Plan by rolling out a trained policy (its mean action, with the robot's escape).

    ``policy``: a :class:`~pointplan.models.policy.Policy` or a checkpoint's path.
    ``options``: a :class:`~pointplan.planners.rollout.RolloutOptions`; its fields may
    also be given as keywords (``PolicyPlanner(policy, attempts=4)``), which replace those
    of ``options``. The ones a user changes most:

    - ``escape``: where the robot is stuck, take the next few actions from a wider spread
      or toward a random subgoal (an :class:`~pointplan.planners.rollout.Escape`, or its
      number of steps with the rest of the robot's default; ``None``: the robot's
      default, :data:`~pointplan.planners.rollout.ESCAPE_DEFAULTS`; 0: off);
    - ``attempts``, ``action_noise``: when the mean-action rollout fails, up to
      ``attempts - 1`` more from the start with sampled actions (static scenes);
      ``info["attempts"]`` says how many ran, and all their steps and checks count;
    - ``stall_steps``, ``stall_distance``: stop a rollout whose last ``stall_steps`` steps
      took it less than ``stall_distance`` from where it was (``info["end"] ==
      "stalled"``; off by default; the hybrid planner uses 10 steps and 0.035);
    - ``greedy_goal``, ``connect_goal``: the goal tests (both on by default);
    - ``draws``: the action of a step is the mean over this many observations.

    ``env``: the environment's settings the rollout steps with (an
    :class:`~pointplan.envs.core.EnvConfig`); ``None``: the policy's observation and the
    robot's planning sub-step (:data:`~pointplan.planners.rollout.SUBSTEP_DEFAULTS`).
    ``substep``: the largest sub-step of the motion check (geodesic distance), replacing
    the one of ``env`` or the robot's; finer certifies moves closer to obstacles.

    ``observer_wrapper``: a function ``observer -> observer`` applied to the observer of
    ``plan`` (e.g. :func:`pointplan.observers.perturb.perturbation`: noisy, dropped or
    occluded points; static scenes only). A PointNet actor is copied to numpy when the
    planner is made (later changes to the policy's weights are not seen; make a new
    planner). ``info["time_split"]`` of a one-robot rollout has the seconds spent
    observing, in the network and in motion checks.
    """

    name = "policy"

    def __init__(
        self,
        policy: object,
        robot: Robot | None = None,
        env: EnvConfig | None = None,
        options: RolloutOptions | None = None,
        observer_wrapper: Callable[[Any], Any] | None = None,
        substep: float | None = None,
        **option_fields: Any,
    ) -> None:
        from ..models.policy import Policy

        unknown = set(option_fields) - _OPTION_NAMES
        if unknown:
            raise TypeError(
                f"PolicyPlanner got unknown options {', '.join(sorted(unknown))}; known: {', '.join(sorted(_OPTION_NAMES))}"
            )
        if isinstance(policy, (str, Path)):
            policy = Policy.from_checkpoint(policy)
        if not isinstance(policy, Policy):
            raise TypeError(f"PolicyPlanner plans with a Policy or a checkpoint's path, not {type(policy).__name__}")
        self.policy = policy
        self.robot = robot or policy.robot
        if self.robot.name != policy.robot.name:
            raise ValueError(f"the policy was trained for robot {policy.robot.name!r}, not {self.robot.name!r}")
        if substep is not None and not (math.isfinite(substep) and substep > 0):
            raise ValueError(f"substep must be a finite number > 0, not {substep}")
        if env is None:
            env = EnvConfig(observation=policy.observation, n_points=policy.n_points)
            substep = substep or default_substep(self.robot)
        if substep is not None:
            env = replace(env, substep=substep)
        if env.observation != policy.observation:
            raise ValueError(f"the policy was trained on {policy.observation!r} observations, not {env.observation!r}")
        self.options = replace(options or RolloutOptions(), **option_fields)
        self.engine = RolloutEngine(policy, self.robot, env, self.options, observer_wrapper)

    def __repr__(self) -> str:
        return f"PolicyPlanner({self.policy.path or 'policy'}, robot={self.robot.name!r}, {self.options})"

    @property
    def env(self) -> EnvConfig:
        """The environment settings the rollout observes and moves by (the policy's own)."""
        return self.engine.env

    @property
    def horizon(self) -> int:
        """The most policy steps of one rollout."""
        return self.engine.horizon

    @property
    def escape(self) -> Escape:
        """How the rollout leaves a place where the robot is stuck (``--escape``)."""
        return self.engine.escape

    @property
    def stall_steps(self) -> int | None:
        """The rollout stops when its last this many steps left the robot within
        ``stall_distance`` of where it was (None: no stall test, the horizon only)."""
        return self.options.stall_steps

    @property
    def fast(self) -> Any:
        """The network as numpy arrays, or ``None`` (PyTorch on one thread)."""
        return self.engine.fast

    def plan(self, problem: Problem) -> PlanResult:
        """Roll the policy out from the start, each move certified free, until the goal (or a certified straight edge to it) or the horizon."""
        return self.engine.plan(problem)

    def plan_many(self, problems: Sequence[Problem]) -> list[PlanResult]:
        """All problems, by the fastest way measured for the observer
        (``benchmarks/bench_plan_many.py``): one by one through the one-robot rollout
        (compiled where it can be: the ball seeing points, the sphere and the S-shape
        seeing rays, in scenes of boxes) where the observer has one (the same results as
        ``plan``; for the sphere's ``global`` policy 67.5 queries/s against 6.9 in
        lockstep), otherwise in lockstep through the batched core (its observations are
        drawn for the batch, so a rollout may differ from ``plan``'s). One by one also with
        an ``observer_wrapper``, ``draws > 1`` or ``attempts > 1``."""
        one_by_one = (
            self.engine.one_robot()
            or self.engine.observer_wrapper is not None
            or self.options.draws > 1
            or self.options.attempts > 1
        )
        if one_by_one:
            return [self.plan(p) for p in problems]
        return self.engine.run(problems)


__all__ = [
    "ESCAPE_DEFAULTS",
    "Escape",
    "PolicyPlanner",
    "RolloutOptions",
    "connect_to_goal",
    "rollout_batch",
    "torch_threads",
]
