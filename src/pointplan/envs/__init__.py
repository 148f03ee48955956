"""Gymnasium environments: ``pointplan/Narrow2D-v0`` and the batched vector env."""

from __future__ import annotations

from typing import Any

import gymnasium as gym

from .core import BatchedCore, EnvConfig, q_free
from .planning_env import PlanningEnv, PlanningVectorEnv, set_renderer

#: scenario name -> Gymnasium id. Settings are keyword arguments of ``gymnasium.make``:
#: ``robot`` (3D ids: ``sphere3d`` or ``sshape``), and the fields of :class:`EnvConfig`
#: (``observation``, ``n_points``, ``split``, ``horizon``, ...).
ENV_IDS = {
    "narrow2d": "pointplan/Narrow2D-v0",
    "boxes3d": "pointplan/Boxes3D-v0",
    "synthetic3d": "pointplan/Synthetic3D-v0",
    "ycb3d": "pointplan/YCB3D-v0",
    "dynamic3d": "pointplan/Dynamic3D-v0",
    "slot": "pointplan/Slot-v0",
    "slotmoving": "pointplan/SlotMoving-v0",
    "slotwide": "pointplan/SlotWide-v0",
    "slotclassic": "pointplan/SlotClassic-v0",
    "qureshi3d": "pointplan/Qureshi3D-v0",
    "cluttered3d": "pointplan/Cluttered3D-v0",
}


def make_env(scenario: str, **kwargs: Any) -> PlanningEnv:
    """The single environment of a scenario (Gymnasium entry point)."""
    return PlanningEnv(scenario, **kwargs)


def make_vector_env(scenario: str, num_envs: int = 16, **kwargs: Any) -> PlanningVectorEnv:
    """The batched vector environment of a scenario (Gymnasium vector entry point)."""
    return PlanningVectorEnv(scenario, num_envs=num_envs, **kwargs)


def register_envs() -> None:
    """Register the package's ids with Gymnasium (done on import of ``pointplan``)."""
    from functools import partial

    for name, env_id in ENV_IDS.items():
        if env_id in gym.registry:
            continue
        gym.register(
            id=env_id,
            entry_point=partial(make_env, name),  # type: ignore[arg-type]
            vector_entry_point=partial(make_vector_env, name),  # type: ignore[arg-type]
            max_episode_steps=None,
        )


__all__ = [
    "ENV_IDS",
    "BatchedCore",
    "EnvConfig",
    "PlanningEnv",
    "PlanningVectorEnv",
    "make_env",
    "make_vector_env",
    "q_free",
    "register_envs",
    "set_renderer",
]
