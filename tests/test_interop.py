"""The environments fit the ecosystem: stable-baselines3's SAC with its HER buffer runs."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import pointplan  # noqa: F401

sb3 = pytest.importorskip("stable_baselines3")


def test_sb3_sac_with_her_runs_on_narrow2d() -> None:
    from stable_baselines3 import SAC
    from stable_baselines3.her.her_replay_buffer import HerReplayBuffer

    env = gym.make("pointplan/Narrow2D-v0", observation="surface-normals", n_points=16)
    model = SAC(
        "MultiInputPolicy",
        env,
        replay_buffer_class=HerReplayBuffer,
        replay_buffer_kwargs={"n_sampled_goal": 4, "goal_selection_strategy": "future", "copy_info_dict": True},
        learning_starts=120,
        batch_size=32,
        policy_kwargs={"net_arch": [32, 32]},
        seed=0,
        device="cpu",
    )
    model.learn(total_timesteps=300)
    assert model.num_timesteps == 300
    buf = model.replay_buffer
    assert buf.size() > 0
    # HER relabelling went through the env's compute_reward: sampled rewards are the env's
    batch = buf.sample(64)
    rewards = batch.rewards.numpy().ravel()
    assert np.all((rewards <= 20.0) & (rewards >= -4.0 - np.sqrt(2) - 1e-6))
    obs, _ = env.reset(seed=1)
    action, _ = model.predict(obs, deterministic=True)
    assert env.action_space.contains(action.astype(np.float32))
