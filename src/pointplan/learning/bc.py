"""Behavioural cloning from Bi-RRT demonstrations.

Demonstrations are Bi-RRT solutions (shortcut) of training problems, resampled into steps
of the policy's length: step ``t`` moves from ``q_t`` to ``q_{t+1}`` along the path, at most
one action scale per axis, and the expert action is ``log(q_t^-1 q_{t+1}) / action_scale``.
The actor's mean action (after the tanh) is fitted to it with an L2 loss.
"""

from __future__ import annotations

import signal
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import torch

from ..envs.core import EnvConfig
from ..models.actor_critic import Actor, NetConfig
from ..models.checkpoint import to_dict
from ..models.encoders import EncoderConfig
from ..models.inputs import goal_dim, goal_input, obs_input
from ..observers import OBSERVERS, make_observer
from ..parallel import Interrupted, backend, wants_workers
from ..robots.base import Robot
from ..scenes.scenarios import Scenario, make_scenario
from ..scenes.scene import Problem
from .memory import keep_freed_memory
from .rundir import RunDir, load_trainer_state, say_interrupted_early

if TYPE_CHECKING:
    from concurrent.futures import Executor

    from ..parallel import WorkerPool

    #: where demonstrations are planned: a worker pool, or a ``concurrent.futures`` pool of processes
    DemoPool = WorkerPool | Executor


@dataclass
class Demos:
    """Expert steps: configuration, goal, action in [-1, 1], and the index of the problem
    (in ``problems``) each step belongs to."""

    q: np.ndarray
    goal: np.ndarray
    action: np.ndarray
    scene: np.ndarray
    problems: list[Problem]
    #: the expert paths the steps were cut from: (problem index in the split, path in
    #: steps); a path may start anywhere (DAgger labels states the policy visited)
    paths: list[tuple[int, np.ndarray]] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.q)


def resample_path(robot: Robot, path: np.ndarray) -> np.ndarray:
    """Configurations along a path so that every consecutive pair is one action: the twist
    between them is within the robot's action scale on every axis."""
    from ..evaluation.evaluate import timed_path

    return timed_path(robot, path)


#: one demonstration to plan: (env, robot, split, problem index, problem seed, planner
#: seed, max nodes, start or None for the problem's own, Bi-RRT attempts, clearance margin)
DemoJob = tuple[str, "str | None", str, int, int, int, int, "np.ndarray | None", int, float]

#: planner seeds of a job's attempts after its first are this far apart
_ATTEMPT_SEED_STRIDE = 1_000_003


def _demo_index(seed: int, n_problems: int, i: int) -> int:
    # training workspaces far from those the RL trainer draws first; seed-dependent
    return 1_000_000 + seed * n_problems + i


def _plan_demo(job: DemoJob) -> tuple[int, np.ndarray | None]:
    """Solve one training problem with Bi-RRT (from ``start`` if given) and cut its path into
    policy steps. With several attempts, Bi-RRT plans the problem that many times (planner
    seeds ``_ATTEMPT_SEED_STRIDE`` apart) and the shortest solution is kept. Runs in worker
    processes: the problem is rebuilt from its index, so only indices and arrays travel."""
    from ..planners.base import path_length
    from ..planners.birrt import BiRRT

    env, robot_name, split, index, seed, planner_seed, max_nodes, start, attempts, margin = job
    scenario = make_scenario(env, robot=robot_name)
    p = scenario.problem(split, index, seed=seed)
    if start is not None:
        p = Problem(p.scene, start, p.goal, p.tag)
    best, best_len = None, float("inf")
    # with a margin, plan for the padded body first (a path that keeps its distance from the
    # obstacles); where that fails (a start or goal closer than the margin, a gap too narrow
    # for the padded body), plan for the body itself
    bodies = [scenario.robot.padded(margin), scenario.robot] if margin > 0 else [scenario.robot]
    for body in bodies:
        for a in range(max(1, attempts)):
            opts: dict[str, Any] = {**body.planner_defaults("birrt"), "max_nodes": max_nodes}  # an arm's joint steps
            res = BiRRT(body, seed=planner_seed + a * _ATTEMPT_SEED_STRIDE, **opts).plan(p)
            if res.success and (length := path_length(scenario.robot, res.path)) < best_len:
                best, best_len = res.path, length
        if best is not None:
            break
    return index, (resample_path(scenario.robot, best) if best is not None else None)


def _single_thread() -> None:
    """A planning worker process: one thread; Ctrl-C is the main process's to handle."""
    torch.set_num_threads(1)
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def demo_pool(workers: int, address: str | None = None) -> DemoPool | None:
    """A pool for :func:`plan_demos`: the default back end's workers when it can run here
    (Ray, :class:`pointplan.distributed.RayPool`; ``address`` joins a cluster), else a
    process pool; ``None`` for one worker and no address."""
    if not wants_workers(workers, address):
        return None
    if backend().available():
        return backend().pool(workers if workers > 1 else None, address)
    if address:
        raise RuntimeError(
            "running on several workers needs Ray: pip install 'pointplan[ray]' (or drop --workers/--address to run in one process)"
        )
    print(
        f"pointplan: planning in {workers} local processes; running on several workers needs Ray: pip install 'pointplan[ray]' to use Ray",
        file=sys.stderr,
    )
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    return ProcessPoolExecutor(workers, mp_context=mp.get_context("spawn"), initializer=_single_thread)


def plan_demos(
    jobs: list[DemoJob], pool: DemoPool | None = None, progress: bool = True, desc: str = "demonstrations"
) -> list[tuple[int, np.ndarray]]:
    """Plan every job (in ``pool`` if given: a ``concurrent.futures`` pool or a
    :class:`~pointplan.parallel.WorkerPool`; each job has its own planner seed, so the
    result does not depend on the workers); returns the solved ones in job order."""
    from concurrent.futures import Executor

    bar = None
    if progress:
        from ..progress import progress_bar

        bar = progress_bar(total=len(jobs), desc=desc, unit="problem")
    out: list[tuple[int, np.ndarray]] = []
    if pool is not None and not isinstance(pool, Executor):
        # results come back in job order; Ctrl-C keeps the demonstrations that finished
        live_bar = bar
        bar = None  # advanced as results arrive, not in the loop below
        try:
            results: Any = pool.map(
                _plan_demo, jobs, on_result=lambda *_: live_bar.update() if live_bar is not None else None
            )
        except Interrupted as stop:
            results = [stop.results[i] for i in sorted(stop.results)]
            print(
                f"\ninterrupted: keeping the {len(results)} of {len(jobs)} demonstrations that finished",
                file=sys.stderr,
            )
        finally:
            if live_bar is not None:
                live_bar.close()
    elif pool is not None:
        results = pool.map(_plan_demo, jobs, chunksize=8)
    else:
        results = _plan_in_turn(jobs, bar)
        bar = None  # (advanced by _plan_in_turn)
    for index, path in results:
        if path is not None and len(path) > 1:
            out.append((index, path))
        if bar is not None:
            bar.update()
    if bar is not None:
        bar.close()
    return out


def _plan_in_turn(jobs: list[DemoJob], bar: Any) -> list[tuple[int, np.ndarray | None]]:
    """Plan the jobs one after the other in this process; Ctrl-C keeps those that finished."""
    results: list[tuple[int, np.ndarray | None]] = []
    try:
        for job in jobs:
            results.append(_plan_demo(job))
            if bar is not None:
                bar.update()
    except KeyboardInterrupt:
        print(f"\ninterrupted: keeping the {len(results)} of {len(jobs)} demonstrations that finished", file=sys.stderr)
    finally:
        if bar is not None:
            bar.close()
    return results


def generate_demos(
    scenario: Scenario,
    n_problems: int,
    seed: int = 0,
    max_nodes: int = 20000,
    progress: bool = True,
    split: str = "train",
    workers: int = 1,
    address: str | None = None,
    attempts: int = 1,
    margin: float = 0.0,
    pool: DemoPool | None = None,
) -> Demos:
    """Plan ``n_problems`` training problems with Bi-RRT and cut the paths into steps (in
    ``pool`` if given, else on ``workers`` Ray workers or processes, see :func:`demo_pool`);
    with ``attempts > 1`` each problem is planned that many times and its shortest solution
    kept (the first attempt is the single-attempt run's, so its problems and solutions are a
    subset). With
    ``margin > 0`` the expert plans for the body grown by ``margin`` (:meth:`Robot.padded`),
    falling back to the body itself where the padded one finds no path."""
    if attempts < 1:
        raise ValueError(f"attempts must be >= 1, not {attempts}")
    robot_name = scenario.robot.name if scenario.robot.dim == 3 else None
    index = [_demo_index(seed, n_problems, i) for i in range(n_problems)]
    jobs: list[DemoJob] = [
        (scenario.name, robot_name, split, k, seed, seed * 7_919 + k, max_nodes, None, attempts, float(margin))
        for k in index
    ]
    own = pool is None
    if own:
        pool = demo_pool(workers, address)
    try:
        paths = plan_demos(jobs, pool, progress)
    finally:
        if own and pool is not None:
            pool.shutdown(cancel_futures=True)  # (after Ctrl-C: the jobs not started are dropped)
    return demos_from_paths(scenario, split, seed, paths)


def demos_from_paths(scenario: Scenario, split: str, seed: int, paths: list[tuple[int, np.ndarray]]) -> Demos:
    """The expert steps of ``paths`` (problem index in ``split``, path in steps)."""
    robot = scenario.robot
    qs, goals, acts, idx = [], [], [], []
    problems: dict[int, Problem] = {}
    order: dict[int, int] = {}
    for index, path in paths:
        if index not in problems:
            problems[index] = scenario.problem(split, index, seed=seed)
            order[index] = len(order)
        a = robot.log(path[:-1], path[1:]) / robot.action_scale
        qs.append(path[:-1])
        goals.append(np.broadcast_to(problems[index].goal, path[:-1].shape))
        acts.append(np.clip(a, -1, 1))
        idx.append(np.full(len(a), order[index]))
    if not qs:
        raise ValueError("no demonstration was solved")
    return Demos(
        np.concatenate(qs),
        np.concatenate(goals),
        np.concatenate(acts).astype(np.float32),
        np.concatenate(idx),
        list(problems.values()),
        list(paths),
    )


def save_demos(path: str | Path, scenario: Scenario, demos: Demos, split: str, seed: int) -> None:
    """Keep the demonstration paths (plain arrays) to reuse them in another run."""
    keys = np.array([k for k, _ in demos.paths], np.int64)
    lengths = np.array([len(p) for _, p in demos.paths], np.int64)
    flat = np.concatenate([p for _, p in demos.paths]) if demos.paths else np.zeros((0, scenario.robot.config_dim))
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(
        path,
        env=scenario.name,
        robot=scenario.robot.name,
        split=split,
        seed=seed,
        index=keys,
        lengths=lengths,
        configs=flat,
    )


def load_demos(path: str | Path, scenario: Scenario) -> Demos:
    """Demonstrations saved by :func:`save_demos` (the problems are rebuilt from their indices)."""
    with np.load(path, allow_pickle=False) as f:
        if str(f["env"]) != scenario.name or str(f["robot"]) not in (scenario.robot.name, scenario.robot.body):
            raise ValueError(
                f"{path}: demonstrations of {f['env']} / {f['robot']}, not {scenario.name} / {scenario.robot.name}"
            )
        split, seed = str(f["split"]), int(f["seed"])
        pieces = np.split(f["configs"], np.cumsum(f["lengths"])[:-1]) if len(f["lengths"]) else []
        paths = [(int(k), np.asarray(c)) for k, c in zip(f["index"], pieces)]
    return demos_from_paths(scenario, split, seed, paths)


def observation_shape(robot: Robot, env: EnvConfig) -> tuple[int, ...]:
    """The shape of one observation of ``env``'s observer."""
    kwargs: dict[str, Any] = {} if env.observation == "image" else {"n_points": env.n_points}
    return tuple(make_observer(str(env.observation), robot, **kwargs).space.shape)


def observe_demos(
    demos: Demos, robot: Robot, env: EnvConfig, rng: np.random.Generator, chunk: int = 4096
) -> np.ndarray:
    """Observations of every demonstration step (the observer's random subsets are drawn
    anew on every call, so calling again gives a fresh augmentation), in the observer's
    ``storage_dtype`` (occupancy images as bytes: a million 64 x 64 images take 4 GB,
    not 16)."""
    kwargs: dict[str, Any] = {} if env.observation == "image" else {"n_points": env.n_points}
    name = env.observation_for(robot)
    out: np.ndarray | None = None  # filled chunk by chunk (a million steps of 256 points: 6 GB)
    for c in range(0, len(demos), chunk):
        sl = slice(c, c + chunk)
        obs = make_observer(name, robot, **kwargs)
        obs.bind([demos.problems[j].scene for j in demos.scene[sl]])
        part = obs.observe(demos.q[sl], rng)
        if out is None:
            out = np.empty((len(demos), *part.shape[1:]), obs.storage_dtype)
        out[sl] = part
    if out is None:
        raise ValueError("no demonstration steps to observe")
    return out


def observations_vary(robot: Robot, env: EnvConfig) -> bool:
    """Whether :func:`observe_demos` gives new observations on every call (random point
    subsets, random rays) or the same ones, leaving ``rng`` untouched (the occupancy image:
    :attr:`~pointplan.observers.base.Observer.stochastic`); the latter need observing
    once for any number of epochs."""
    cls = OBSERVERS.get(env.observation_for(robot))
    return cls is None or cls.stochastic


def stored_obs_tensor(robot: Robot, obs: np.ndarray, device: torch.device | str) -> torch.Tensor:
    """Many observations (:func:`observe_demos`) as one tensor to index batches from:
    point sets as the network takes them (scaled in place, float32), images in their
    stored dtype, so that only each batch is converted (``batch.float()``)."""
    if obs.dtype == np.float32:
        return torch.as_tensor(obs_input(robot, obs, copy=False), device=device)
    return torch.as_tensor(obs, device=device)


def demo_episodes(
    demos: Demos, robot: Robot, env: EnvConfig, rng: np.random.Generator, horizon: int | None = None
) -> list[tuple[np.ndarray, ...]]:
    """The demonstration paths as the episodes an environment would have produced, in
    :meth:`~pointplan.learning.replay.EpisodeReplay.add_episode`'s order (obs, next_obs,
    q, q_next, goal, action, action_norm, collided): each step moves from ``q_t`` to
    ``q_{t+1}`` with the expert action, collision-free (the paths are certified); an
    episode ends at the first step within the goal tolerance, or after ``horizon`` steps."""
    from ..envs.core import goal_reached

    episodes: list[tuple[np.ndarray, ...]] = []
    configs: list[np.ndarray] = []
    scenes: list[np.ndarray] = []
    spans: list[tuple[int, int, int, np.ndarray]] = []
    row = 0
    for _, path in demos.paths:
        n = len(path) - 1
        if n <= 0:
            continue
        p = int(demos.scene[row])
        goal = demos.problems[p].goal
        reached = goal_reached(robot, env, path[1:], np.broadcast_to(goal, path[1:].shape))
        t_end = int(np.argmax(reached)) + 1 if reached.any() else n
        if horizon is not None:
            t_end = min(t_end, int(horizon))
        spans.append((row, t_end, len(configs), goal))
        configs.append(path[: t_end + 1])
        scenes.append(np.full(t_end + 1, p))
        row += n
    if not configs:
        return episodes
    q_all, scene_all = np.concatenate(configs), np.concatenate(scenes)
    view = Demos(q_all, q_all, np.zeros((len(q_all), robot.twist_dim), np.float32), scene_all, demos.problems)
    obs_all = observe_demos(view, robot, env, rng)
    start = 0
    for (row, t_end, _, goal), c in zip(spans, configs):
        obs = obs_all[start : start + t_end + 1]
        action = demos.action[row : row + t_end]
        episodes.append(
            (
                obs[:-1],
                obs[1:],
                c[:-1],
                c[1:],
                np.broadcast_to(goal, c[:-1].shape).copy(),
                action,
                np.linalg.norm(action, axis=-1).astype(np.float64),
                np.zeros(t_end, bool),
            )
        )
        start += t_end + 1
    return episodes


@dataclass(frozen=True)
class BCConfig:
    """A behavioural-cloning run (saved with its checkpoint)."""

    env: str = "narrow2d"
    #: ``sphere3d`` or ``sshape`` in the 3D scenes; ``None`` takes the scenario's default
    robot: str | None = None
    observation: str = "surface-normals"
    n_points: int = 64
    #: demonstration problems planned by Bi-RRT (when --demos names a file that exists,
    #: every demonstration in it is used instead)
    n_problems: int = field(default=2000, metadata={"min": 1})
    #: passes over the demonstrations
    epochs: int = field(default=30, metadata={"min": 1})
    #: Adam step size
    lr: float = 1e-3
    #: demonstration steps per gradient step
    batch_size: int = field(default=256, metadata={"min": 1})
    seed: int = 0
    device: str = "cpu"
    #: draw new observation subsets every this many epochs (0: never; observations that
    #: draw nothing at random, the occupancy image, are computed once)
    refresh_every: int = 5
    #: weight of a Gaussian likelihood term that fits the actor's spread (its log-std) to
    #: the residuals of its mean action, before the tanh, with the mean held fixed; 0 leaves
    #: the spread unfitted (what SAC then samples from is whatever the untrained head gives)
    spread_weight: float = field(default=0.0, metadata={"min": 0})
    net: NetConfig = field(
        default_factory=lambda: NetConfig(
            EncoderConfig(width=64), head_width=64, critic_action="pooled", shared_encoder=True
        )
    )
    #: workers planning the demonstrations (Ray when installed, else processes); the demonstrations equal a serial run's
    workers: int = field(default=1, metadata={"min": 1})
    #: a Ray cluster to plan the demonstrations on
    address: str | None = None
    #: a file of demonstrations: loaded if it exists, written after planning otherwise
    demos_file: str | None = None
    #: Bi-RRT runs per demonstration problem; the shortest solution is kept (shorter,
    #: more consistent demonstrations: an expert that picks the shorter way round an
    #: obstacle, rather than either way at random, is easier to clone)
    expert_attempts: int = field(default=1, metadata={"min": 1})
    #: the expert plans for the robot's body grown by this much (falling back to the body
    #: itself where that finds no path), so that its paths keep their distance from the
    #: obstacles instead of grazing them
    expert_margin: float = field(default=0.0, metadata={"min": 0})
    #: Bi-RRT node budget of each demonstration (problems it cannot solve within it are
    #: left out: an arm's unsolvable problems cost seconds per thousand nodes)
    expert_max_nodes: int = field(default=20000, metadata={"min": 1})
    #: start from this checkpoint's actor (its network must be this run's): cloning
    #: fine-tunes it; with DAgger rounds, DAgger starts from it instead of cloning first
    init_actor: str | None = None


def train_bc(
    cfg: BCConfig,
    run_dir: str | Path,
    progress: bool = True,
    demos: Demos | None = None,
    pool: DemoPool | None = None,
    resume: str | Path | None = None,
    eval_episodes: int = 0,
) -> dict[str, Any]:
    """Fit the actor to demonstrations; saves the policy as ``run_dir/bc.pt``, the trainer
    state as ``last.pt`` (also on Ctrl-C; ``resume`` continues from it), the loss of every
    epoch in ``metrics.csv`` and demonstrations planned here in ``demos.npz`` (or
    ``cfg.demos_file``). With ``eval_episodes`` the clone is rolled out on that many
    validation problems at the end. Returns a summary. ``pool``: where to plan the
    demonstrations (see :func:`generate_demos`)."""
    folder = RunDir(run_dir, "pointplan bc")
    ckpt = load_trainer_state(resume, "bc_trainer", "pointplan bc", cfg.device) if resume is not None else None
    state = ckpt["bc_trainer"] if ckpt is not None else None
    scenario = make_scenario(cfg.env, robot=cfg.robot)
    robot = scenario.robot
    env = EnvConfig(observation=cfg.observation, n_points=cfg.n_points)
    rng = np.random.default_rng(cfg.seed)
    torch.manual_seed(cfg.seed)
    start = init_actor_state(cfg.init_actor, cfg.device) if ckpt is None and cfg.init_actor else None
    t0 = time.perf_counter()
    try:
        demos, demos_file = _bc_demos(cfg, scenario, folder, progress, demos, pool, state)
    except KeyboardInterrupt:
        say_interrupted_early("planning the demonstrations")
        return {"run_dir": str(folder.path), "interrupted": True, "epochs": 0}
    t_demos = time.perf_counter() - t0
    obs_shape = observation_shape(robot, env)
    actor = Actor(obs_shape, goal_dim(robot), robot.twist_dim, cfg.net).to(torch.device(cfg.device))
    opt = torch.optim.Adam(actor.parameters(), lr=cfg.lr)
    if start is not None:
        load_init_actor(actor, start, str(cfg.init_actor))
    losses, wall_before = _restore_bc(ckpt, actor, opt, rng) if ckpt is not None else ([], 0.0)
    if len(losses) >= cfg.epochs:
        raise ValueError(
            f"{resume}: the run has done its {len(losses)} epochs; give --epochs above that to continue it"
        )
    if ckpt is not None:
        folder.metrics.drop_after(len(losses))
    val = _fit_bc(cfg, actor, opt, demos, scenario, env, rng, losses, folder, progress, eval_episodes)
    train_time = wall_before + time.perf_counter() - t0 - t_demos
    payload = {
        **policy_payload(cfg, robot.name, obs_shape, actor, scenario.horizon),
        "bc_config": to_dict(cfg),
        "demo_steps": len(demos),
    }
    trainer = {
        "epochs": len(losses),
        "losses": list(losses),
        "optimizer": opt.state_dict(),
        "demos": demos_file,
        "wall_time_s": train_time,
        "eval_episodes": eval_episodes,
    }
    summary = {
        "run_dir": str(folder.path),
        "demo_steps": len(demos),
        "demo_problems": len(demos.problems),
        "epochs": len(losses),
        "interrupted": False,
    }
    if not _save_bc(folder, payload, trainer, rng, cfg.epochs, val):
        return {**summary, "interrupted": True}
    return {
        **summary,
        "checkpoint": str(folder.path / "bc.pt"),
        "demo_time_s": t_demos,
        "train_time_s": train_time,
        "final_loss": losses[-1],
        "val_success": val,
        "val_problems": eval_episodes if val is not None else 0,
    }


def _fit_bc(
    cfg: BCConfig,
    actor: Actor,
    opt: torch.optim.Optimizer,
    demos: Demos,
    scenario: Scenario,
    env: EnvConfig,
    rng: np.random.Generator,
    losses: list[float],
    folder: RunDir,
    progress: bool,
    eval_episodes: int,
) -> float | None:
    """Fit ``actor`` to ``demos`` up to ``cfg.epochs`` (``losses`` holds the epochs done
    and gets the new ones; Ctrl-C ends the fit after the current gradient step); then, when
    every epoch is done, its success rate on ``eval_episodes`` validation problems (None
    without them)."""
    val = None
    with folder.ctrl_c() as stop:
        fit_actor(
            actor,
            opt,
            demos,
            scenario.robot,
            env,
            cfg.epochs,
            cfg.batch_size,
            rng,
            cfg.refresh_every,
            progress,
            cfg.spread_weight,
            losses,
            stop,
            folder.log,
        )
        if len(losses) == cfg.epochs and eval_episodes:
            val = validate_actor(actor, scenario, env, eval_episodes, cfg.seed, cfg.device)
    return val


def _save_bc(
    folder: RunDir,
    payload: dict[str, Any],
    trainer: dict[str, Any],
    rng: np.random.Generator,
    epochs: int,
    val: float | None,
) -> bool:
    """Write a cloning run's ``last.pt`` (through ``folder.interrupted`` when the run
    stopped before its ``epochs``) and, when it did them all, ``bc.pt``; close the folder.
    Returns whether the run did all its epochs."""
    save_last = lambda: folder.save(
        "last.pt",
        {**payload, "bc_trainer": {**trainer, "rng": rng.bit_generator.state, "torch_rng": torch.get_rng_state()}},
    )
    done = trainer["epochs"]
    if done < epochs:
        folder.interrupted(f"in epoch {done + 1} of {epochs}", save_last)
        folder.close()
        return False
    folder.save("bc.pt", {**payload, **({"val_success": val} if val is not None else {})})
    save_last()
    folder.close()
    return True


def _bc_demos(
    cfg: BCConfig,
    scenario: Scenario,
    folder: RunDir,
    progress: bool,
    demos: Demos | None,
    pool: DemoPool | None,
    state: dict[str, Any] | None,
) -> tuple[Demos, str | None]:
    """The demonstrations of a cloning run and the file that keeps them (None: given, not
    kept): a resumed run's own, ``cfg.demos_file`` when it exists, else planned and written
    to ``cfg.demos_file`` or the run folder's ``demos.npz``."""
    if demos is not None:
        return demos, cfg.demos_file
    kept = state.get("demos") if state is not None else None
    if kept and Path(kept).exists():
        return load_demos(kept, scenario), str(kept)
    if cfg.demos_file and Path(cfg.demos_file).exists():
        demos = load_demos(cfg.demos_file, scenario)
        if progress and len(demos.problems) != cfg.n_problems:
            print(
                f"{cfg.demos_file}: all its {len(demos.problems)} demonstrations are used (--problems {cfg.n_problems} counts only problems to plan)"
            )
        return demos, cfg.demos_file
    demos = generate_demos(
        scenario,
        cfg.n_problems,
        cfg.seed,
        max_nodes=cfg.expert_max_nodes,
        progress=progress,
        workers=cfg.workers,
        address=cfg.address,
        attempts=cfg.expert_attempts,
        margin=cfg.expert_margin,
        pool=pool,
    )
    path = cfg.demos_file or str(folder.path / "demos.npz")
    save_demos(path, scenario, demos, "train", cfg.seed)
    return demos, path


def init_actor_state(path: str, device: str) -> dict[str, Any]:
    """The actor weights of checkpoint ``path`` (read before any demonstration is planned,
    so that a wrong path fails at once)."""
    from ..models.checkpoint import load_checkpoint

    data = load_checkpoint(path, device)
    if "actor" not in data:
        raise ValueError(f"--init-actor {path}: the checkpoint has no actor")
    return dict(data["actor"])


def load_init_actor(actor: Actor, state: dict[str, Any], path: str) -> None:
    """Load ``state`` into ``actor``; a clear error where its network differs from this run's."""
    try:
        actor.load_state_dict(state)
    except RuntimeError as e:
        raise ValueError(
            f"--init-actor {path}: its network is not this run's (give the same --observation, "
            f"--n-points, --width, --layers, --encoder and --encoder-sharing): {str(e).splitlines()[0]}"
        ) from None


def _restore_bc(
    ckpt: dict[str, Any], actor: Actor, opt: torch.optim.Optimizer, rng: np.random.Generator
) -> tuple[list[float], float]:
    """Load a cloning run's ``last.pt``; returns the losses of its epochs and its training time."""
    actor.load_state_dict(ckpt["actor"])
    state = ckpt["bc_trainer"]
    opt.load_state_dict(state["optimizer"])
    rng.bit_generator.state = state["rng"]
    torch.set_rng_state(state["torch_rng"])
    return [float(x) for x in state["losses"]], float(state["wall_time_s"])


def validate_actor(
    actor: Actor, scenario: Scenario, env: EnvConfig, episodes: int, seed: int, device: str = "cpu"
) -> float:
    """Success rate of the actor's mean action on the first ``episodes`` validation problems
    (the rollout engine, as training validation does)."""
    from ..models.policy import Policy
    from ..planners.rollout import rollout_batch

    policy = Policy(actor, scenario.robot, {"observation": env.observation, "n_points": env.n_points}, device)
    problems = scenario.problems("val", episodes, seed=seed)
    res = rollout_batch(
        policy,
        scenario.robot,
        EnvConfig(observation=env.observation, n_points=env.n_points, split="val"),
        problems,
        scenario.horizon,
        seed=seed,
    )
    actor.train()
    return float(np.mean([r.success for r in res]))


def policy_payload(cfg: BCConfig, robot: str, obs_shape: tuple[int, ...], actor: Actor, horizon: int) -> dict[str, Any]:
    """What a policy checkpoint holds (:class:`~pointplan.models.policy.Policy` reads it)."""
    return {
        "env": cfg.env,
        "robot": robot,
        "observation": cfg.observation,
        "n_points": cfg.n_points,
        "obs_shape": list(obs_shape),
        "net": to_dict(cfg.net),
        "actor": actor.state_dict(),
        "horizon": horizon,
    }


#: expert actions are clipped to this before the inverse tanh (saturated ones would be infinite)
_ATANH_CLIP = 0.995


def spread_loss(mean: torch.Tensor, log_std: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
    """Negative log-likelihood (up to a constant) of the expert's action before the tanh,
    ``atanh(a)``, under ``N(mean, exp(log_std))``, with the mean detached: this term fits
    the spread to the residuals of the mean and does not pull the mean itself (the L2 loss
    does; the layers both outputs share get gradients from both)."""
    u = torch.atanh(action.clamp(-_ATANH_CLIP, _ATANH_CLIP))
    z = (u - mean.detach()) * torch.exp(-log_std)
    return (0.5 * z**2 + log_std).sum(-1).mean()


def fit_actor(
    actor: Actor,
    opt: torch.optim.Optimizer,
    demos: Demos,
    robot: Robot,
    env: EnvConfig,
    epochs: float,
    batch_size: int,
    rng: np.random.Generator,
    refresh_every: int = 5,
    progress: bool = True,
    spread_weight: float = 0.0,
    done: list[float] | None = None,
    stop: Callable[[], bool] | None = None,
    on_epoch: Callable[[dict[str, float]], None] | None = None,
    stored: torch.Tensor | None = None,
) -> list[float]:
    """Fit the actor's mean action to the demonstrations (L2) for ``epochs`` passes (a
    fraction runs part of one); new observation subsets every ``refresh_every`` epochs
    (observations that do not vary, :func:`observations_vary`, are computed once).
    With ``spread_weight`` the log-std is fitted too (:func:`spread_loss`). Returns the
    mean L2 loss of each pass. ``done``: the losses of passes made before (the fit goes on
    after them, appending to that list); ``stop``: asked after every gradient step, ends
    the fit with the current pass unfinished (and not counted); ``on_epoch``: called with
    ``{"epoch", "loss"}`` after each pass; ``stored``: the observations of every step,
    :func:`stored_obs_tensor` of :func:`observe_demos`, computed once by a caller that
    fits many times on observations that do not vary (the occupancy image, whose million
    images of the paper's budget take many minutes to rasterise)."""
    device = next(actor.parameters()).device
    vary = observations_vary(robot, env)
    if stored is not None and vary:
        raise ValueError(f"stored observations are for observers that do not vary; {env.observation!r} does")
    if env.observation == "image":  # the CNN's activations: large blocks freed and taken every batch
        keep_freed_memory()
    act = torch.as_tensor(demos.action, device=device)
    g_all = torch.as_tensor(goal_input(robot, demos.q, demos.goal), device=device)
    losses: list[float] = done if done is not None else []
    total_passes = int(np.ceil(epochs))
    passes: Any = range(len(losses), total_passes)
    if progress:
        from ..progress import progress_bar

        passes = progress_bar(passes, desc="behavioural cloning", unit="epoch", total=total_passes, initial=len(losses))
    obs = stored
    for ep in passes:
        if obs is None or (vary and refresh_every and ep % refresh_every == 0):
            obs = None  # (the old subsets freed first: one copy of them in memory at a time)
            obs = stored_obs_tensor(robot, observe_demos(demos, robot, env, rng), device)
        n = len(demos) if ep + 1 <= epochs else int(len(demos) * (epochs - ep))
        perm = torch.as_tensor(rng.permutation(len(demos))[:n], device=device)
        total, stopped = 0.0, False
        for s in range(0, len(perm), batch_size):
            b = perm[s : s + batch_size]
            mean, log_std = actor(obs[b].float(), g_all[b])
            loss = ((torch.tanh(mean) - act[b]) ** 2).sum(-1).mean()
            full = loss + spread_weight * spread_loss(mean, log_std, act[b]) if spread_weight > 0 else loss
            opt.zero_grad(set_to_none=True)
            full.backward()
            opt.step()
            total += float(loss.detach()) * len(b)
            stopped = stop is not None and stop()
            if stopped:
                break
        if stopped:
            break
        losses.append(total / max(len(perm), 1))
        if on_epoch is not None:
            on_epoch({"epoch": len(losses), "loss": losses[-1]})
        if progress:
            passes.set_postfix(loss=f"{losses[-1]:.4f}", refresh=False)
    if progress:
        passes.close()
    return losses
