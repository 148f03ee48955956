"""Behavioural cloning from Bi-RRT demonstrations.

Demonstrations are Bi-RRT solutions (shortcut) of training problems, resampled into steps
of the policy's length: step ``t`` moves from ``q_t`` to ``q_{t+1}`` along the path, at most
one action scale per axis, and the expert action is ``log(q_t^-1 q_{t+1}) / action_scale``.
The actor's mean action (after the tanh) is fitted to it with an L2 loss.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ..envs.core import EnvConfig
from ..models.actor_critic import Actor, NetConfig
from ..models.encoders import EncoderConfig
from ..models.inputs import goal_input, obs_input
from ..observers import make_observer
from ..robots.base import Robot
from ..scenes.scenarios import Scenario, make_scenario
from ..scenes.scene import Problem
from .checkpoint import save_checkpoint, to_dict


@dataclass
class Demos:
    """Expert steps: configuration, goal, action in [-1, 1], and the index of the scene."""

    q: np.ndarray
    goal: np.ndarray
    action: np.ndarray
    scene: np.ndarray
    problems: list[Problem]
    #: problem index -> resampled path (what :func:`save_demos` keeps)
    paths: dict[int, np.ndarray] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.q)


def resample_path(robot: Robot, path: np.ndarray) -> np.ndarray:
    """Configurations along a path so that every consecutive pair is one action: the twist
    between them is within the robot's action scale on every axis."""
    out = [np.asarray(path[0], np.float64)]
    for a, b in zip(path[:-1], path[1:]):
        v = robot.log(a, b)
        n = max(1, int(np.ceil(np.max(np.abs(v) / robot.action_scale) - 1e-9)))
        s = np.arange(1, n + 1) / n
        out.extend(robot.interpolate(np.asarray(a)[None], np.asarray(b)[None], s))
    return np.asarray(out)


def _demo_index(seed: int, n_problems: int, i: int) -> int:
    # training workspaces far from those the RL trainer draws first; seed-dependent
    return 1_000_000 + seed * n_problems + i


def _plan_demo(job: tuple[str, str | None, str, int, int, int]) -> tuple[int, np.ndarray | None]:
    """Solve one training problem with Bi-RRT and cut its path into policy steps (in a worker
    process: the problem is rebuilt from its index, so only indices and arrays travel)."""
    from ..planners.birrt import BiRRT

    env, robot_name, split, index, seed, max_nodes = job
    scenario = make_scenario(env, robot=robot_name)
    p = scenario.problem(split, index, seed=seed)
    res = BiRRT(scenario.robot, max_nodes=max_nodes, seed=seed * 7_919 + index).plan(p)
    return index, (resample_path(scenario.robot, res.path) if res.success else None)


def generate_demos(
    scenario: Scenario,
    n_problems: int,
    seed: int = 0,
    max_nodes: int = 20000,
    progress: bool = True,
    split: str = "train",
    workers: int = 1,
) -> Demos:
    """Plan ``n_problems`` training problems with Bi-RRT and cut the paths into steps.

    ``workers > 1`` plans in that many processes (each problem has its own planner seed,
    so the demonstrations do not depend on the number of workers)."""
    robot = scenario.robot
    robot_name = robot.name if robot.dim == 3 else None
    jobs = [(scenario.name, robot_name, split, _demo_index(seed, n_problems, i), seed, max_nodes) for i in range(n_problems)]
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=n_problems, desc="demonstrations", unit="problem")
    paths: dict[int, np.ndarray | None] = {}
    if workers > 1:
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(workers, mp_context=mp.get_context("spawn"), initializer=_single_thread) as ex:
            for index, path in ex.map(_plan_demo, jobs, chunksize=8):
                paths[index] = path
                if bar is not None:
                    bar.update()
    else:
        for job in jobs:
            index, path = _plan_demo(job)
            paths[index] = path
            if bar is not None:
                bar.update()
    if bar is not None:
        bar.close()
    return _demos_from_paths(scenario, split, seed, paths)


def _single_thread() -> None:
    torch.set_num_threads(1)


def _demos_from_paths(scenario: Scenario, split: str, seed: int, paths: dict[int, np.ndarray | None]) -> Demos:
    robot = scenario.robot
    qs, goals, acts, idx, probs, keys = [], [], [], [], [], []
    for index in sorted(paths):
        path = paths[index]
        if path is None:
            continue
        p = scenario.problem(split, index, seed=seed)
        a = robot.log(path[:-1], path[1:]) / robot.action_scale
        qs.append(path[:-1])
        goals.append(np.broadcast_to(p.goal, path[:-1].shape))
        acts.append(np.clip(a, -1, 1))
        idx.append(np.full(len(a), len(probs)))
        probs.append(p)
        keys.append(index)
    kept = {k: p for k in keys if (p := paths[k]) is not None}
    return Demos(np.concatenate(qs), np.concatenate(goals), np.concatenate(acts).astype(np.float32), np.concatenate(idx), probs, kept)


def save_demos(path: str | Path, scenario: Scenario, demos: Demos, split: str, seed: int) -> None:
    """Keep the resampled demonstration paths (plain arrays) to reuse them in another run."""
    paths = demos.paths
    keys = np.array(sorted(paths), np.int64)
    flat = np.concatenate([paths[int(k)] for k in keys]) if len(keys) else np.zeros((0, scenario.robot.config_dim))
    lengths = np.array([len(paths[int(k)]) for k in keys], np.int64)
    np.savez_compressed(path, env=scenario.name, robot=scenario.robot.name, split=split, seed=seed, index=keys, lengths=lengths, configs=flat)


def load_demos(path: str | Path, scenario: Scenario) -> Demos:
    """Demonstrations saved by :func:`save_demos` (the problems are rebuilt from their indices)."""
    with np.load(path, allow_pickle=False) as f:
        if str(f["env"]) != scenario.name or str(f["robot"]) != scenario.robot.name:
            raise ValueError(f"{path}: demonstrations of {f['env']} / {f['robot']}, not {scenario.name} / {scenario.robot.name}")
        split, seed = str(f["split"]), int(f["seed"])
        ends = np.cumsum(f["lengths"])
        pieces = np.split(f["configs"], ends[:-1]) if len(ends) else []
        paths: dict[int, np.ndarray | None] = {int(k): np.asarray(c) for k, c in zip(f["index"], pieces)}
    return _demos_from_paths(scenario, split, seed, paths)


def observe_demos(demos: Demos, robot: Robot, env: EnvConfig, rng: np.random.Generator, chunk: int = 4096) -> np.ndarray:
    """Observations of every demonstration step (the observer's random subsets are drawn
    anew on every call, so calling again gives a fresh augmentation)."""
    kwargs: dict[str, Any] = {} if env.observation == "image" else {"n_points": env.n_points}
    out = []
    for c in range(0, len(demos), chunk):
        sl = slice(c, c + chunk)
        obs = make_observer(env.observation, robot, **kwargs)
        obs.bind([demos.problems[j].scene for j in demos.scene[sl]])
        out.append(obs.observe(demos.q[sl], rng))
    return np.concatenate(out)


@dataclass(frozen=True)
class BCConfig:
    env: str = "narrow2d"
    #: ``sphere3d`` or ``sshape`` in the 3D scenes; ``None`` takes the scenario's default
    robot: str | None = None
    observation: str = "surface-normals"
    n_points: int = 64
    n_problems: int = 2000
    epochs: int = 30
    lr: float = 1e-3
    batch_size: int = 256
    seed: int = 0
    device: str = "cpu"
    #: draw new observation subsets every this many epochs (0: never)
    refresh_every: int = 5
    net: NetConfig = field(default_factory=lambda: NetConfig(EncoderConfig(width=64), head_width=64, critic_action="pooled", shared_encoder=True))
    #: processes planning the demonstrations
    workers: int = 1
    #: a file of demonstrations: loaded if it exists, written after planning otherwise
    demos_file: str | None = None


def train_bc(cfg: BCConfig, run_dir: str | Path, progress: bool = True, demos: Demos | None = None) -> dict[str, Any]:
    """Fit the actor to demonstrations; saves ``run_dir/bc.pt``. Returns a summary."""
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    scenario = make_scenario(cfg.env, robot=cfg.robot)
    robot = scenario.robot
    env = EnvConfig(observation=cfg.observation, n_points=cfg.n_points)
    rng = np.random.default_rng(cfg.seed)
    torch.manual_seed(cfg.seed)
    t0 = time.perf_counter()
    if demos is None and cfg.demos_file and Path(cfg.demos_file).exists():
        demos = load_demos(cfg.demos_file, scenario)
    if demos is None:
        demos = generate_demos(scenario, cfg.n_problems, cfg.seed, progress=progress, workers=cfg.workers)
        if cfg.demos_file:
            save_demos(cfg.demos_file, scenario, demos, "train", cfg.seed)
    t_demos = time.perf_counter() - t0
    obs = obs_input(robot, observe_demos(demos, robot, env, rng))
    obs_shape = tuple(obs.shape[1:])
    device = torch.device(cfg.device)
    actor = Actor(obs_shape, robot.twist_dim, robot.twist_dim, cfg.net).to(device)
    opt = torch.optim.Adam(actor.parameters(), lr=cfg.lr)
    goal_vec = goal_input(robot, demos.q, demos.goal)
    act = torch.as_tensor(demos.action, device=device)
    g_all = torch.as_tensor(goal_vec, device=device)
    losses = []
    epochs = range(cfg.epochs)
    if progress:
        from tqdm import tqdm

        epochs = tqdm(epochs, desc="behavioural cloning", unit="epoch")
    for ep in epochs:
        if cfg.refresh_every and ep > 0 and ep % cfg.refresh_every == 0:
            obs = obs_input(robot, observe_demos(demos, robot, env, rng))
        o_all = torch.as_tensor(obs, device=device)
        perm = torch.as_tensor(rng.permutation(len(demos)), device=device)
        total = 0.0
        for s in range(0, len(perm), cfg.batch_size):
            b = perm[s : s + cfg.batch_size]
            pred = actor.act(o_all[b], g_all[b])
            loss = ((pred - act[b]) ** 2).sum(-1).mean()
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            total += float(loss.detach()) * len(b)
        losses.append(total / len(perm))
        if progress:
            epochs.set_postfix(loss=f"{losses[-1]:.4f}")  # type: ignore[attr-defined]
    payload = {
        "env": cfg.env,
        "robot": robot.name,
        "observation": cfg.observation,
        "n_points": cfg.n_points,
        "obs_shape": list(obs_shape),
        "net": to_dict(cfg.net),
        "bc_config": to_dict(cfg),
        "actor": actor.state_dict(),
        "demo_steps": len(demos),
        "horizon": scenario.horizon,
    }
    save_checkpoint(run_dir / "bc.pt", payload)
    return {"checkpoint": str(run_dir / "bc.pt"), "demo_steps": len(demos), "demo_problems": len(demos.problems), "demo_time_s": t_demos, "train_time_s": time.perf_counter() - t0 - t_demos, "final_loss": losses[-1] if losses else float("nan")}
