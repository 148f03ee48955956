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

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import torch

from ..envs.core import EnvConfig
from ..models.actor_critic import Actor
from ..models.checkpoint import to_dict
from ..models.inputs import goal_dim
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
    init_actor_state,
    load_demos,
    load_init_actor,
    observation_shape,
    plan_demos,
    policy_payload,
    save_demos,
)
from .rundir import RunDir, best_or_none, load_trainer_state, say_interrupted_early

if TYPE_CHECKING:
    from ..planners.base import PlanResult
    from ..scenes.scene import Problem
    from .bc import DemoPool


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
    #: validation problems (``val`` split): after the cloning, and after each DAgger round
    eval_episodes: int = field(default=200, metadata={"min": 1})
    #: Bi-RRT node budget of the expert (its labels, and the first demonstrations)
    max_nodes: int = field(default=20000, metadata={"min": 1})
    #: who labels: ``birrt`` (Bi-RRT from the state reached to the goal) or ``slot-threading``
    #: (Slot scenes only: one threading of every slot, :mod:`pointplan.planners.slot_threading`;
    #: it also plans the first demonstrations when there is no demonstrations file), or
    #: ``slot-threading-copies`` (the same with the template's symmetric copies, the one
    #: turned least from the robot: ``SlotThreading(copies=True)``), or ``roadmap`` (the
    #: roadmap expert, :mod:`pointplan.learning.roadmap`: one roadmap per rolled-out
    #: workspace, searched once from its goal, so every state gets one label, with the
    #: lookahead of ``scripts/roadmap_demos.py --lookahead``)
    expert: str = field(
        default="birrt", metadata={"choices": ("birrt", "slot-threading", "slot-threading-copies", "roadmap")}
    )
    #: ``expert roadmap``: nodes of each workspace's roadmap
    roadmap_nodes: int = field(default=2000, metadata={"min": 2})
    #: ``expert roadmap``: nearest nodes each node (and each labelled state) is joined to
    roadmap_k: int = field(default=15, metadata={"min": 1})


def _rollout_index(seed: int, rnd: int, rollouts: int, i: int) -> int:
    # training problems apart from the demonstrations' (1e6 + ...) and each other
    return 2_000_000 + seed * 100_000_000 + rnd * rollouts + i


def _label_jobs(cfg: DaggerConfig, scenario: Scenario, rnd: int, results: list[PlanResult]) -> list[DemoJob]:
    """Expert queries at evenly spaced states of every failed rollout."""
    robot_name = scenario.robot.name if scenario.robot.dim == 3 else None
    jobs: list[DemoJob] = []
    for i, res in enumerate(results):
        if res.success or len(res.path) < 1:
            continue
        k = min(cfg.labels_per_failure, len(res.path))
        index = _rollout_index(cfg.bc.seed, rnd, cfg.rollouts, i)
        for j in np.unique(np.linspace(0, len(res.path) - 1, k).round().astype(int)):
            jobs.append(
                (
                    scenario.name,
                    robot_name,
                    "train",
                    index,
                    cfg.bc.seed,
                    index * 100 + int(j),
                    cfg.max_nodes,
                    res.path[j].copy(),
                    1,
                    0.0,
                )
            )
    return jobs


def _validate(
    policy: Policy, scenario: Scenario, env: EnvConfig, problems: list[Problem], seed: int
) -> tuple[float, float]:
    from ..planners.rollout import rollout_batch

    res = rollout_batch(policy, scenario.robot, env, problems, scenario.horizon, seed=seed)
    return float(np.mean([r.success for r in res])), float(np.mean([r.nodes for r in res]))


def _threading_labels(
    scenario: Scenario,
    labels: Sequence[tuple[int, int, np.ndarray | None]],
    progress: bool,
    desc: str,
    copies: bool = False,
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
        from ..progress import progress_bar

        it = progress_bar(labels, desc=desc, unit="label")
    for index, seed, start in it:
        problem = scenario.problem("train", index, seed=seed)
        path = expert.plan(problem, start, seed=index)
        if path is not None and len(path) > 1:
            out.append((index, resample_path(scenario.robot, path)))
    return out


def _roadmap_labels(
    cfg: DaggerConfig,
    scenario: Scenario,
    jobs: Sequence[DemoJob],
    progress: bool,
    desc: str,
    stop: Callable[[], bool] = lambda: False,
) -> list[tuple[int, np.ndarray]]:
    """The roadmap expert's paths from the states of ``jobs`` (grouped by problem: one
    roadmap and one search per workspace), cut into policy steps; ``stop`` is asked after
    each workspace (Ctrl-C: the round is played again on resume)."""
    from .roadmap import label_states

    by_problem: dict[int, list[np.ndarray]] = {}
    for job in jobs:
        by_problem.setdefault(int(job[3]), []).append(np.asarray(job[7], np.float64))
    items = list(by_problem.items())
    if progress:
        from ..progress import progress_bar

        items = progress_bar(items, desc=desc, unit="workspace")
    out: list[tuple[int, np.ndarray]] = []
    for index, states in items:
        if stop():
            break
        paths = label_states(
            scenario, "train", cfg.bc.seed, index, states, cfg.roadmap_nodes, cfg.roadmap_k, rng_seed=cfg.bc.seed
        )
        out.extend((index, path) for path in paths)
    return out


def _roadmap_demos(cfg: DaggerConfig, scenario: Scenario, progress: bool) -> Demos:
    """The roadmap expert's demonstrations of the cloning problems (those Bi-RRT would
    plan), as ``scripts/roadmap_demos.py --lookahead`` builds them (20 paths from roadmap
    nodes per problem besides the start's)."""
    from .roadmap import demo_problem_indices, roadmap_demos

    b = cfg.bc
    indices = demo_problem_indices(b.seed, b.n_problems)
    bar = None
    if progress:
        from ..progress import progress_bar

        bar = progress_bar(total=len(indices), desc="roadmap demonstrations", unit="problem")
    paths = roadmap_demos(
        scenario,
        "train",
        b.seed,
        indices,
        cfg.roadmap_nodes,
        cfg.roadmap_k,
        20,
        rng_seed=b.seed,
        ahead=True,
        on_problem=(lambda *_: bar.update()) if bar is not None else None,
    )
    if bar is not None:
        bar.close()
    return demos_from_paths(scenario, "train", b.seed, paths)


def first_demos(
    cfg: DaggerConfig, scenario: Scenario, demos_path: Path, progress: bool, pool: DemoPool | None = None
) -> Demos:
    """The cloning demonstrations (from ``cfg.bc.demos_file`` when it exists, else planned by
    ``cfg.expert``, Bi-RRT on ``pool`` if given), also written to ``demos_path``."""
    b = cfg.bc
    source = b.demos_file if b.demos_file and Path(b.demos_file).exists() else None
    if source:
        demos = load_demos(source, scenario)
    elif cfg.expert.startswith("slot-threading"):
        from .bc import _demo_index

        jobs = [(_demo_index(b.seed, b.n_problems, i), b.seed, None) for i in range(b.n_problems)]
        paths = _threading_labels(
            scenario, jobs, progress, "demonstrations", copies=cfg.expert == "slot-threading-copies"
        )
        demos = demos_from_paths(scenario, "train", b.seed, paths)
    elif cfg.expert == "roadmap":
        demos = _roadmap_demos(cfg, scenario, progress)
    else:
        demos = generate_demos(
            scenario, b.n_problems, b.seed, progress=progress, workers=b.workers, address=b.address, pool=pool
        )
    save_demos(demos_path, scenario, demos, "train", b.seed)
    return demos


def _roll_out_and_label(
    cfg: DaggerConfig,
    scenario: Scenario,
    policy: Policy,
    env: EnvConfig,
    rnd: int,
    pool: DemoPool | None,
    progress: bool,
    stop: Callable[[], bool] = lambda: False,
) -> tuple[list[PlanResult], list[tuple[int, np.ndarray]]]:
    """Round ``rnd``'s rollouts of the policy on fresh training problems, and the expert's
    paths from states of the failed ones."""
    from ..planners.rollout import rollout_batch

    b = cfg.bc
    probs = [
        scenario.problem("train", _rollout_index(b.seed, rnd, cfg.rollouts, i), seed=b.seed)
        for i in range(cfg.rollouts)
    ]
    results = rollout_batch(policy, scenario.robot, env, probs, scenario.horizon, seed=b.seed * 1000 + rnd)
    jobs = _label_jobs(cfg, scenario, rnd, results)
    if cfg.expert.startswith("slot-threading"):
        labels = [(j[3], j[4], j[7]) for j in jobs]
        return results, _threading_labels(
            scenario, labels, progress, f"round {rnd + 1}: expert labels", copies=cfg.expert == "slot-threading-copies"
        )
    if cfg.expert == "roadmap":
        return results, _roadmap_labels(cfg, scenario, jobs, progress, f"round {rnd + 1}: roadmap labels", stop)
    return results, plan_demos(jobs, pool, progress, desc=f"round {rnd + 1}: expert labels")


def _print_round(row: dict[str, Any], best: float) -> None:
    print(
        f"round {row['round']}: rollouts {row['rollout_success']:.3f}, {row['labels']} expert paths, {row['demo_steps']} steps; "
        f"val success {row['val_success']:.3f} (best {best:.3f}), {row['wall_time_s']:.0f} s",
        flush=True,
    )


class _DaggerRun:
    """The pieces of a DAgger run and its counters (built by :func:`train_dagger`)."""

    def __init__(
        self,
        cfg: DaggerConfig,
        folder: RunDir,
        progress: bool,
        init_actor: str | None,
        resume: str | Path | None,
        pool: DemoPool | None,
    ) -> None:
        b = cfg.bc
        self.cfg, self.folder = cfg, folder
        self.scenario = make_scenario(b.env, robot=b.robot)
        self.robot = self.scenario.robot
        self.env = EnvConfig(observation=b.observation, n_points=b.n_points, split="train")
        self.rng = np.random.default_rng(b.seed)
        torch.manual_seed(b.seed)
        self.obs_shape = observation_shape(self.robot, self.env)
        self.actor = Actor(self.obs_shape, goal_dim(self.robot), self.robot.twist_dim, b.net).to(b.device)
        self.opt = torch.optim.Adam(self.actor.parameters(), lr=b.lr)
        self.demos_path = folder.path / "demos.npz"
        self.round, self.best, self.best_nodes, self.wall_before, self.env_steps = 0, -1.0, float("inf"), 0.0, 0
        self.clone_losses: list[float] = []
        self.clone_done = bool(init_actor)
        if resume is not None:
            self._resume(resume)
            self.demos = load_demos(self.demos_path, self.scenario)
            folder.metrics.drop_after(self.round)
        else:
            self.demos = first_demos(cfg, self.scenario, self.demos_path, progress, pool)
            if init_actor:
                load_init_actor(self.actor, init_actor_state(init_actor, b.device), init_actor)
        self.policy = Policy(self.actor, self.robot, {"observation": b.observation, "n_points": b.n_points}, b.device)
        self.val_problems = self.scenario.problems("val", cfg.eval_episodes, seed=b.seed)
        self.t0 = time.perf_counter()

    def _resume(self, path: str | Path) -> None:
        """Restore the actor, the optimiser, the random streams and the counters of a DAgger ``last.pt``."""
        state = load_trainer_state(path, "dagger", "pointplan bc", self.cfg.bc.device)
        self.actor.load_state_dict(state["actor"])
        d = state["dagger"]
        self.opt.load_state_dict(d["optimizer"])
        self.rng.bit_generator.state = d["rng"]
        torch.set_rng_state(d["torch_rng"])
        self.round, self.best, self.best_nodes = int(d["round"]), float(d["best"]), float(d["best_nodes"])
        self.wall_before, self.env_steps = float(d["wall_time_s"]), int(d["env_steps"])
        self.clone_losses = [float(x) for x in d.get("clone_losses", [])]
        self.clone_done = bool(d.get("clone_done", True))  # (runs saved before this was kept had cloned)

    @property
    def wall(self) -> float:
        return self.wall_before + time.perf_counter() - self.t0

    def clone(self, progress: bool, stop: Callable[[], bool]) -> None:
        """The behavioural cloning the rounds start from (what is left of it on resume)."""
        b = self.cfg.bc
        if not self.clone_done:
            self.actor.train()
            fit_actor(
                self.actor,
                self.opt,
                self.demos,
                self.robot,
                self.env,
                b.epochs,
                b.batch_size,
                self.rng,
                b.refresh_every,
                progress,
                b.spread_weight,
                self.clone_losses,
                stop,
            )
            self.clone_done = len(self.clone_losses) >= b.epochs

    def play_round(
        self, rnd: int, pool: DemoPool | None, progress: bool, stop: Callable[[], bool]
    ) -> dict[str, Any] | None:
        """Round ``rnd``: roll out, label, refit, validate, log and save; None when ``stop``
        ended it early (the round is played again on resume)."""
        cfg, b = self.cfg, self.cfg.bc
        self.actor.eval()
        results, new = _roll_out_and_label(cfg, self.scenario, self.policy, self.env, rnd, pool, progress, stop)
        if stop():
            return None
        self.demos = demos_from_paths(self.scenario, "train", b.seed, self.demos.paths + new)
        save_demos(self.demos_path, self.scenario, self.demos, "train", b.seed)
        self.actor.train()
        losses = fit_actor(
            self.actor,
            self.opt,
            self.demos,
            self.robot,
            self.env,
            cfg.epochs_per_round,
            b.batch_size,
            self.rng,
            1,
            progress,
            b.spread_weight,
            None,
            stop,
        )
        if stop():
            return None
        self.actor.eval()
        val, nodes = _validate(self.policy, self.scenario, self.env, self.val_problems, b.seed)
        improved = val > self.best or (val == self.best and nodes < self.best_nodes)
        if improved:
            self.best, self.best_nodes = val, nodes
        self.round, self.env_steps = rnd + 1, self.env_steps + sum(r.nodes for r in results)
        row = {
            "round": rnd + 1,
            "wall_time_s": self.wall,
            "rollout_success": float(np.mean([r.success for r in results])),
            "labels": len(new),
            "demo_steps": len(self.demos),
            "val_success": val,
            "val_nodes": nodes,
            "loss": losses[-1],
            "rollout_env_steps": self.env_steps,
        }
        self.folder.log(row)
        self.save({"val_success": val}, improved)
        return row

    def save(self, extra: dict[str, Any], improved: bool = False) -> None:
        """``last.pt`` with the state to resume from; ``best.pt`` when validation improved."""
        wall = self.wall
        payload = {
            **policy_payload(self.cfg.bc, self.robot.name, self.obs_shape, self.actor, self.scenario.horizon),
            "dagger_config": to_dict(self.cfg),
            **extra,
            "wall_time_s": wall,
            "round": self.round,
        }
        counters = {
            "round": self.round,
            "best": self.best,
            "best_nodes": self.best_nodes,
            "wall_time_s": wall,
            "env_steps": self.env_steps,
        }
        clone = {"clone_losses": list(self.clone_losses), "clone_done": self.clone_done}
        state = {
            **counters,
            **clone,
            "optimizer": self.opt.state_dict(),
            "rng": self.rng.bit_generator.state,
            "torch_rng": torch.get_rng_state(),
        }
        self.folder.save("last.pt", {**payload, "dagger": state})
        if improved:
            self.folder.save("best.pt", payload)


def train_dagger(
    cfg: DaggerConfig,
    run_dir: str | Path,
    progress: bool = True,
    init_actor: str | None = None,
    resume: str | Path | None = None,
    pool: DemoPool | None = None,
) -> dict[str, Any]:
    """Behavioural cloning (from ``init_actor`` if given, else fitted here), then
    ``cfg.rounds`` DAgger rounds; checkpoints ``best.pt`` and ``last.pt`` (resumable, also
    after Ctrl-C), ``metrics.csv`` and TensorBoard logs in ``run_dir``, the aggregated
    demonstrations in ``demos.npz``. The Bi-RRT expert plans on ``pool`` if given (else see
    :func:`~.bc.demo_pool`)."""
    folder = RunDir(run_dir, "pointplan bc")
    try:
        run = _DaggerRun(cfg, folder, progress, init_actor, resume, pool)
    except KeyboardInterrupt:
        say_interrupted_early("planning the demonstrations")
        return {"run_dir": str(folder.path), "best_success": None, "interrupted": True}
    own = pool is None
    if own:
        pool = demo_pool(cfg.bc.workers, cfg.bc.address)
    try:
        with folder.ctrl_c() as stop:
            run.clone(progress, stop)
            for rnd in range(run.round, cfg.rounds):
                row = None if stop() else run.play_round(rnd, pool, progress, stop)
                if row is None:
                    break
                if progress:
                    _print_round(row, run.best)
    finally:
        if own and pool is not None:
            pool.shutdown(cancel_futures=True)
    # (not when it came after the last round)
    interrupted = stop.requested and not (run.clone_done and run.round >= cfg.rounds)
    if interrupted:
        where = (
            f"in round {run.round + 1} of {cfg.rounds}"
            if run.clone_done
            else f"while cloning, in epoch {len(run.clone_losses) + 1} of {cfg.bc.epochs}"
        )
        folder.interrupted(where, lambda: run.save({}))
    folder.close()
    summary = {
        "run_dir": str(folder.path),
        "best_success": best_or_none(run.best),
        "demo_steps": len(run.demos),
        "wall_time_s": run.wall,
    }
    return {**summary, "interrupted": interrupted}
