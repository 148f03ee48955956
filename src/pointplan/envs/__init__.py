"""Gymnasium environments: ``pointplan/Narrow2D-v0`` and the batched vector env."""

from __future__ import annotations

from typing import Any

import gymnasium as gym

from .core import BatchedCore, EnvConfig, q_free
from .planning_env import PlanningEnv, PlanningVectorEnv

ENV_IDS = {"narrow2d": "pointplan/Narrow2D-v0"}


def make_narrow2d(**kwargs: Any) -> PlanningEnv:
    return PlanningEnv("narrow2d", **kwargs)


def make_narrow2d_vector(num_envs: int = 16, **kwargs: Any) -> PlanningVectorEnv:
    return PlanningVectorEnv("narrow2d", num_envs=num_envs, **kwargs)


def register_envs() -> None:
    """Register the package's ids with Gymnasium (done on import of ``pointplan``)."""
    if "pointplan/Narrow2D-v0" not in gym.registry:
        gym.register(
            id="pointplan/Narrow2D-v0",
            entry_point="pointplan.envs:make_narrow2d",
            vector_entry_point="pointplan.envs:make_narrow2d_vector",
            max_episode_steps=None,
        )


__all__ = ["BatchedCore", "EnvConfig", "PlanningEnv", "PlanningVectorEnv", "q_free", "register_envs", "ENV_IDS"]
