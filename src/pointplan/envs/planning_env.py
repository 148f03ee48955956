"""Goal-conditioned Gymnasium environments for rigid-body motion planning."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from numpy.typing import NDArray

from ..robots.base import Robot
from ..scenes.scenarios import Scenario, make_scenario
from ..scenes.scene import Problem
from .core import Array, BatchedCore, EnvConfig

#: draws ``(problem, robot, q)`` as an RGB image for ``render_mode="rgb_array"``
Renderer = Callable[[Problem, Robot, Array], NDArray[np.uint8]]
_renderer: Renderer | None = None


def set_renderer(renderer: Renderer | None) -> None:
    """Install what :meth:`PlanningEnv.render` draws with (the package root installs
    :func:`pointplan.viz.plot2d.render_rgb`)."""
    global _renderer
    _renderer = renderer


def _resolve(scenario: str | Scenario, robot: str | None = None) -> Scenario:
    if isinstance(scenario, str):
        return make_scenario(scenario, robot=robot)
    if robot is not None and robot != scenario.robot.name:
        raise ValueError(f"robot={robot!r} conflicts with the scenario's robot {scenario.robot.name!r}")
    return scenario


def _goal_space(core: BatchedCore) -> spaces.Box:
    robot = core.robot
    bounds_low, bounds_high = core.scenario.bounds
    low = np.full(robot.config_dim, -1.0, dtype=np.float32)
    high = np.full(robot.config_dim, 1.0, dtype=np.float32)
    low[: robot.dim], high[: robot.dim] = bounds_low, bounds_high
    return spaces.Box(low, high, dtype=np.float32)


def _info_arrays(info: Any, n: int) -> tuple[Array, NDArray[np.bool_]]:
    """(action_norm, collided) from one info dict, or a sequence of them (HER buffers)."""
    need = "compute_reward needs the step's info['action_norm'] and info['collided'] (with stable-baselines3's HerReplayBuffer, pass copy_info_dict=True)"
    if isinstance(info, dict):
        if "action_norm" not in info or "collided" not in info:
            raise KeyError(need)
        return np.asarray(info["action_norm"], np.float64), np.asarray(info["collided"], bool)
    infos = list(np.asarray(info, dtype=object).reshape(-1))
    if any("action_norm" not in i or "collided" not in i for i in infos):
        raise KeyError(need)
    return (
        np.array([float(i["action_norm"]) for i in infos]).reshape(n),
        np.array([bool(i["collided"]) for i in infos]).reshape(n),
    )


class PlanningEnv(gym.Env[dict[str, NDArray[np.float32]], NDArray[np.float32]]):
    """One robot, one workspace per episode, reach the goal without colliding.

    Observation: a dict with ``observation`` (obstacles in the robot frame, e.g. ``(N, 4)``
    points and normals), ``achieved_goal`` (the current configuration) and ``desired_goal``
    (the goal configuration), both in the world frame. Action: a body twist in
    ``[-1, 1]^k`` scaled by the robot's ``action_scale``. Reward
    ``-||a|| + (-0.1 free | -4 collided) + 20 on success``. ``info`` carries ``collided``,
    ``is_success``, ``action_norm`` and ``collision_checks``.

    Pass ``options={"problem": Problem}`` to ``reset`` to play a given problem.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(
        self,
        scenario: str | Scenario = "narrow2d",
        render_mode: str | None = None,
        robot: str | None = None,
        **settings: Any,
    ) -> None:
        self.config = EnvConfig(**settings)
        self.core = BatchedCore(_resolve(scenario, robot), 1, self.config)
        self.robot = self.core.robot
        self.render_mode = render_mode
        self.observation_space = spaces.Dict(  # type: ignore[assignment]  # (gymnasium's Dict is not generic in its value type)
            {
                "observation": self.core.observer.space,
                "achieved_goal": _goal_space(self.core),
                "desired_goal": _goal_space(self.core),
            }
        )
        k = self.robot.twist_dim
        self.action_space = spaces.Box(-1.0, 1.0, shape=(k,), dtype=np.float32)

    @property
    def problem(self) -> Problem:
        """The current problem."""
        scene = self.core.scenes[0]
        assert scene is not None, "call reset first"
        return Problem(scene, self.core.q[0].copy(), self.core.goal[0].copy())

    def _obs(self) -> dict[str, NDArray[np.float32]]:
        return {k: v[0] for k, v in self.core.observe(self.np_random).items()}

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, NDArray[np.float32]], dict[str, Any]]:
        """Start an episode: a random problem of the split, or ``options["problem"]``;
        returns ``(observation, info)``."""
        super().reset(seed=seed)  # seeds self.np_random, the env's one generator
        problem = (options or {}).get("problem")
        self.core.reset_envs([0], self.np_random, [problem] if problem is not None else None)
        return self._obs(), {}

    def step(
        self, action: NDArray[np.float32]
    ) -> tuple[dict[str, NDArray[np.float32]], float, bool, bool, dict[str, Any]]:
        """Move by ``action`` (the motion checked in sub-steps; a collision stops it);
        returns ``(observation, reward, terminated, truncated, info)``."""
        reward, term, trunc, info = self.core.step(np.asarray(action)[None])
        one = {k: (v[0].item() if isinstance(v[0], np.generic) else v[0]) for k, v in info.items()}
        return self._obs(), float(reward[0]), bool(term[0]), bool(trunc[0]), one

    def compute_reward(self, achieved_goal: Array, desired_goal: Array, info: Any) -> Array:
        """The reward the env would have given for reaching ``achieved_goal`` while aiming at
        ``desired_goal`` (hindsight relabelling). Batched over leading dimensions."""
        achieved = np.asarray(achieved_goal, np.float64)
        desired = np.asarray(desired_goal, np.float64)
        n = int(np.prod(achieved.shape[:-1])) if achieved.ndim > 1 else 1
        norm, collided = _info_arrays(info, n)
        norm = norm.reshape(achieved.shape[:-1])
        collided = collided.reshape(achieved.shape[:-1])
        success = self.core.success(achieved, desired, collided)
        return self.core.reward(norm, collided, success)

    def render(self) -> NDArray[np.uint8] | None:
        """The problem and the robot as an RGB image (``render_mode="rgb_array"``; else None)."""
        if self.render_mode != "rgb_array":
            return None
        if _renderer is None:
            raise RuntimeError("no renderer is installed (importing pointplan installs one): see set_renderer")
        return _renderer(self.problem, self.robot, self.core.q[0])


class PlanningVectorEnv(VectorEnv[dict[str, NDArray[np.float32]], NDArray[np.float32], NDArray[Any]]):
    """``num_envs`` environments, each in its own workspace, stepping in one batched call.

    Autoreset is "same step": when an episode ends, the returned observation already
    belongs to the next episode and ``infos["final_obs"]`` / ``infos["final_info"]`` hold the
    last observation and info of the finished one.
    """

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": []}

    def __init__(
        self, scenario: str | Scenario = "narrow2d", num_envs: int = 16, robot: str | None = None, **settings: Any
    ) -> None:
        self.config = EnvConfig(**settings)
        self.core = BatchedCore(_resolve(scenario, robot), num_envs, self.config)
        self.robot = self.core.robot
        self.num_envs = int(num_envs)
        self.single_observation_space = spaces.Dict(
            {
                "observation": self.core.observer.space,
                "achieved_goal": _goal_space(self.core),
                "desired_goal": _goal_space(self.core),
            }
        )
        self.single_action_space = spaces.Box(-1.0, 1.0, shape=(self.robot.twist_dim,), dtype=np.float32)
        self.observation_space = gym.vector.utils.batch_space(self.single_observation_space, self.num_envs)
        self.action_space = gym.vector.utils.batch_space(self.single_action_space, self.num_envs)

    def reset(
        self, *, seed: int | list[int] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, NDArray[np.float32]], dict[str, Any]]:
        """Start an episode in every environment: random problems, or ``options["problems"]``
        (one per environment, ``None`` for a random one); ``seed`` an int or one per
        environment."""
        if isinstance(seed, int) or seed is None:
            super().reset(seed=seed)  # seeds self.np_random, the env's one generator
        else:  # one seed per environment: the generator is drawn from all of them
            self.np_random = np.random.default_rng(list(seed))
        problems: Sequence[Problem | None] | None = (options or {}).get("problems")
        self.core.reset_envs(range(self.num_envs), self.np_random, problems)
        return self.core.observe(self.np_random), {}

    def step(
        self, actions: NDArray[np.float32]
    ) -> tuple[dict[str, NDArray[np.float32]], Array, NDArray[np.bool_], NDArray[np.bool_], dict[str, Any]]:
        """Move every environment by its row of ``actions``; an environment whose episode
        ends starts the next one in the same call (see the class's description)."""
        reward, term, trunc, info = self.core.step(actions)
        done = term | trunc
        infos: dict[str, Any] = dict(info)
        if done.any():
            infos["final_obs"] = self.core.observe(self.np_random)
            infos["final_info"] = {k: v.copy() for k, v in info.items()}
            infos["_final"] = done.copy()
            self.core.reset_envs(np.flatnonzero(done).tolist(), self.np_random)
        return self.core.observe(self.np_random), reward, term, trunc, infos
