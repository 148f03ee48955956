"""The SAC + HER training loop over a batch of environments.

``E`` workspaces step together through the batched core; finished episodes enter the
replay buffer whole (for hindsight relabelling); the agent takes ``updates_per_step``
gradient steps per collected transition. Every ``eval_every`` transitions the deterministic
policy is rolled out on held-out (``val``) workspaces; the best and the last checkpoints
are kept in the run directory with ``metrics.csv`` and TensorBoard logs.
"""

from __future__ import annotations

import csv
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ..config import from_dict
from ..envs.core import BatchedCore, EnvConfig
from ..models.actor_critic import NetConfig
from ..models.checkpoint import load_checkpoint, save_checkpoint, to_dict
from ..models.encoders import EncoderConfig
from ..scenes.scenarios import make_scenario
from ..scenes.scene import Problem
from .curriculum import EpisodeSource, FailurePool
from .replay import EpisodeReplay
from .sac import SAC, SACConfig


@dataclass(frozen=True)
class TrainConfig:
    """Everything that defines a training run (saved with every checkpoint)."""

    env: str = "narrow2d"
    #: ``sphere3d`` or ``sshape`` in the 3D scenes; ``None`` takes the scenario's default
    robot: str | None = None
    observation: str = "surface-normals"
    n_points: int = 64
    #: environments stepping together
    num_envs: int = 16
    #: environment transitions to collect
    total_steps: int = 200_000
    #: transitions of uniform random actions before the policy acts
    warmup_steps: int = 1_000
    #: gradient steps per collected transition (the paper: 1)
    updates_per_step: float = 0.25
    #: environment transitions between two validations (and checkpoints)
    eval_every: int = 10_000
    #: validation problems (the ``val`` split)
    eval_episodes: int = 100
    #: stop early once the validation success reaches this
    target_success: float = 1.01
    #: seeds the problems, the networks and the validation set
    seed: int = 0
    #: ``cpu`` or ``cuda``
    device: str = "cpu"
    net: NetConfig = field(default_factory=lambda: NetConfig(EncoderConfig(width=64), head_width=64, critic_action="pooled", shared_encoder=True))
    sac: SACConfig = field(default_factory=SACConfig)
    #: a checkpoint whose actor initialises this run's actor (e.g. behavioural cloning)
    init_actor: str | None = None
    #: share of new training episodes that retry a problem the policy failed (see
    #: ``learning/curriculum.py``); 0 draws every episode fresh, as in the paper
    retry_failures: float = 0.0
    #: at every validation, the deterministic policy also attempts this many fresh training
    #: problems; the ones it fails enter the retry pool
    mine_episodes: int = 0
    #: problems kept for retrying
    pool_size: int = 2000
    #: retries of a problem after its last failure
    pool_retries: int = 4


@dataclass
class TrainResult:
    run_dir: Path
    best_success: float
    steps: int
    wall_time_s: float
    history: list[dict[str, float]]
    #: stopped by Ctrl-C (training on Ray workers), after a last validation and checkpoint
    interrupted: bool = False


class _Logger:
    def __init__(self, run_dir: Path) -> None:
        self.path = run_dir / "metrics.csv"
        self.rows: list[dict[str, float]] = []
        self.tb: Any = None
        try:
            from torch.utils.tensorboard import SummaryWriter

            self.tb = SummaryWriter(str(run_dir / "tb"))
        except Exception:  # tensorboard missing: CSV only
            self.tb = None

    def log(self, row: dict[str, float]) -> None:
        self.rows.append(row)
        old: list[dict[str, str]] = []
        keys = list(row)
        if self.path.exists():  # e.g. a run resumed into its own folder: keep its columns
            with self.path.open(newline="") as f:
                reader = csv.DictReader(f)
                header = list(reader.fieldnames or [])
                if set(keys) <= set(header):
                    keys = header
                else:  # new columns (an option turned on at resume): rewrite with all of them
                    old = list(reader)
                    keys = header + [k for k in keys if k not in header]
        rewrite = bool(old) or not self.path.exists()
        with self.path.open("w" if rewrite else "a", newline="") as f:
            w = csv.DictWriter(f, fieldnames=keys, extrasaction="ignore", restval="")
            if rewrite:
                w.writeheader()
                w.writerows(old)
            w.writerow(row)
        if self.tb is not None:
            for k, v in row.items():
                if k != "env_steps":
                    self.tb.add_scalar(k, v, int(row["env_steps"]))
            self.tb.flush()


def _checkpoint_payload(cfg: TrainConfig, agent: SAC, obs_shape: tuple[int, ...], robot_name: str, extra: dict[str, Any]) -> dict[str, Any]:
    return {
        "env": cfg.env,
        "robot": robot_name,
        "observation": cfg.observation,
        "n_points": cfg.n_points,
        "obs_shape": list(obs_shape),
        "net": to_dict(cfg.net),
        "train_config": to_dict(cfg),
        "actor": agent.policy_actor.state_dict(),
        **extra,
    }


def train(
    cfg: TrainConfig,
    run_dir: str | Path,
    progress: bool = True,
    resume: str | Path | None = None,
    on_eval: Callable[[dict[str, float]], None] | None = None,
    workers: int | None = None,
    address: str | None = None,
    sync_every: int | None = None,
) -> TrainResult:
    """Train a policy with SAC + HER; returns where the checkpoints are and the history.

    With ``workers > 1`` or a Ray cluster ``address``, Ray rollout workers step the
    ``num_envs`` environments (shared out among them) and this process learns from the
    episodes they send, broadcasting the actor every ``sync_every`` updates
    (``pointplan.distributed.rollouts``)."""
    from ..distributed import wants_ray

    remote = None
    if wants_ray(workers, address):
        if cfg.retry_failures > 0:
            raise ValueError("--retry-failures runs in one process for now: drop --workers/--address to use it")
        from ..distributed.rollouts import SYNC_EVERY, RayRollouts

        remote = RayRollouts(cfg, workers, address, sync_every or SYNC_EVERY)
    try:
        res = _train(cfg, run_dir, progress, resume, on_eval, remote)
        res.interrupted = bool(remote is not None and remote.interrupted)
        return res
    finally:
        if remote is not None:
            remote.close()


def _train(
    cfg: TrainConfig,
    run_dir: str | Path,
    progress: bool,
    resume: str | Path | None,
    on_eval: Callable[[dict[str, float]], None] | None,
    remote: Any,
) -> TrainResult:
    from ..planners.policy import rollout_batch

    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    scenario = make_scenario(cfg.env, robot=cfg.robot)
    robot = scenario.robot
    env_cfg = EnvConfig(observation=cfg.observation, n_points=cfg.n_points, split="train")
    core = BatchedCore(scenario, cfg.num_envs, env_cfg)
    obs_shape = tuple(core.observer.space.shape)
    rng = np.random.default_rng(cfg.seed)
    torch.manual_seed(cfg.seed)
    agent = SAC(robot, env_cfg, obs_shape, cfg.net, cfg.sac, cfg.device)
    steps, best, best_nodes, elapsed_before = 0, -1.0, float("inf"), 0.0
    if cfg.init_actor and resume is None:  # a resumed run has its own actor already
        init = load_checkpoint(cfg.init_actor, cfg.device)
        agent.actor.load_state_dict(init["actor"])
    if resume is not None:
        state = load_checkpoint(resume, cfg.device)
        agent.load_state_dict(state["trainer"]["agent"])
        steps = int(state["trainer"]["steps"])
        best = float(state["trainer"]["best"])
        best_nodes = float(state["trainer"].get("best_nodes", float("inf")))
        elapsed_before = float(state["trainer"]["wall_time_s"])
        rng.bit_generator.state = state["trainer"]["rng"]
        torch.set_rng_state(state["trainer"]["torch_rng"])
        before = from_dict(TrainConfig, state["train_config"])
        if before.sac.lr != cfg.sac.lr:
            agent.set_lr(cfg.sac.lr)
        if (before.eval_episodes, before.seed) != (cfg.eval_episodes, cfg.seed):
            best, best_nodes = -1.0, float("inf")  # another validation set: not comparable
    capacity = int(min(cfg.sac.buffer_size, max(cfg.total_steps, 10_000)))
    buffer = EpisodeReplay(capacity, obs_shape, robot.config_dim, robot.twist_dim)
    val_problems = scenario.problems("val", cfg.eval_episodes, seed=cfg.seed)
    logger = _Logger(run_dir)

    e, h = cfg.num_envs, core.horizon
    st = {
        "obs": np.zeros((e, h) + obs_shape, np.float32),
        "next_obs": np.zeros((e, h) + obs_shape, np.float32),
        "q": np.zeros((e, h, robot.config_dim)),
        "q_next": np.zeros((e, h, robot.config_dim)),
        "goal": np.zeros((e, h, robot.config_dim)),
        "action": np.zeros((e, h, robot.twist_dim), np.float32),
        "action_norm": np.zeros((e, h)),
        "collided": np.zeros((e, h), bool),
    }
    pool = FailurePool(cfg.pool_size, cfg.pool_retries) if (cfg.retry_failures > 0 or cfg.mine_episodes > 0) else None
    source = EpisodeSource(core, pool, cfg.retry_failures)
    obs: Any = None
    if remote is None:  # (rollout workers start their own environments)
        source.reset(range(e), rng)
        obs = core.observe(rng)["observation"]
    recent: list[float] = []
    credit, last_losses = 0.0, {}
    t_start = time.perf_counter()
    next_eval = (steps // cfg.eval_every + 1) * cfg.eval_every
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=cfg.total_steps, initial=steps, unit="step", dynamic_ncols=True)
    history: list[dict[str, float]] = []
    rows = np.arange(e)
    while steps < cfg.total_steps:
        stop_now = remote is not None and remote.interrupted
        if remote is not None:  # Ray rollout workers step the environments
            remote.sync(agent.actor, agent.updates)
            episodes, succ, collected = remote.next_chunk(random_actions=steps < cfg.warmup_steps and cfg.init_actor is None)
            for episode in episodes:
                buffer.add_episode(*episode)
            recent = (recent + succ)[-200:]
            steps += collected
        else:
            collected = e
            q, goal = core.q.copy(), core.goal.copy()
            if steps < cfg.warmup_steps and cfg.init_actor is None:
                actions = rng.uniform(-1.0, 1.0, (e, robot.twist_dim)).astype(np.float32)
            else:
                actions = agent.act(obs, q, goal)
            t_idx = core.t.copy()
            _, term, trunc, info = core.step(actions)
            next_obs = core.observe(rng)["observation"]
            for k, v in (("obs", obs), ("next_obs", next_obs), ("q", q), ("q_next", core.q), ("goal", goal), ("action", actions), ("action_norm", info["action_norm"]), ("collided", info["collided"])):
                st[k][rows, t_idx] = v
            done = term | trunc
            steps += e
            if done.any():
                for i in np.flatnonzero(done):
                    n = int(t_idx[i]) + 1
                    buffer.add_episode(*(st[k][i, :n] for k in ("obs", "next_obs", "q", "q_next", "goal", "action", "action_norm", "collided")))
                    if not source.is_retry(i):  # the success rate of fresh problems only
                        recent.append(float(term[i]))
                    source.ended(i, bool(term[i]))
                recent = recent[-200:]
                source.reset(np.flatnonzero(done).tolist(), rng)
                fresh = core.observe(rng)["observation"]
                next_obs = np.where(done.reshape((-1,) + (1,) * len(obs_shape)), fresh, next_obs)
            obs = next_obs
        if steps >= cfg.warmup_steps and len(buffer) >= cfg.sac.batch_size:
            credit += collected * cfg.updates_per_step
            while credit >= 1.0:
                last_losses = agent.update(buffer.sample(cfg.sac.batch_size, rng, cfg.sac.her_ratio))
                credit -= 1.0
        if bar is not None:
            bar.update(collected)
            if recent:
                bar.set_postfix(train_success=f"{np.mean(recent):.2f}", best_val=f"{max(best, 0):.3f}", updates=agent.updates)
        if steps >= next_eval or steps >= cfg.total_steps or stop_now:
            next_eval += cfg.eval_every
            agent.actor.eval()

            def validate(averaged: bool) -> list[Any]:
                return rollout_batch(lambda o, qq, g: agent.act(o, qq, g, deterministic=True, averaged=averaged), robot, env_cfg, val_problems, scenario.horizon, seed=cfg.seed)

            res = validate(averaged=True)
            raw: dict[str, float] = {}
            if agent.actor_avg is not None:  # the current actor too, for comparison
                raw["val_success_current"] = float(np.mean([r.success for r in validate(averaged=False)]))
            if pool is not None:
                if cfg.mine_episodes > 0:  # failures of the deterministic policy on fresh problems
                    mined = []
                    for _ in range(cfg.mine_episodes):
                        scene = scenario.scene("train", int(rng.integers(0, 2**31 - 1)))
                        mined.append(Problem(scene, *scenario.sample_problem(scene, rng)))
                    mres = rollout_batch(lambda o, qq, g: agent.act(o, qq, g, deterministic=True, averaged=True), robot, env_cfg, mined, scenario.horizon, seed=steps)
                    for p, r in zip(mined, mres, strict=True):
                        if not r.success:
                            pool.failed(p)
                    raw["mine_success"] = float(np.mean([r.success for r in mres]))
                raw["pool_size"] = float(len(pool))
                raw["retry_share"] = source.retry_share
            agent.actor.train()
            val = float(np.mean([r.success for r in res]))
            nodes_all = float(np.mean([r.nodes for r in res]))
            # the best checkpoint: highest validation success, then fewest steps
            improved = val > best or (val == best and nodes_all < best_nodes)
            wall = elapsed_before + time.perf_counter() - t_start
            row = {
                "env_steps": float(steps),
                "updates": float(agent.updates),
                "wall_time_s": wall,
                "val_success": val,
                "train_success": float(np.mean(recent)) if recent else 0.0,
                "val_nodes": float(np.mean([r.nodes for r in res if r.success])) if any(r.success for r in res) else 0.0,
                **raw,
                **{k: float(v) for k, v in last_losses.items()},
            }
            history.append(row)
            logger.log(row)
            if on_eval is not None:
                on_eval(row)
            trainer_state = {
                "agent": agent.state_dict(),
                "steps": steps,
                "best": max(best, val),
                "best_nodes": nodes_all if improved else best_nodes,
                "wall_time_s": wall,
                "rng": rng.bit_generator.state,
                "torch_rng": torch.get_rng_state(),
            }
            extra = {"env_steps": steps, "val_success": val, "wall_time_s": wall, "horizon": core.horizon}
            save_checkpoint(run_dir / "last.pt", {**_checkpoint_payload(cfg, agent, obs_shape, robot.name, extra), "trainer": trainer_state})
            if improved:
                best, best_nodes = val, nodes_all
                save_checkpoint(run_dir / "best.pt", _checkpoint_payload(cfg, agent, obs_shape, robot.name, extra))
            if bar is not None:
                bar.write(f"step {steps}: val success {val:.3f} (best {best:.3f}), {wall:.0f} s")
            if val >= cfg.target_success or stop_now:
                break
    if bar is not None:
        bar.close()
    wall = elapsed_before + time.perf_counter() - t_start
    return TrainResult(run_dir=run_dir, best_success=best, steps=steps, wall_time_s=wall, history=history)

