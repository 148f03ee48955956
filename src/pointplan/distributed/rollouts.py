"""Rollout workers for SAC training on Ray.

Each worker (a Ray actor) steps its share of the training environments through its own
:class:`~pointplan.envs.core.BatchedCore` with a copy of the actor, and sends the episodes
that finished back to the learner (the process running :func:`pointplan.learning.train.train`,
on a GPU if it has one). The learner keeps the replay buffer and hindsight relabelling,
takes ``updates_per_step`` gradient steps per transition it receives (as the serial
trainer does), and sends the actor's weights to the workers every ``sync_every`` updates.

A worker runs one *chunk* (``steps_per_call`` lockstep steps of its environments) per
call; the learner asks it for the next chunk as soon as one arrives and learns from that
one meanwhile, so collection and learning overlap, with the workers at most one chunk
ahead. Each worker draws from its own random stream (seeded by the run's seed and the
worker's number), so runs with workers are reproducible in their statistics, not step for
step like the serial trainer: which worker's chunk arrives first depends on timing.

A worker that dies is replaced (a new number, so a new stream) and asked again; the
episodes it had under way are lost, which only costs time.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from ..learning.train import TrainConfig

#: lockstep steps per call of a worker (each of its environments takes this many)
STEPS_PER_CALL = 10
#: learner updates between two weight broadcasts
SYNC_EVERY = 16


class RolloutWorker:
    """Environments of one worker and a copy of the actor (runs as a Ray actor)."""

    def __init__(self, cfg: dict[str, Any], index: int, num_envs: int) -> None:
        import torch

        from ..config import from_dict
        from ..envs.core import BatchedCore, EnvConfig
        from ..learning.curriculum import EpisodeSource
        from ..learning.replay import EpisodeStaging
        from ..learning.train import TrainConfig
        from ..models.actor_critic import Actor
        from ..models.inputs import goal_dim
        from ..scenes.scenarios import make_scenario

        torch.set_num_threads(1)
        self.cfg = c = from_dict(TrainConfig, cfg)
        scenario = make_scenario(c.env, robot=c.robot)
        self.robot = scenario.robot
        self.core = BatchedCore(
            scenario,
            num_envs,
            EnvConfig(observation=c.observation, n_points=c.n_points, split="train", action_cost=c.action_cost),
        )
        self.rng = np.random.default_rng(np.random.SeedSequence([c.seed, 0x524159, index]))
        torch.manual_seed(int(self.rng.integers(2**31)))
        obs_shape = tuple(self.core.observer.space.shape)
        self.actor = Actor(obs_shape, goal_dim(self.robot), self.robot.twist_dim, c.net).eval()
        self.weights_version = -1
        self.source = EpisodeSource(self.core, None, 0.0)
        self.source.reset(range(num_envs), self.rng)
        self.obs = self.core.observe(self.rng)["observation"]
        self.staging = EpisodeStaging(
            num_envs, self.core.horizon, obs_shape, self.robot.config_dim, self.robot.twist_dim
        )

    def _act(self, obs: np.ndarray, q: np.ndarray, goal: np.ndarray) -> np.ndarray:
        import torch

        from ..models.inputs import goal_input, obs_input

        with torch.no_grad():
            o = torch.as_tensor(np.asarray(obs_input(self.robot, obs), np.float32))
            g = torch.as_tensor(np.asarray(goal_input(self.robot, q, goal), np.float32))
            return self.actor.sample(o, g)[0].numpy()

    def collect(
        self, weights: Any, version: int, n_steps: int, random_actions: bool
    ) -> tuple[list[tuple[np.ndarray, ...]], list[float], int]:
        """Step every environment ``n_steps`` times (uniform random actions, or the actor
        with ``weights``, loaded if ``version`` is new); returns the episodes that ended
        (arrays in the order of ``EpisodeReplay.add_episode``), their success, and the
        transitions collected."""
        if version != self.weights_version and weights is not None:
            self.actor.load_state_dict(weights)
            self.weights_version = version
        core, rng = self.core, self.rng
        e = core.num_envs
        episodes: list[tuple[np.ndarray, ...]] = []
        success: list[float] = []
        obs = self.obs
        for _ in range(n_steps):
            q, goal = core.q.copy(), core.goal.copy()
            if random_actions:
                actions = rng.uniform(-1.0, 1.0, (e, self.robot.twist_dim)).astype(np.float32)
            else:
                actions = self._act(obs, q, goal)
            t_idx = core.t.copy()
            _, term, trunc, info = core.step(actions)
            next_obs = core.observe(rng)["observation"]
            done = term | trunc
            ended = self.staging.add(
                t_idx,
                done,
                obs=obs,
                next_obs=next_obs,
                q=q,
                q_next=core.q,
                goal=goal,
                action=actions,
                action_norm=info["action_norm"],
                collided=info["collided"],
            )
            episodes += [tuple(a.copy() for a in episode) for episode in ended]
            if done.any():
                success += [float(term[i]) for i in np.flatnonzero(done)]
                self.source.reset(np.flatnonzero(done).tolist(), rng)
                fresh = core.observe(rng)["observation"]
                next_obs = np.where(done.reshape((-1,) + (1,) * (next_obs.ndim - 1)), fresh, next_obs)
            obs = next_obs
        self.obs = obs
        return episodes, success, n_steps * e


class RayRollouts:
    """The learner's side: starts the workers, hands out chunks, gathers episodes.

    ``num_envs`` environments in all are shared out among ``workers`` workers (each gets at
    least one). Ctrl-C (SIGINT) asks the run to stop: :attr:`interrupted` becomes true, the
    trainer validates and saves its checkpoints one last time, and :meth:`close` stops the
    workers; a second Ctrl-C interrupts at once."""

    def __init__(
        self,
        cfg: TrainConfig,
        workers: int | None,
        address: str | None,
        sync_every: int = SYNC_EVERY,
        steps_per_call: int = STEPS_PER_CALL,
    ) -> None:
        from ..models.checkpoint import to_dict
        from .tasks import cluster_cpus, connect

        ray = connect(workers, address)
        self.ray = ray
        n = int(workers) if workers else max(1, cluster_cpus() - 1)
        self.cfg_dict = to_dict(cfg)
        sizes = [len(s) for s in np.array_split(np.arange(max(cfg.num_envs, n)), n)]
        self.sizes = sizes
        self.remote_cls = ray.remote(num_cpus=1)(RolloutWorker)
        self.workers: list[Any] = []
        self.next_index = 0
        for size in sizes:
            self.workers.append(self._start(size))
        self.sync_every = int(sync_every)
        self.steps_per_call = int(steps_per_call)
        self.version = -1
        self.weights_ref: Any = None
        self.last_sync_updates = -(10**9)
        self.inflight: dict[Any, int] = {}
        self.replaced = 0
        self.interrupted = False
        self._old_handler: Any = None
        if threading.current_thread() is threading.main_thread():
            self._old_handler = signal.signal(signal.SIGINT, self._on_sigint)

    def _start(self, size: int) -> Any:
        w = self.remote_cls.remote(self.cfg_dict, self.next_index, size)
        self.next_index += 1
        return w

    def _on_sigint(self, signum: int, frame: Any) -> None:
        import sys

        if self.interrupted:
            raise KeyboardInterrupt
        self.interrupted = True
        print(
            "\ninterrupted: stopping the rollout workers after a last validation and checkpoint (Ctrl-C again to stop now)",
            file=sys.stderr,
        )

    def sync(self, actor: Any, updates: int) -> None:
        """Publish ``actor``'s weights if ``sync_every`` updates have passed since the last."""
        if updates - self.last_sync_updates >= self.sync_every or self.weights_ref is None:
            state = {k: v.detach().cpu() for k, v in actor.state_dict().items()}
            self.weights_ref = self.ray.put(state)
            self.version += 1
            self.last_sync_updates = updates

    def _submit(self, k: int, random_actions: bool) -> None:
        ref = self.workers[k].collect.remote(self.weights_ref, self.version, self.steps_per_call, random_actions)
        self.inflight[ref] = k

    def next_chunk(self, random_actions: bool) -> tuple[list[tuple[np.ndarray, ...]], list[float], int]:
        """Episodes, their success and the transitions of the next chunk to arrive; the
        worker that sent it is asked for its next chunk at once (with the latest weights)."""
        ray = self.ray
        for k in range(len(self.workers)):
            if k not in self.inflight.values():
                self._submit(k, random_actions)
        while True:
            done, _ = ray.wait(list(self.inflight), num_returns=1)
            ref = done[0]
            k = self.inflight.pop(ref)
            try:
                out = ray.get(ref)
            except (ray.exceptions.RayActorError, ray.exceptions.WorkerCrashedError):
                # the worker died: start another in its place and ask it instead
                self.replaced += 1
                self.workers[k] = self._start(self.sizes[k])
                self._submit(k, random_actions)
                continue
            self._submit(k, random_actions)
            return out

    def close(self) -> None:
        """Stop the workers (the learner keeps what it has)."""
        self.inflight.clear()
        for w in self.workers:
            with contextlib.suppress(Exception):
                self.ray.kill(w)
        self.workers = []
        if self._old_handler is not None:
            signal.signal(signal.SIGINT, self._old_handler)
            self._old_handler = None


def ray_rollouts(
    workers: int | None, address: str | None, sync_every: int | None = None
) -> Callable[[TrainConfig], RayRollouts]:
    """The ``rollouts`` factory :func:`pointplan.learning.train.train` takes: Ray rollout
    workers on this machine (``workers``) or a cluster (``address``)."""

    def start(cfg: TrainConfig) -> RayRollouts:
        return RayRollouts(cfg, workers, address, sync_every or SYNC_EVERY)

    return start
