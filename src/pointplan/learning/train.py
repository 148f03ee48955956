"""The SAC + HER training loop over a batch of environments.

``E`` workspaces step together through the batched core; finished episodes enter the
replay buffer whole (for hindsight relabelling); the agent takes ``updates_per_step``
gradient steps per collected transition. Every ``eval_every`` transitions the deterministic
policy is rolled out on held-out (``val``) workspaces; the best and the last checkpoints
are kept in the run directory with ``metrics.csv`` and TensorBoard logs.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import torch

from ..config import from_dict
from ..envs.core import BatchedCore, EnvConfig
from ..models.actor_critic import NetConfig
from ..models.checkpoint import CheckpointError, load_checkpoint, to_dict
from ..models.encoders import EncoderConfig
from ..parallel import RolloutSource, backend, wants_workers
from ..scenes.scenarios import Scenario, make_scenario
from ..scenes.scene import Problem
from .curriculum import EpisodeSource, FailurePool
from .memory import keep_freed_memory
from .replay import Batch, EpisodeReplay
from .rundir import MetricsLog, RunDir, best_note, best_or_none
from .sac import SAC, DemoBatch, SACConfig

if TYPE_CHECKING:
    from ..planners.base import PlanResult

#: the metrics log of a run folder (``metrics.csv`` and TensorBoard)
_Logger = MetricsLog


@dataclass(frozen=True)
class TrainConfig:
    """Everything that defines a training run (saved with every checkpoint)."""

    env: str = "narrow2d"
    #: ``sphere3d`` or ``sshape`` in the 3D scenes; ``None`` takes the scenario's default
    robot: str | None = None
    observation: str = "surface-normals"
    n_points: int = 64
    #: environments stepping together
    num_envs: int = field(default=16, metadata={"min": 1})
    #: environment transitions to collect
    total_steps: int = field(default=200_000, metadata={"min": 1})
    #: transitions of uniform random actions before the policy acts
    warmup_steps: int = 1_000
    #: gradient steps per collected transition (the paper: 1)
    updates_per_step: float = 0.25
    #: environment transitions between two validations (and checkpoints)
    eval_every: int = field(default=10_000, metadata={"min": 1})
    #: validation problems (the ``val`` split)
    eval_episodes: int = field(default=100, metadata={"min": 1})
    #: stop early once the validation success reaches this
    target_success: float = 1.01
    #: seeds the problems, the networks and the validation set
    seed: int = 0
    #: ``cpu`` or ``cuda``
    device: str = "cpu"
    net: NetConfig = field(
        default_factory=lambda: NetConfig(
            EncoderConfig(width=64), head_width=64, critic_action="pooled", shared_encoder=True
        )
    )
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
    pool_size: int = field(default=2000, metadata={"min": 1})
    #: retries of a problem after its last failure
    pool_retries: int = 4
    #: weight of the action's norm in the reward (the paper: 1; see ``EnvConfig.action_cost``)
    action_cost: float = field(default=1.0, metadata={"min": 0})
    #: a demonstrations file (written by ``pointplan bc --demos``) for the actor's cloning
    #: term (``--bc-weight``)
    demos: str | None = None
    #: gradient steps between two fresh draws of the demonstrations' observation subsets
    demo_refresh: int = field(default=20_000, metadata={"min": 1})
    #: share of every gradient step's batch drawn from the demonstrations (``--demos``)
    #: replayed as episodes, in a buffer of their own that is never overwritten (as in
    #: Nair et al. 2018); 0 learns from the agent's own experience only
    demo_share: float = field(default=0.0, metadata={"min": 0})


@dataclass
class TrainResult:
    """What :func:`train` returns: the run folder (checkpoints, metrics), the best
    validation success, the environment steps taken, the wall time and the validation
    history."""

    run_dir: Path
    #: the best validation success, None before the first validation
    best_success: float | None
    steps: int
    wall_time_s: float
    history: list[dict[str, float]]
    #: stopped by Ctrl-C: in one process after saving the trainer state at the current step
    #: to ``last.pt``; with Ray workers after a last validation and checkpoint
    interrupted: bool = False


def _checkpoint_payload(
    cfg: TrainConfig, agent: SAC, obs_shape: tuple[int, ...], robot_name: str, extra: dict[str, Any]
) -> dict[str, Any]:
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
    rollouts: Callable[[TrainConfig], RolloutSource] | None = None,
) -> TrainResult:
    """Train a policy with SAC + HER; returns where the checkpoints are and the history.

    With ``rollouts`` (a factory of rollout sources, e.g.
    ``pointplan.distributed.rollouts.ray_rollouts(workers, address)``), or ``workers > 1`` or
    a Ray cluster ``address`` (the default back end's rollout workers, which broadcast the
    actor every ``sync_every`` updates), the ``num_envs`` environments are stepped elsewhere
    and this process learns from the episodes they send."""
    folder = RunDir(run_dir, "pointplan train")  # before any work: a folder that cannot be used is an error now
    if rollouts is None and wants_workers(workers, address):
        rollouts = backend().rollouts(workers, address, sync_every)
    remote = None
    if rollouts is not None:
        if cfg.retry_failures > 0:
            raise ValueError("--retry-failures runs in one process for now: drop --workers/--address to use it")
        remote = rollouts(cfg)
    try:
        res = _train(cfg, folder, progress, resume, on_eval, remote)
        res.interrupted = res.interrupted or bool(remote is not None and remote.interrupted)
        return res
    finally:
        if remote is not None:
            remote.close()


@dataclass
class _Run:
    """What the training loop reads and updates: the pieces of the run and its counters."""

    cfg: TrainConfig
    folder: RunDir
    scenario: Scenario
    core: BatchedCore
    env_cfg: EnvConfig
    obs_shape: tuple[int, ...]
    rng: np.random.Generator
    agent: SAC
    steps: int = 0
    best: float = -1.0
    best_nodes: float = float("inf")
    elapsed_before: float = 0.0
    buffer: Any = None
    val_problems: list[Problem] = field(default_factory=list)
    logger: Any = None
    pool: FailurePool | None = None
    source: Any = None
    obs: Any = None
    recent: list[float] = field(default_factory=list)
    credit: float = 0.0
    last_losses: dict[str, float] = field(default_factory=dict)
    history: list[dict[str, float]] = field(default_factory=list)
    t_start: float = 0.0
    next_eval: int = 0
    demos: Any = None
    demo_obs: Any = None
    demo_goal: Any = None
    demo_action: Any = None
    demo_drawn_at: int = -1
    demo_buffer: Any = None

    @property
    def run_dir(self) -> Path:
        return self.folder.path

    @property
    def wall(self) -> float:
        return self.elapsed_before + time.perf_counter() - self.t_start

    @property
    def warming_up(self) -> bool:
        return self.steps < self.cfg.warmup_steps and self.cfg.init_actor is None


def _start(cfg: TrainConfig, folder: RunDir, resume: str | Path | None, remote: RolloutSource | None) -> _Run:
    """Build the environments, the agent and the buffer; restore ``resume``'s trainer state."""
    scenario = make_scenario(cfg.env, robot=cfg.robot)
    env_cfg = EnvConfig(observation=cfg.observation, n_points=cfg.n_points, split="train", action_cost=cfg.action_cost)
    core = BatchedCore(scenario, cfg.num_envs, env_cfg)
    obs_shape = tuple(core.observer.space.shape)
    if cfg.observation == "image":  # the CNN's activations: large blocks freed and taken every update
        keep_freed_memory()
    rng = np.random.default_rng(cfg.seed)
    torch.manual_seed(cfg.seed)
    agent = SAC(scenario.robot, env_cfg, obs_shape, cfg.net, cfg.sac, cfg.device)
    run = _Run(cfg, folder, scenario, core, env_cfg, obs_shape, rng, agent)
    if cfg.init_actor and resume is None:  # a resumed run has its own actor already
        agent.load_actor(load_checkpoint(cfg.init_actor, cfg.device)["actor"])
    if resume is not None:
        _resume(run, resume)
        if run.steps >= cfg.total_steps:
            raise ValueError(
                f"{resume}: the run has done {run.steps} steps already; set total_steps above that to continue it"
            )
    robot = scenario.robot
    run.buffer = EpisodeReplay(
        int(min(cfg.sac.buffer_size, max(cfg.total_steps, 10_000))),
        obs_shape,
        robot.config_dim,
        robot.twist_dim,
        core.observer.storage_dtype,
    )
    run.buffer.track(cfg.num_envs, core.horizon)
    run.val_problems = scenario.problems("val", cfg.eval_episodes, seed=cfg.seed)
    run.logger = folder.metrics
    if resume is not None:  # rows logged after that state was saved are logged again
        run.logger.drop_after(run.steps)
    if cfg.retry_failures > 0 or cfg.mine_episodes > 0:
        run.pool = FailurePool(cfg.pool_size, cfg.pool_retries)
    run.source = EpisodeSource(core, run.pool, cfg.retry_failures)
    if not 0 <= cfg.demo_share < 1:
        raise ValueError(f"demo_share must be in [0, 1), not {cfg.demo_share}")
    if cfg.sac.bc_weight > 0 or cfg.demo_share > 0:
        _load_demos(run)
    if cfg.demo_share > 0:
        run.demo_buffer = _demo_replay(run)
    if remote is None:  # (rollout workers start their own environments)
        run.source.reset(range(cfg.num_envs), rng)
        run.obs = core.observe(rng)["observation"]
    run.t_start = time.perf_counter()
    run.next_eval = (run.steps // cfg.eval_every + 1) * cfg.eval_every
    return run


def _load_demos(run: _Run) -> None:
    """The demonstrations of ``cfg.demos`` for the actor's cloning term."""
    from ..models.inputs import goal_input
    from .bc import load_demos

    cfg, robot = run.cfg, run.scenario.robot
    if not cfg.demos:
        raise ValueError(
            "--bc-weight and --demo-share need demonstrations: give --demos FILE (written by `pointplan bc --demos FILE`)"
        )
    if not Path(cfg.demos).exists():
        raise FileNotFoundError(
            f"--demos {cfg.demos}: no such file (write one with `pointplan bc --demos {cfg.demos}`)"
        )
    run.demos = load_demos(cfg.demos, run.scenario)
    agent = run.agent
    run.demo_goal = agent.tensor(goal_input(robot, run.demos.q, run.demos.goal))
    run.demo_action = agent.tensor(run.demos.action)


def _demo_replay(run: _Run) -> EpisodeReplay:
    """The demonstrations as episodes in a buffer of their own (observations drawn once)."""
    from .bc import demo_episodes

    robot = run.scenario.robot
    episodes = demo_episodes(run.demos, robot, run.env_cfg, run.rng, run.core.horizon)
    buf = EpisodeReplay(
        sum(len(e[2]) for e in episodes),
        run.obs_shape,
        robot.config_dim,
        robot.twist_dim,
        run.core.observer.storage_dtype,
    )
    for episode in episodes:
        buf.add_episode(*episode)
    return buf


def _sample(run: _Run) -> Batch:
    """A training batch: ``demo_share`` of it from the demonstrations' buffer when kept."""
    cfg = run.cfg
    n = cfg.sac.batch_size
    if run.demo_buffer is None:
        return run.buffer.sample(n, run.rng, cfg.sac.her_ratio)
    k = int(round(cfg.demo_share * n))
    own = run.buffer.sample(n - k, run.rng, cfg.sac.her_ratio)
    demo = run.demo_buffer.sample(k, run.rng, cfg.sac.her_ratio)
    return Batch(
        **{f.name: np.concatenate([getattr(own, f.name), getattr(demo, f.name)]) for f in dataclasses.fields(Batch)}
    )


def _demo_batch(run: _Run) -> DemoBatch | None:
    """A batch of demonstration steps (observations drawn anew every ``demo_refresh``
    gradient steps)."""
    if run.demos is None:
        return None
    from .bc import observe_demos, stored_obs_tensor

    agent, cfg = run.agent, run.cfg
    if run.demo_obs is None or agent.updates - run.demo_drawn_at >= cfg.demo_refresh:
        robot = run.scenario.robot
        run.demo_obs = None  # (the old observations freed first)
        run.demo_obs = stored_obs_tensor(robot, observe_demos(run.demos, robot, run.env_cfg, run.rng), agent.device)
        run.demo_drawn_at = agent.updates
    idx = torch.as_tensor(run.rng.integers(0, len(run.demos), cfg.sac.batch_size), device=agent.device)
    return DemoBatch(run.demo_obs[idx].float(), run.demo_goal[idx], run.demo_action[idx])


def _resume(run: _Run, path: str | Path) -> None:
    """Continue from the trainer state in ``path`` (a run's ``last.pt``)."""
    cfg, agent = run.cfg, run.agent
    state = load_checkpoint(path, cfg.device)
    if "trainer" not in state:
        raise CheckpointError(
            f"{path}: holds a policy but no trainer state (best.pt and bc.pt do not); resume from the run's last.pt"
        )
    trainer = state["trainer"]
    agent.load_state_dict(trainer["agent"])
    run.steps = int(trainer["steps"])
    run.best = float(trainer["best"])
    run.best_nodes = float(trainer.get("best_nodes", float("inf")))
    run.elapsed_before = float(trainer["wall_time_s"])
    run.rng.bit_generator.state = trainer["rng"]
    torch.set_rng_state(trainer["torch_rng"])
    before = from_dict(TrainConfig, state["train_config"])
    if before.sac.lr != cfg.sac.lr:
        agent.set_lr(cfg.sac.lr)
    if (before.eval_episodes, before.seed) != (cfg.eval_episodes, cfg.seed):
        run.best, run.best_nodes = -1.0, float("inf")  # another validation set: not comparable


def _collect(run: _Run) -> int:
    """One step of every environment; finished episodes enter the buffer and restart."""
    core, rng, e = run.core, run.rng, run.cfg.num_envs
    q, goal = core.q.copy(), core.goal.copy()
    if run.warming_up:
        actions = rng.uniform(-1.0, 1.0, (e, core.robot.twist_dim)).astype(np.float32)
    else:
        actions = run.agent.act(run.obs, q, goal)
    t = core.t.copy()
    _, term, trunc, info = core.step(actions)
    next_obs = core.observe(rng)["observation"]
    done = term | trunc
    run.buffer.add_steps(
        t,
        done,
        obs=run.obs,
        next_obs=next_obs,
        q=q,
        q_next=core.q,
        goal=goal,
        action=actions,
        action_norm=info["action_norm"],
        collided=info["collided"],
    )
    run.steps += e
    if done.any():
        for i in np.flatnonzero(done):
            if not run.source.is_retry(i):  # the success rate of fresh problems only
                run.recent.append(float(term[i]))
            run.source.ended(i, bool(term[i]))
        run.recent = run.recent[-200:]
        run.source.reset(np.flatnonzero(done).tolist(), rng)
        fresh = core.observe(rng)["observation"]
        next_obs = np.where(done.reshape((-1,) + (1,) * len(run.obs_shape)), fresh, next_obs)
    run.obs = next_obs
    return e


def _collect_remote(run: _Run, remote: RolloutSource) -> int:
    """Episodes from the rollout workers (which step the environments)."""
    remote.sync(run.agent.actor, run.agent.updates)
    episodes, succ, collected = remote.next_chunk(random_actions=run.warming_up)
    for episode in episodes:
        run.buffer.add_episode(*episode)
    run.recent = (run.recent + succ)[-200:]
    run.steps += collected
    return int(collected)


def _learn(run: _Run, collected: int) -> None:
    """``updates_per_step`` gradient steps per collected transition (after the warm-up)."""
    cfg = run.cfg
    if run.steps >= cfg.warmup_steps and len(run.buffer) >= cfg.sac.batch_size:
        run.credit += collected * cfg.updates_per_step
        while run.credit >= 1.0:
            demo = _demo_batch(run) if run.agent.updates >= cfg.sac.actor_delay else None
            run.last_losses = run.agent.update(_sample(run), demo)
            run.credit -= 1.0


def _rollouts(run: _Run, problems: list[Problem], averaged: bool, seed: int) -> list[PlanResult]:
    """The deterministic policy on ``problems``."""
    from ..planners.rollout import rollout_batch

    agent = run.agent
    return rollout_batch(
        lambda o, q, g: agent.act(o, q, g, deterministic=True, averaged=averaged),
        run.scenario.robot,
        run.env_cfg,
        problems,
        run.scenario.horizon,
        seed=seed,
    )


def _mine_failures(run: _Run) -> dict[str, float]:
    """The deterministic policy on fresh training problems; its failures enter the retry pool."""
    cfg, pool, scenario = run.cfg, run.pool, run.scenario
    assert pool is not None
    raw: dict[str, float] = {}
    if cfg.mine_episodes > 0:
        mined = []
        for _ in range(cfg.mine_episodes):
            scene = scenario.scene("train", int(run.rng.integers(0, 2**31 - 1)))
            mined.append(Problem(scene, *scenario.sample_problem(scene, run.rng)))
        results = _rollouts(run, mined, averaged=True, seed=run.steps)
        for p, r in zip(mined, results, strict=True):
            if not r.success:
                pool.failed(p)
        raw["mine_success"] = float(np.mean([r.success for r in results]))
    raw["pool_size"] = float(len(pool))
    raw["retry_share"] = run.source.retry_share
    return raw


def _validate(run: _Run) -> tuple[dict[str, float], float]:
    """Validation (and failure mining): the metrics row and the mean steps of all episodes."""
    agent = run.agent
    agent.actor.eval()
    res = _rollouts(run, run.val_problems, averaged=True, seed=run.cfg.seed)
    raw: dict[str, float] = {}
    if agent.actor_avg is not None:  # the current actor too, for comparison
        raw["val_success_current"] = float(
            np.mean([r.success for r in _rollouts(run, run.val_problems, averaged=False, seed=run.cfg.seed)])
        )
    if run.pool is not None:
        raw.update(_mine_failures(run))
    agent.actor.train()
    solved = [r.nodes for r in res if r.success]
    row = {
        "env_steps": float(run.steps),
        "updates": float(agent.updates),
        "wall_time_s": run.wall,
        "val_success": float(np.mean([r.success for r in res])),
        "train_success": float(np.mean(run.recent)) if run.recent else 0.0,
        "val_nodes": float(np.mean(solved)) if solved else 0.0,
        **raw,
        **{k: float(v) for k, v in run.last_losses.items()},
    }
    return row, float(np.mean([r.nodes for r in res]))


def _trainer_state(run: _Run, wall: float, best: float, best_nodes: float) -> dict[str, Any]:
    return {
        "agent": run.agent.state_dict(),
        "steps": run.steps,
        "best": best,
        "best_nodes": best_nodes,
        "wall_time_s": wall,
        "rng": run.rng.bit_generator.state,
        "torch_rng": torch.get_rng_state(),
    }


def _save(run: _Run, row: dict[str, float], nodes_all: float) -> None:
    """``last.pt`` with the trainer state; ``best.pt`` when validation improved (highest
    success, then fewest steps)."""
    val, wall = row["val_success"], row["wall_time_s"]
    improved = val > run.best or (val == run.best and nodes_all < run.best_nodes)
    state = _trainer_state(run, wall, max(run.best, val), nodes_all if improved else run.best_nodes)
    extra = {"env_steps": run.steps, "val_success": val, "wall_time_s": wall, "horizon": run.core.horizon}
    payload = _checkpoint_payload(run.cfg, run.agent, run.obs_shape, run.scenario.robot.name, extra)
    run.folder.save("last.pt", {**payload, "trainer": state})
    if improved:
        run.best, run.best_nodes = val, nodes_all
        run.folder.save("best.pt", payload)


def _evaluate(run: _Run, on_eval: Callable[[dict[str, float]], None] | None, bar: Any) -> float:
    """Validate, log and checkpoint; returns the validation success."""
    row, nodes_all = _validate(run)
    run.history.append(row)
    run.logger.log(row)
    if on_eval is not None:
        on_eval(row)
    _save(run, row, nodes_all)
    if bar is not None:
        bar.write(
            f"step {run.steps}: val success {row['val_success']:.3f} (best {run.best:.3f}), {row['wall_time_s']:.0f} s"
        )
    return row["val_success"]


def _progress(run: _Run, bar: Any, collected: int) -> None:
    if bar is not None:
        if run.recent:  # the postfix first: the update may draw the bar
            post = {"train_success": f"{np.mean(run.recent):.2f}", "updates": run.agent.updates}
            if run.best >= 0:
                post["best_val"] = f"{run.best:.3f}"
            bar.set_postfix(post, refresh=False)
        bar.update(max(0, min(collected, bar.total - bar.n)))  # the last step may overshoot the total


def _save_last(run: _Run) -> None:
    """``last.pt`` with the trainer state at the current step (no validation)."""
    wall = run.wall
    extra: dict[str, Any] = {"env_steps": run.steps, "wall_time_s": wall, "horizon": run.core.horizon}
    if run.history:
        extra["val_success"] = run.history[-1]["val_success"]
    payload = _checkpoint_payload(run.cfg, run.agent, run.obs_shape, run.scenario.robot.name, extra)
    run.folder.save("last.pt", {**payload, "trainer": _trainer_state(run, wall, run.best, run.best_nodes)})


def _train(
    cfg: TrainConfig,
    folder: RunDir,
    progress: bool,
    resume: str | Path | None,
    on_eval: Callable[[dict[str, float]], None] | None,
    remote: RolloutSource | None,
) -> TrainResult:
    run = _start(cfg, folder, resume, remote)
    bar = None
    if progress:
        from ..progress import progress_bar

        bar = progress_bar(total=cfg.total_steps, initial=run.steps, unit="step", dynamic_ncols=True)
    stop_now = False
    with folder.ctrl_c(enabled=remote is None) as ctrl_c:  # (Ray rollouts handle Ctrl-C themselves)
        while run.steps < cfg.total_steps and not ctrl_c.requested:
            stop_now = remote is not None and remote.interrupted
            collected = _collect(run) if remote is None else _collect_remote(run, remote)
            _learn(run, collected)
            finished = False
            if run.steps >= run.next_eval or run.steps >= cfg.total_steps or stop_now:
                run.next_eval += cfg.eval_every
                finished = _evaluate(run, on_eval, bar) >= cfg.target_success or stop_now
            _progress(run, bar, collected)
            if finished:
                break
    if bar is not None:
        bar.close()
    if ctrl_c.requested or stop_now:  # (with Ray workers the last validation saved the state)
        folder.interrupted(
            f"at step {run.steps}",
            (lambda: _save_last(run)) if ctrl_c.requested else (lambda: None),
            best_note(best_or_none(run.best)),
        )
    folder.close()
    interrupted = ctrl_c.requested or stop_now
    return TrainResult(
        run_dir=run.run_dir,
        best_success=best_or_none(run.best),
        steps=run.steps,
        wall_time_s=run.wall,
        history=run.history,
        interrupted=interrupted,
    )
