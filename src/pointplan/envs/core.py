"""The batched core shared by the single and the vector environment.

``E`` workspaces step together: one collision query answers every sub-step of every
environment, one observer call observes them all.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..geometry.collision import CollisionWorld
from ..observers import make_observer
from ..observers.base import Observer
from ..robots.base import Robot
from ..robots.motion import intervals
from ..scenes.scenarios import Scenario
from ..scenes.scene import Problem, Scene

Array = NDArray[np.float64]
Bool = NDArray[np.bool_]


@dataclass(frozen=True)
class EnvConfig:
    """Settings of a planning environment (keyword arguments of ``gymnasium.make``)."""

    #: observation type: ``surface``, ``surface-normals``, ``interior``, ``image`` (2D);
    #: ``global``, ``local`` (3D); ``None`` takes the scenario's default
    observation: str | None = None
    #: number of observed points (point observers); ``None`` takes the observer's default
    #: (64; 256 for ``global``)
    n_points: int | None = None
    #: ``train``, ``val`` (held out for model selection) or ``test`` workspaces
    split: str = "train"
    #: episode length; ``None`` takes the scenario's (50 for 2D-Narrow)
    horizon: int | None = None
    #: success when the geodesic distance to the goal is below this (and no collision)
    goal_tolerance: float = 0.07
    #: largest sub-step of ``q_free`` (geodesic distance)
    substep: float = 0.01
    reward_free: float = -0.1
    reward_collision: float = -4.0
    reward_success: float = 20.0
    #: weight of the action's norm in the reward (the paper: 1). Lower it for the 6-DoF
    #: S-shape: with weight 1, 46% of Bi-RRT's S-shape solutions in 3D-Boxes earn less than
    #: standing still for the whole episode (docs/notebook/sshape.md, "The action cost")
    action_cost: float = 1.0
    #: a move that would leave the workspace: ``clip`` sends it to its end clipped into the
    #: bounds (sliding along the border, checked); ``stop`` ends it at the border
    bounds: str = "clip"

    def __post_init__(self) -> None:
        if self.bounds not in ("clip", "stop"):
            raise ValueError(f"bounds must be 'clip' or 'stop', not {self.bounds!r}")

    def observation_for(self, robot: Robot) -> str:
        """The observer's name: ``observation``, or by default boundary points with
        normals in 2D and ``global`` points in 3D."""
        return self.observation or ("surface-normals" if robot.dim == 2 else "global")


def q_free(
    robot: Robot,
    world: CollisionWorld,
    q: Array,
    twist: Array,
    low: Array,
    high: Array,
    substep: float = 0.01,
    clip_target: bool = True,
) -> tuple[Array, Bool, NDArray[np.int64]]:
    """Walk ``q -> q * exp(twist)`` in sub-steps of at most ``substep`` and stop at the last
    free one inside the bounds.

    ``q: (E, config_dim)``, ``twist: (E, twist_dim)``, ``world`` stacked over ``E`` (or a
    single world), ``low, high: (E, d)``. With ``clip_target`` (the default) a move whose
    end leaves the bounds is sent to its end clipped into the bounds instead (the twist
    becomes ``log(q^-1 clip(q exp(twist)))``, shortened where it would be a longer step
    than ``twist`` in units of ``robot.action_scale``: one action stays one time step), so a
    robot pushing against the border slides along it, like the paper's clipping, but on a
    path that is checked. The bounds then
    stop a move like an obstacle does (only an SE(3) screw motion can bulge out on its way),
    without counting as a collision: the robot ends at the last sub-step before the first
    one that collides or leaves the bounds. So the executed motion is always a piece of one
    geodesic from ``q`` (what the evaluator re-checks) and stays inside the bounds. Returns
    the new configurations, whether the move was stopped by a collision, and the number of
    configurations checked per environment. A move shorter than ``substep`` is still checked.

    The sub-steps are certified by the robot's motion validator
    (:func:`pointplan.robots.motion.check_motions`): the body is grown at every sub-step so
    that no configuration between two of them, nor the start pose, can touch an obstacle
    unnoticed. With moving obstacles ``world`` is the world at the end of the step, and the
    start pose is checked against it too.
    """
    q = np.asarray(q, np.float64)
    twist = np.asarray(twist, np.float64)
    if clip_target:
        target = robot.integrate(q, twist)
        clipped = robot.clip(target, low, high)
        moved = np.any(clipped != target, axis=-1)
        if moved.any():  # aim at the clipped target instead: slide along the border, checked
            twist = twist.copy()
            scale = np.asarray(robot.action_scale, np.float64)
            aimed = robot.log(q[moved], clipped[moved])
            # never a longer step than the one commanded (in actions, the evaluator's clock):
            # an SE(3) log aimed at the clipped pose can exceed it in a translation coordinate
            cap = np.maximum(np.max(np.abs(twist[moved]) / scale, axis=-1), 1.0)
            size = np.max(np.abs(aimed) / scale, axis=-1)
            f = np.where(size > cap, cap / np.where(size > 0, size, 1.0), 1.0)
            twist[moved] = aimed * f[:, None]
    n = intervals(np.linalg.norm(twist, axis=-1), substep)
    chk = robot.check_motions(world, q, twist, n, low, high)
    rows = np.arange(q.shape[0])
    last = chk.free
    new_q = np.where((last > 0)[:, None], chk.configs[rows, np.maximum(last, 0)], q)
    return new_q, chk.collided, chk.checks


def goal_reached(
    robot: Robot, config: EnvConfig, achieved: Array, desired: Array, collided: Bool | None = None
) -> Bool:
    """The success rule: within the goal tolerance of ``desired`` (in a step that did not
    collide, when ``collided`` is given)."""
    ok = robot.distance(achieved, desired) < config.goal_tolerance
    return ok if collided is None else ok & ~np.asarray(collided, bool)


def step_reward(config: EnvConfig, action_norm: Array, collided: Bool, success: Bool) -> Array:
    """The reward rule: ``-action_cost |a| + (free | collided penalty) + success bonus``."""
    c = config
    return (
        -c.action_cost * np.asarray(action_norm)
        + np.where(collided, c.reward_collision, c.reward_free)
        + c.reward_success * success
    )


def _stacked_at(scenes: Sequence[Scene], t: NDArray[np.int64]) -> CollisionWorld:
    """The obstacles of ``scenes``, each at its own time ``t[i]``, stacked."""
    return CollisionWorld.stack([s.world_at(int(ti)) for s, ti in zip(scenes, t)])


class BatchedCore:
    """``E`` planning environments of one scenario stepping in lockstep."""

    def __init__(self, scenario: Scenario, num_envs: int, config: EnvConfig) -> None:
        if config.split not in ("train", "val", "test"):
            raise ValueError(f"split must be 'train', 'val' or 'test', not {config.split!r}")
        self.scenario = scenario
        self.robot: Robot = scenario.robot
        self.config = config
        self.num_envs = int(num_envs)
        self.horizon = int(config.horizon or scenario.horizon)
        observation = config.observation_for(self.robot)
        kwargs: dict[str, Any] = {}
        if observation != "image" and config.n_points is not None:
            kwargs["n_points"] = config.n_points
        self.observer = make_observer(observation, self.robot, **kwargs)
        self.observation = observation
        self._observer_kwargs = kwargs
        e, c = self.num_envs, self.robot.config_dim
        self.q = np.zeros((e, c))
        self.goal = np.zeros((e, c))
        self.t = np.zeros(e, dtype=np.int64)
        self.scenes: list[Scene | None] = [None] * e
        # what the scenes' bounds bound: positions (rigid robots) or joints (an arm)
        k = self.robot.positions(np.zeros(c)).shape[-1]
        self.low = np.zeros((e, k))
        self.high = np.ones((e, k))
        self._world: CollisionWorld | None = None

    # ------------------------------------------------------------------ resets
    def reset_envs(
        self, idx: Sequence[int], rng: np.random.Generator, problems: Sequence[Problem | None] | None = None
    ) -> None:
        """Start new episodes in environments ``idx``: a new workspace and problem each,
        drawn from ``rng``, or the given problems."""
        for j, i in enumerate(idx):
            prob = problems[j] if problems is not None else None
            if prob is None:
                scene = self.scenario.scene(self.config.split, int(rng.integers(0, 2**31 - 1)))
                start, goal = self.scenario.sample_problem(scene, rng)
            else:
                if prob.scene.dim != self.robot.dim or prob.start.shape != (self.robot.config_dim,):
                    raise ValueError(
                        f"problem {prob.tag or ''} does not fit robot {self.robot.name} "
                        f"(start has {prob.start.shape[0]} coordinates, expected {self.robot.config_dim})"
                    )
                scene, start, goal = prob.scene, prob.start, prob.goal
            if self.scenes[i] is not scene:
                self.scenes[i] = scene
                self._world = None
                if len(self.observer.scenes) < self.num_envs:
                    self.observer.bind([s if s is not None else scene for s in self.scenes])
                else:
                    self.observer.set_scene(i, scene)
            self.q[i], self.goal[i], self.t[i] = start, goal, 0
            self.low[i], self.high[i] = scene.low, scene.high

    @property
    def world(self) -> CollisionWorld:
        """The stacked obstacles of the ``E`` scenes (static scenes)."""
        if self._world is None:
            scenes = [s for s in self.scenes if s is not None]
            if len(scenes) != self.num_envs:
                raise RuntimeError("reset every environment before stepping")
            self._world = CollisionWorld.stack([s.world for s in scenes])
        return self._world

    def world_at(self, t: NDArray[np.int64]) -> CollisionWorld:
        """The stacked obstacles with each environment's scene at its own time ``t[i]``."""
        scenes = [s for s in self.scenes if s is not None]
        if not any(s.dynamic for s in scenes):
            return self.world
        if len(scenes) != self.num_envs:
            raise RuntimeError("reset every environment before stepping")
        return _stacked_at(scenes, t)

    def rows(self, idx: Sequence[int] | NDArray[np.int64], t: NDArray[np.int64]) -> tuple[Observer, CollisionWorld]:
        """A fresh observer of this core's kind bound to the scenes of environments ``idx``
        alone, and their obstacles at times ``t`` (one per environment of ``idx``): a few
        environments observed and moved apart from the batch (the scenes keep their point
        sets and obstacle worlds cached, so this is cheap)."""
        scenes = [s for s in (self.scenes[int(i)] for i in idx) if s is not None]
        if len(scenes) != len(idx):
            raise RuntimeError("reset every environment before stepping")
        observer = make_observer(self.observation, self.robot, **self._observer_kwargs)
        observer.bind(scenes)
        return observer, _stacked_at(scenes, t)

    # ------------------------------------------------------------------ step
    def observe(self, rng: np.random.Generator) -> dict[str, NDArray[np.float32]]:
        return {
            "observation": self.observer.observe(self.q, rng, self.t),
            "achieved_goal": self.q.astype(np.float32),
            "desired_goal": self.goal.astype(np.float32),
        }

    def success(self, achieved: Array, desired: Array, collided: Bool | None = None) -> Bool:
        return goal_reached(self.robot, self.config, achieved, desired, collided)

    def reward(self, action_norm: Array, collided: Bool, success: Bool) -> Array:
        return step_reward(self.config, action_norm, collided, success)

    def step(self, actions: ArrayLike) -> tuple[Array, Bool, Bool, dict[str, Any]]:
        """Apply actions ``(E, twist_dim)`` in [-1, 1]: returns reward, terminated,
        truncated and per-environment info arrays. Observations come from ``observe``."""
        a = np.clip(np.asarray(actions, np.float64).reshape(self.num_envs, self.robot.twist_dim), -1.0, 1.0)
        twist = a * self.robot.action_scale
        # a move from step t to t + 1 is checked against the obstacles at t + 1
        world = self.world_at(self.t + 1)
        self.q, collided, checks = q_free(
            self.robot,
            world,
            self.q,
            twist,
            self.low,
            self.high,
            self.config.substep,
            clip_target=self.config.bounds == "clip",
        )
        crushed = np.zeros(self.num_envs, dtype=bool)
        if world is not self._world:  # moving obstacles: one may have run into the robot
            crushed = self.robot.collides(world, self.q[:, None])[:, 0]
            collided |= crushed
        self.t += 1
        success = self.success(self.q, self.goal, collided)
        action_norm = np.linalg.norm(a, axis=-1)
        reward = self.reward(action_norm, collided, success)
        # an obstacle that ran into the robot ends the episode, as a failure
        truncated = ((self.t >= self.horizon) | crushed) & ~success
        info = {
            "collided": collided,
            "crushed": crushed,
            "is_success": success,
            "action_norm": action_norm,
            "collision_checks": checks,
        }
        return reward, success, truncated, info
