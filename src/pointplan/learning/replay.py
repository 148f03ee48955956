"""Episode-aware replay buffer with hindsight goal relabelling ("future" strategy).

Transitions are stored whole episodes at a time (an episode enters the buffer when it
ends), so every transition knows where its episode ends. With :meth:`EpisodeReplay.track`
the buffer also stages the episodes ``E`` environments are in: :meth:`add_steps` takes one
transition per environment and adds each episode as it ends. A relabelled sample replaces the
goal with the configuration reached at a later step of the same episode; its reward is
recomputed from the stored action norm and collision flag, exactly as the environment
would have computed it (see ``BatchedCore.reward``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray


@dataclass
class Batch:
    """A sampled batch (numpy). ``goal`` is the (possibly relabelled) goal configuration."""

    obs: NDArray[np.float32]
    next_obs: NDArray[np.float32]
    q: NDArray[np.float64]
    q_next: NDArray[np.float64]
    goal: NDArray[np.float64]
    action: NDArray[np.float32]
    action_norm: NDArray[np.float64]
    collided: NDArray[np.bool_]
    relabelled: NDArray[np.bool_]


#: the stored fields of a transition, in :meth:`EpisodeReplay.add_episode`'s order
_FIELDS = ("obs", "next_obs", "q", "q_next", "goal", "action", "action_norm", "collided")


class EpisodeStaging:
    """The running episodes of ``E`` environments: one transition per environment at a
    time; each episode is handed out whole when it ends."""

    def __init__(
        self,
        num_envs: int,
        horizon: int,
        obs_shape: tuple[int, ...],
        config_dim: int,
        action_dim: int,
        obs_dtype: type = np.float32,
    ) -> None:
        e, h = int(num_envs), int(horizon)
        self.arrays: dict[str, np.ndarray] = {
            "obs": np.zeros((e, h) + tuple(obs_shape), obs_dtype),
            "next_obs": np.zeros((e, h) + tuple(obs_shape), obs_dtype),
            "q": np.zeros((e, h, config_dim)),
            "q_next": np.zeros((e, h, config_dim)),
            "goal": np.zeros((e, h, config_dim)),
            "action": np.zeros((e, h, action_dim), np.float32),
            "action_norm": np.zeros((e, h)),
            "collided": np.zeros((e, h), bool),
        }

    def add(self, t: np.ndarray, done: np.ndarray, **transition: np.ndarray) -> list[tuple[np.ndarray, ...]]:
        """One transition per environment, at step ``t[i]`` of its episode (the fields of
        :meth:`EpisodeReplay.add_episode` as keywords); returns the episodes that are
        ``done`` (views of the staging arrays, valid until the next call), in environment
        order, as :meth:`EpisodeReplay.add_episode`'s arguments."""
        rows = np.arange(len(t))
        for k in _FIELDS:
            self.arrays[k][rows, t] = transition[k]
        return [tuple(self.arrays[k][i, : int(t[i]) + 1] for k in _FIELDS) for i in np.flatnonzero(done)]


class EpisodeReplay:
    """A ring buffer of ``capacity`` transitions.

    Memory: observations and next observations are kept in ``obs_dtype``, float32 for
    point sets (``2 * capacity * obs_size * 4`` bytes: 2.0 GB for 1e6 transitions of 64
    points x 4 features), bytes for occupancy images (their observer's
    ``storage_dtype``: 8.2 GB for 1e6 transitions of 64 x 64 images, not 33).
    """

    def __init__(
        self, capacity: int, obs_shape: tuple[int, ...], config_dim: int, action_dim: int, obs_dtype: type = np.float32
    ) -> None:
        self.capacity = int(capacity)
        c = self.capacity
        self.obs: np.ndarray = np.zeros((c,) + tuple(obs_shape), obs_dtype)
        self.next_obs: np.ndarray = np.zeros((c,) + tuple(obs_shape), obs_dtype)
        self.q = np.zeros((c, config_dim))
        self.q_next = np.zeros((c, config_dim))
        self.goal = np.zeros((c, config_dim))
        self.action = np.zeros((c, action_dim), np.float32)
        self.action_norm = np.zeros(c)
        self.collided = np.zeros(c, bool)
        self.episode = np.full(c, -1, np.int64)
        self.step = np.zeros(c, np.int64)
        self.length = np.zeros(c, np.int64)
        self.pos = 0
        self.size = 0
        self.n_episodes = 0
        self._staging: EpisodeStaging | None = None

    def track(self, num_envs: int, horizon: int) -> None:
        """Stage the running episodes of ``num_envs`` environments of at most ``horizon`` steps."""
        self._staging = EpisodeStaging(
            num_envs, horizon, self.obs.shape[1:], self.q.shape[1], self.action.shape[1], self.obs.dtype.type
        )

    def add_steps(self, t: np.ndarray, done: np.ndarray, **transition: np.ndarray) -> None:
        """One transition per tracked environment, at step ``t[i]`` of its episode (the
        fields of :meth:`add_episode` as keywords); the episodes that are ``done`` enter
        the buffer, in environment order."""
        if self._staging is None:
            raise RuntimeError("call track(num_envs, horizon) first")
        for episode in self._staging.add(t, done, **transition):
            self.add_episode(*episode)

    def __len__(self) -> int:
        return self.size

    def add_episode(
        self,
        obs: np.ndarray,
        next_obs: np.ndarray,
        q: np.ndarray,
        q_next: np.ndarray,
        goal: np.ndarray,
        action: np.ndarray,
        action_norm: np.ndarray,
        collided: np.ndarray,
    ) -> None:
        """Store one finished episode of ``T`` transitions (arrays with leading ``T``)."""
        t = len(q)
        if t == 0:
            return
        if t > self.capacity:
            raise ValueError("episode longer than the buffer")
        idx = (self.pos + np.arange(t)) % self.capacity
        self.obs[idx] = obs
        self.next_obs[idx] = next_obs
        self.q[idx] = q
        self.q_next[idx] = q_next
        self.goal[idx] = goal
        self.action[idx] = action
        self.action_norm[idx] = action_norm
        self.collided[idx] = collided
        self.episode[idx] = self.n_episodes
        self.step[idx] = np.arange(t)
        self.length[idx] = t
        self.n_episodes += 1
        self.pos = int((self.pos + t) % self.capacity)
        self.size = min(self.size + t, self.capacity)

    def sample(self, batch_size: int, rng: np.random.Generator, her_ratio: float = 0.8) -> Batch:
        """A uniform batch; a fraction ``her_ratio`` gets a future goal of its episode."""
        if self.size == 0:
            raise ValueError("the buffer is empty")
        i = rng.integers(0, self.size, batch_size)
        goal = self.goal[i].copy()
        relabel = rng.random(batch_size) < her_ratio
        # future step t' in [t, T-1]; its reached configuration q_next[t'] is the new goal
        remaining = self.length[i] - self.step[i]
        offset = (rng.random(batch_size) * remaining).astype(np.int64)
        j = (i + offset) % self.capacity
        valid = relabel & (self.episode[j] == self.episode[i])  # not overwritten meanwhile
        goal[valid] = self.q_next[j[valid]]
        return Batch(
            obs=self.obs[i],
            next_obs=self.next_obs[i],
            q=self.q[i],
            q_next=self.q_next[i],
            goal=goal,
            action=self.action[i],
            action_norm=self.action_norm[i],
            collided=self.collided[i],
            relabelled=valid,
        )
