"""DAgger: behavioural cloning on the states the policy itself visits.

Plain behavioural cloning only sees states on Bi-RRT's paths; once the policy drifts off
them it meets situations no demonstration covered. Each DAgger round (Ross et al., 2011)
rolls the current policy out on fresh training problems, asks the expert (Bi-RRT, from the
state the policy reached to the goal) what to do at a few states of every failed rollout,
adds those expert paths to the demonstrations and fits the actor again on all of them.
The expert is cheap for the sphere (milliseconds a query), which makes this far cheaper
on a CPU than reinforcement learning with a 256-point PointNet. Validation uses the
``val`` split; ``best.pt`` is the round with the highest validation success (ties: fewer
steps).
"""

from __future__ import annotations

import csv
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ..envs.core import EnvConfig
from ..models.actor_critic import Actor
from ..models.checkpoint import load_checkpoint, save_checkpoint, to_dict
from ..models.policy import Policy
from ..scenes.scenarios import Scenario, make_scenario
from .bc import (
    BCConfig,
    DemoJob,
    Demos,
    demo_pool,
    demos_from_paths,
    fit_actor,
    generate_demos,
    load_demos,
    observation_shape,
    plan_demos,
    policy_payload,
    save_demos,
)


@dataclass(frozen=True)
class DaggerConfig:
    """A DAgger run: the behavioural-cloning settings plus the rounds."""

    bc: BCConfig = field(default_factory=BCConfig)
    #: rounds of roll out, label, refit
    rounds: int = 20
    #: fresh training problems the policy attempts per round
    rollouts: int = field(default=400, metadata={"min": 1})
    #: visited states of each failed rollout that the expert labels (evenly spaced)
    labels_per_failure: int = 4
    #: passes over all demonstrations after each round
    epochs_per_round: float = 2.0
    #: validation problems (``val`` split) after each round
    eval_episodes: int = field(default=200, metadata={"min": 1})
    #: Bi-RRT node budget of the expert
    max_nodes: int = field(default=20000, metadata={"min": 1})
    #: who labels: ``birrt`` (Bi-RRT from the state reached to the goal) or ``slot-threading``
    #: (Slot scenes only: one threading of every slot, :mod:`pointplan.planners.slot_threading`;
    #: it also plans the first demonstrations when there is no demonstrations file), or
    #: ``slot-threading-copies`` (the same with the template's symmetric copies, the one
    #: turned least from the robot: ``SlotThreading(copies=True)``)
    expert: str = field(default="birrt", metadata={"choices": ("birrt", "slot-threading", "slot-threading-copies")})


def _rollout_index(seed: int, rnd: int, rollouts: int, i: int) -> int:
    # training problems apart from the demonstrations' (1e6 + ...) and each other
    return 2_000_000 + seed * 100_000_000 + rnd * rollouts + i


def _label_jobs(cfg: DaggerConfig, scenario: Scenario, rnd: int, results: list[Any]) -> list[DemoJob]:
    """Expert queries at evenly spaced states of every failed rollout."""
    robot_name = scenario.robot.name if scenario.robot.dim == 3 else None
    jobs: list[DemoJob] = []
    for i, res in enumerate(results):
        if res.success or len(res.path) < 1:
            continue
        k = min(cfg.labels_per_failure, len(res.path))
        index = _rollout_index(cfg.bc.seed, rnd, cfg.rollouts, i)
        for j in np.unique(np.linspace(0, len(res.path) - 1, k).round().astype(int)):
            jobs.append((scenario.name, robot_name, "train", index, cfg.bc.seed, index * 100 + int(j), cfg.max_nodes, res.path[j].copy(), 1, 0.0))
    return jobs


class _Log:
    def __init__(self, path: Path) -> None:
        self.path = path

    def write(self, row: dict[str, float]) -> None:
        new = not self.path.exists()
        with self.path.open("a", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(row))
            if new:
                w.writeheader()
            w.writerow(row)


def _validate(policy: Policy, scenario: Scenario, env: EnvConfig, problems: list[Any], seed: int) -> tuple[float, float]:
    from ..planners.rollout import rollout_batch

    res = rollout_batch(policy, scenario.robot, env, problems, scenario.horizon, seed=seed)
    return float(np.mean([r.success for r in res])), float(np.mean([r.nodes for r in res]))


def _resume(path: str | Path, device: str, actor: Actor, opt: torch.optim.Optimizer, rng: np.random.Generator) -> dict[str, Any]:
    """Restore the actor, the optimiser and the random streams of a DAgger ``last.pt``;
    returns its counters (``round``, ``best``, ...)."""
    state = load_checkpoint(path, device)
    actor.load_state_dict(state["actor"])
    d = state["dagger"]
    opt.load_state_dict(d["optimizer"])
    rng.bit_generator.state = d["rng"]
    torch.set_rng_state(d["torch_rng"])
    return dict(d)


def _threading_labels(
    scenario: Scenario, labels: Sequence[tuple[int, int, np.ndarray | None]], progress: bool, desc: str, copies: bool = False
) -> list[tuple[int, np.ndarray]]:
    """The slot threading expert's paths, cut into policy steps, for ``(problem index in the
    training split, planner seed, start or None)``; the unsolved ones are left out. It takes
    milliseconds a query, so it runs here, not in workers."""
    from ..planners.slot_threading import SlotThreading
    from .bc import resample_path

    expert = SlotThreading.load(scenario.robot, copies=copies)
    out = []
    it = labels
    if progress:
        from tqdm import tqdm

        it = tqdm(labels, desc=desc, unit="label")
    for index, seed, start in it:
        problem = scenario.problem("train", index, seed=seed)
        path = expert.plan(problem, start, seed=index)
        if path is not None and len(path) > 1:
            out.append((index, resample_path(scenario.robot, path)))
    return out


def first_demos(cfg: DaggerConfig, scenario: Scenario, demos_path: Path, progress: bool, pool: Any = None) -> Demos:
    """The cloning demonstrations (from ``cfg.bc.demos_file`` when it exists, else planned by
    ``cfg.expert``, Bi-RRT on ``pool`` if given), also written to ``demos_path``."""
    b = cfg.bc
    source = b.demos_file if b.demos_file and Path(b.demos_file).exists() else None
    if source:
        demos = load_demos(source, scenario)
    elif cfg.expert.startswith("slot-threading"):
        from .bc import _demo_index

        jobs = [(_demo_index(b.seed, b.n_problems, i), b.seed, None) for i in range(b.n_problems)]
        paths = _threading_labels(scenario, jobs, progress, "demonstrations", copies=cfg.expert == "slot-threading-copies")
        demos = demos_from_paths(scenario, "train", b.seed, paths)
    else:
        demos = generate_demos(scenario, b.n_problems, b.seed, progress=progress, workers=b.workers, address=b.address, pool=pool)
    save_demos(demos_path, scenario, demos, "train", b.seed)
    return demos


def _save(run_dir: Path, payload: dict[str, Any], counters: dict[str, Any], opt: torch.optim.Optimizer, rng: np.random.Generator, improved: bool) -> None:
    """``last.pt`` with the state to resume from; ``best.pt`` when validation improved."""
    state = {**counters, "optimizer": opt.state_dict(), "rng": rng.bit_generator.state, "torch_rng": torch.get_rng_state()}
    save_checkpoint(run_dir / "last.pt", {**payload, "dagger": state})
    if improved:
        save_checkpoint(run_dir / "best.pt", payload)


def _roll_out_and_label(
    cfg: DaggerConfig, scenario: Scenario, policy: Policy, env: EnvConfig, rnd: int, pool: Any, progress: bool
) -> tuple[list[Any], list[Any]]:
    """Round ``rnd``'s rollouts of the policy on fresh training problems, and the expert's
    paths from states of the failed ones."""
    from ..planners.rollout import rollout_batch

    b = cfg.bc
    probs = [scenario.problem("train", _rollout_index(b.seed, rnd, cfg.rollouts, i), seed=b.seed) for i in range(cfg.rollouts)]
    results = rollout_batch(policy, scenario.robot, env, probs, scenario.horizon, seed=b.seed * 1000 + rnd)
    jobs = _label_jobs(cfg, scenario, rnd, results)
    if cfg.expert.startswith("slot-threading"):
        labels = [(j[3], j[4], j[7]) for j in jobs]
        return results, _threading_labels(scenario, labels, progress, f"round {rnd + 1}: expert labels", copies=cfg.expert == "slot-threading-copies")
    return results, plan_demos(jobs, pool, progress, desc=f"round {rnd + 1}: expert labels")


def _print_round(row: dict[str, Any], best: float) -> None:
    print(
        f"round {row['round']}: rollouts {row['rollout_success']:.3f}, {row['labels']} expert paths, {row['demo_steps']} steps; "
        f"val success {row['val_success']:.3f} (best {best:.3f}), {row['wall_time_s']:.0f} s",
        flush=True,
    )


def train_dagger(
    cfg: DaggerConfig, run_dir: str | Path, progress: bool = True, init_actor: str | None = None, resume: str | Path | None = None, pool: Any = None
) -> dict[str, Any]:
    """Behavioural cloning (from ``init_actor`` if given, else fitted here), then
    ``cfg.rounds`` DAgger rounds; checkpoints ``best.pt`` and ``last.pt`` (resumable) and
    ``metrics.csv`` in ``run_dir``, the aggregated demonstrations in ``demos.npz``. The
    Bi-RRT expert plans on ``pool`` if given (else see :func:`~.bc.demo_pool`)."""
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    b = cfg.bc
    scenario = make_scenario(b.env, robot=b.robot)
    robot = scenario.robot
    env = EnvConfig(observation=b.observation, n_points=b.n_points, split="train")
    rng = np.random.default_rng(b.seed)
    torch.manual_seed(b.seed)
    obs_shape = observation_shape(robot, env)
    actor = Actor(obs_shape, robot.twist_dim, robot.twist_dim, b.net).to(b.device)
    opt = torch.optim.Adam(actor.parameters(), lr=b.lr)
    demos_path = run_dir / "demos.npz"
    start_round, best, best_nodes, wall_before, env_steps = 0, -1.0, float("inf"), 0.0, 0
    if resume is not None:
        d = _resume(resume, b.device, actor, opt, rng)
        start_round, best, best_nodes, wall_before = int(d["round"]), float(d["best"]), float(d["best_nodes"]), float(d["wall_time_s"])
        env_steps = int(d["env_steps"])
        demos = load_demos(demos_path, scenario)
    else:
        demos = first_demos(cfg, scenario, demos_path, progress, pool)
        if init_actor:
            actor.load_state_dict(load_checkpoint(init_actor, b.device)["actor"])
        else:
            fit_actor(actor, opt, demos, robot, env, b.epochs, b.batch_size, rng, b.refresh_every, progress, b.spread_weight)
    policy = Policy(actor, robot, {"observation": b.observation, "n_points": b.n_points}, b.device)
    val_problems = scenario.problems("val", cfg.eval_episodes, seed=b.seed)
    log = _Log(run_dir / "metrics.csv")
    own = pool is None
    if own:
        pool = demo_pool(b.workers, b.address)
    t0 = time.perf_counter()
    try:
        for rnd in range(start_round, cfg.rounds):
            actor.eval()
            results, new = _roll_out_and_label(cfg, scenario, policy, env, rnd, pool, progress)
            env_steps += sum(r.nodes for r in results)
            demos = demos_from_paths(scenario, "train", b.seed, demos.paths + new)
            save_demos(demos_path, scenario, demos, "train", b.seed)
            actor.train()
            losses = fit_actor(actor, opt, demos, robot, env, cfg.epochs_per_round, b.batch_size, rng, 1, progress, b.spread_weight)
            actor.eval()
            val, nodes = _validate(policy, scenario, env, val_problems, b.seed)
            wall = wall_before + time.perf_counter() - t0
            improved = val > best or (val == best and nodes < best_nodes)
            if improved:
                best, best_nodes = val, nodes
            row = {
                "round": rnd + 1,
                "wall_time_s": wall,
                "rollout_success": float(np.mean([r.success for r in results])),
                "labels": len(new),
                "demo_steps": len(demos),
                "val_success": val,
                "val_nodes": nodes,
                "loss": losses[-1],
                "rollout_env_steps": env_steps,
            }
            log.write(row)
            payload = {
                **policy_payload(b, robot.name, obs_shape, actor, scenario.horizon),
                "dagger_config": to_dict(cfg),
                "val_success": val,
                "wall_time_s": wall,
                "round": rnd + 1,
            }
            counters = {"round": rnd + 1, "best": best, "best_nodes": best_nodes, "wall_time_s": wall, "env_steps": env_steps}
            _save(run_dir, payload, counters, opt, rng, improved)
            if progress:
                _print_round(row, best)
    finally:
        if own and pool is not None:
            pool.shutdown(cancel_futures=True)
    return {"run_dir": str(run_dir), "best_success": best, "demo_steps": len(demos), "wall_time_s": wall_before + time.perf_counter() - t0}
