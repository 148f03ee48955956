"""Training the learned sampler (Ichter, Harrison and Pavone, ICRA 2018): a conditional VAE
(:mod:`pointplan.models.cvae`) fitted to configurations of Bi-RRT solutions.

Data: Bi-RRT (shortcut) solutions of ``n_problems`` training problems, planned as the
behavioural-cloning demonstrations are (:func:`pointplan.learning.bc.generate_demos`; a
``--demos`` file is reused). Each solution is resampled every ``path_spacing`` by arc
length; a batch takes ``batch_problems`` problems and ``per_problem`` configurations drawn
uniformly along each one's solution, so every problem's condition (PointNet on its boundary
points with normals, start, goal) is encoded once per batch.

Model selection uses the validation split only: the loss on Bi-RRT solutions of validation
problems, and every ``eval_every`` epochs the planner itself (``lsample`` at lambda 0.5 and
0.9) on ``plan_problems`` validation problems; ``best.pt`` is the epoch with the fewest
mean nodes at lambda 0.9 (ties: the later epoch), ``last.pt`` the last one.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import torch

from ..models.checkpoint import to_dict
from ..models.cvae import POINT_SPACING, CVAEConfig, LearnedSamplerNet, normalise, pad_cloud, scene_cloud
from ..robots.base import Robot
from ..scenes.scenarios import Scenario, make_scenario
from .bc import Demos, generate_demos, load_demos, save_demos
from .rundir import (
    RunDir,
    epoch_range,
    load_trainer_state,
    optimizer_and_random_state,
    restore_optimizer_and_random_state,
    say_interrupted_early,
)

if TYPE_CHECKING:
    from .bc import DemoPool


@dataclass(frozen=True)
class LSampleConfig:
    """A learned-sampler training run (saved with its checkpoint)."""

    #: scenario (2D-Narrow; the problem's frame is defined in 2D only)
    env: str = "narrow2d"
    #: training problems solved by Bi-RRT for the data
    n_problems: int = field(default=4000, metadata={"min": 1})
    #: validation problems solved by Bi-RRT for the validation loss
    val_problems: int = field(default=500, metadata={"min": 1})
    #: validation problems planned with the sampler (lambda 0.5 and 0.9) to select the epoch; 0: none
    plan_problems: int = 200
    #: passes over the training problems
    epochs: int = field(default=80, metadata={"min": 1})
    #: epochs between two planning evaluations on validation problems
    eval_every: int = field(default=20, metadata={"min": 1})
    #: Adam step size
    lr: float = 1e-3
    #: problems per gradient step
    batch_problems: int = field(default=32, metadata={"min": 1})
    #: configurations drawn along each problem's solution per gradient step
    per_problem: int = field(default=16, metadata={"min": 1})
    #: weight of the KL term (in the units of the CVAE's coordinates: half-distances between start and goal in the problem's frame)
    kl_weight: float = 3e-3
    #: solutions are resampled this far apart (arc length) before configurations are drawn
    path_spacing: float = 0.005
    net: CVAEConfig = field(default_factory=CVAEConfig)
    #: seeds the training problems' draw, the network, the batches and the validation planner
    seed: int = 0
    #: Bi-RRT's node budget for the data
    max_nodes: int = 20000
    #: processes planning the data (Ray when installed); the data equal a serial run's
    workers: int = field(default=1, metadata={"min": 1})
    #: a file of training demonstrations: loaded if it exists, written after planning otherwise
    demos: str | None = None
    #: the same for the validation demonstrations
    val_demos: str | None = None


@dataclass
class PathSet:
    """Solutions resampled by arc length, with each problem's condition."""

    #: ``(P, N, 2 dim)`` boundary points with normals (padded by repetition)
    clouds: np.ndarray
    #: ``(P, 2 dim)`` normalised start and goal
    ends: np.ndarray
    #: ``(M, dim)`` normalised configurations of all resampled solutions
    configs: np.ndarray
    #: ``(P,)`` first row of each problem's configurations, and their count
    offsets: np.ndarray
    counts: np.ndarray

    def __len__(self) -> int:
        return len(self.ends)


def resample_by_length(path: np.ndarray, spacing: float) -> np.ndarray:
    """Points ``spacing`` apart (or a little less) along a polyline, both ends included."""
    seg = np.linalg.norm(np.diff(path, axis=0), axis=-1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    n = max(2, int(np.ceil(cum[-1] / spacing)) + 1)
    s = np.linspace(0.0, cum[-1], n)
    return np.stack([np.interp(s, cum, path[:, k]) for k in range(path.shape[1])], -1)


def path_set(
    demos: Demos, robot: Robot, low: np.ndarray, high: np.ndarray, spacing: float, n_points: int | None = None
) -> PathSet:
    """The data of :func:`train_lsample` from demonstrations (one solution per problem)."""
    if robot.config_dim != robot.dim:
        raise ValueError(f"learned sampling samples positions: robot {robot.name} has orientations")
    problems = demos.problems
    by_index = {int(p.tag.split("/")[2]): p for p in problems} if all(p.tag.count("/") >= 2 for p in problems) else None
    clouds, ends, configs, counts = [], [], [], []
    for k, (index, path) in enumerate(demos.paths):
        p = by_index[index] if by_index is not None else problems[k]
        clouds.append(scene_cloud(p.scene))
        ends.append(normalise(np.stack([p.start, p.goal]), low, high).reshape(-1))
        dense = normalise(resample_by_length(np.asarray(path, np.float64), spacing), low, high)
        configs.append(dense)
        counts.append(len(dense))
    n = n_points or max(len(c) for c in clouds)
    counts_a = np.array(counts, np.int64)
    return PathSet(
        np.stack([pad_cloud(c, n) for c in clouds]).astype(np.float32),
        np.stack(ends).astype(np.float32),
        np.concatenate(configs).astype(np.float32),
        np.concatenate([[0], np.cumsum(counts_a)[:-1]]).astype(np.int64),
        counts_a,
    )


def _batch(data: PathSet, rows: np.ndarray, k: int, rng: np.random.Generator) -> tuple[torch.Tensor, ...]:
    pick = data.offsets[rows, None] + (rng.random((len(rows), k)) * data.counts[rows, None]).astype(np.int64)
    t = torch.from_numpy
    dim = data.configs.shape[1]
    return t(data.clouds[rows]), t(data.ends[rows, :dim]), t(data.ends[rows, dim:]), t(data.configs[pick.reshape(-1)])


def batch_loss(
    net: LearnedSamplerNet, batch: tuple[torch.Tensor, ...], k: int, kl_weight: float
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    clouds, start, goal, x = batch
    c = net.condition(clouds, start, goal).repeat_interleave(k, 0)
    y = net.to_target(x, start.repeat_interleave(k, 0), goal.repeat_interleave(k, 0))
    return net.cvae.loss(y, c, kl_weight)  # type: ignore[no-any-return]


@torch.no_grad()
def validation_loss(net: LearnedSamplerNet, data: PathSet, cfg: LSampleConfig) -> dict[str, float]:
    """Loss, reconstruction and KL on the validation solutions (a fixed draw)."""
    net.eval()
    rng = np.random.default_rng([cfg.seed, 1])
    tot = {"loss": 0.0, "rec": 0.0, "kl": 0.0}
    rows_all = np.arange(len(data))
    for s in range(0, len(data), 256):
        rows = rows_all[s : s + 256]
        loss, rec, kl = batch_loss(net, _batch(data, rows, cfg.per_problem, rng), cfg.per_problem, cfg.kl_weight)
        for key, v in zip(tot, (loss, rec, kl)):
            tot[key] += float(v) * len(rows)
    out = {key: v / len(data) for key, v in tot.items()}
    out["near"] = near_fraction(net, data, rng)
    net.train()
    return out


@torch.no_grad()
def near_fraction(
    net: LearnedSamplerNet, data: PathSet, rng: np.random.Generator, n: int = 64, radius: float = 0.1
) -> float:
    """How many of the decoder's samples (latents from the prior) lie within ``radius``
    (normalised units: 0.05 in the unit square) of their problem's solution, on average
    over the problems of ``data`` (uniform samples: about 15% for a solution 0.75 long)."""
    hits = []
    for s in range(0, len(data), 256):
        rows = np.arange(s, min(s + 256, len(data)))
        clouds, start, goal, _ = _batch(data, rows, 1, rng)
        c = net.condition(clouds, start, goal).repeat_interleave(n, 0)
        z = torch.from_numpy(rng.standard_normal((len(c), net.cvae.latent)).astype(np.float32))
        y = net.cvae.decode(z, c)
        x = (
            net.from_target(y, start.repeat_interleave(n, 0), goal.repeat_interleave(n, 0))
            .numpy()
            .reshape(len(rows), n, -1)
        )
        for k, r in enumerate(rows):
            path = data.configs[data.offsets[r] : data.offsets[r] + data.counts[r]]
            d = np.min(np.linalg.norm(x[k][:, None] - path[None], axis=-1), axis=1)
            hits.append(float(np.mean(d < radius)))
    return float(np.mean(hits))


def sampler_payload(
    cfg: LSampleConfig, robot: Robot, net: LearnedSamplerNet, low: np.ndarray, high: np.ndarray, **extra: Any
) -> dict[str, Any]:
    """What a sampler checkpoint holds (:class:`~pointplan.planners.learned_sampling.LearnedSampler` reads it)."""
    from ..planners.learned_sampling import CHECKPOINT_KIND

    return {
        "kind": CHECKPOINT_KIND,
        "env": cfg.env,
        "robot": robot.name,
        "cvae": to_dict(cfg.net),
        "weights": net.state_dict(),
        "low": [float(x) for x in low],
        "high": [float(x) for x in high],
        "spacing": POINT_SPACING,
        "lsample_config": to_dict(cfg),
        **extra,
    }


def plan_validation(
    checkpoint: Path, scenario: Scenario, n: int, seed: int, lams: tuple[float, ...] = (0.5, 0.9)
) -> dict[str, dict[str, Any]]:
    """Metrics of the learned-sampling planner at each ``lam`` on validation problems
    ``0..n-1`` (problem seed 0, planner seed ``seed``)."""
    from ..evaluation import evaluate
    from ..planners.learned_sampling import LearnedSamplingPlanner

    problems = scenario.problems("val", n, seed=0)
    out = {}
    for lam in lams:
        planner = LearnedSamplingPlanner(scenario.robot, lam=lam, checkpoint=checkpoint, seed=seed, max_nodes=20000)
        report = evaluate(planner, problems, scenario.robot, progress=False)
        if report.interrupted:  # (a second Ctrl-C): a partial validation selects nothing
            raise KeyboardInterrupt
        out[f"lsample-{lam:g}"] = report.metrics()
    return out


def _demos(
    scenario: Scenario,
    cfg: LSampleConfig,
    split: str,
    n: int,
    file: str | None,
    progress: bool,
    pool: DemoPool | None = None,
    keep: Path | None = None,
) -> Demos:
    """The demonstrations of ``split``: ``file``'s if it exists, else planned and written to
    ``file`` (or ``keep``, the run folder's copy a resumed run reads back)."""
    if file and Path(file).exists():
        return load_demos(file, scenario)
    demos = generate_demos(
        scenario, n, cfg.seed, cfg.max_nodes, progress=progress, split=split, workers=cfg.workers, pool=pool
    )
    if file or keep:
        save_demos(file or str(keep), scenario, demos, split, cfg.seed)
    return demos


class _LSampleRun:
    """The data, the network and the counters of a learned-sampler training run (see :func:`train_lsample`)."""

    def __init__(
        self, cfg: LSampleConfig, folder: RunDir, progress: bool, pool: DemoPool | None, resume: str | Path | None
    ) -> None:
        self.cfg, self.folder = cfg, folder
        self.scenario = make_scenario(cfg.env)
        self.robot = self.scenario.robot
        self.low, self.high = self.scenario.bounds
        self.rng = np.random.default_rng(cfg.seed)
        torch.manual_seed(cfg.seed)
        t0 = time.perf_counter()
        keep = {split: folder.path / f"demos_{split}.npz" for split in ("train", "val")}
        files = {
            split: f or (str(keep[split]) if resume is not None and keep[split].exists() else None)
            for split, f in (("train", cfg.demos), ("val", cfg.val_demos))
        }
        train_demos = _demos(self.scenario, cfg, "train", cfg.n_problems, files["train"], progress, pool, keep["train"])
        val_demos = _demos(self.scenario, cfg, "val", cfg.val_problems, files["val"], progress, pool, keep["val"])
        self.data_time = time.perf_counter() - t0
        self.train = path_set(train_demos, self.robot, self.low, self.high, cfg.path_spacing)
        self.val = path_set(val_demos, self.robot, self.low, self.high, cfg.path_spacing)
        self.net = LearnedSamplerNet(cfg.net, self.robot.dim)
        self.opt = torch.optim.Adam(self.net.parameters(), lr=cfg.lr)
        self.rows: list[dict[str, Any]] = []
        self.best: tuple[float, int] | None = None
        self.epoch, self.train_before = 0, 0.0
        if resume is not None:
            self._resume(resume)
        self.t1 = time.perf_counter()

    def _resume(self, path: str | Path) -> None:
        state = load_trainer_state(path, "lsample_trainer", "pointplan lsample-train")
        self.net.load_state_dict(state["weights"])
        t = state["lsample_trainer"]
        restore_optimizer_and_random_state(t, self.opt, self.rng)
        self.epoch, self.train_before = int(t["epoch"]), float(t["train_time_s"])
        self.best = (float(t["best"][0]), int(t["best"][1])) if t["best"] is not None else None
        self.rows = [dict(r) for r in t["rows"]]
        self.folder.metrics.drop_after(self.epoch)

    @property
    def train_time(self) -> float:
        return self.train_before + time.perf_counter() - self.t1

    def payload(self, **extra: Any) -> dict[str, Any]:
        return sampler_payload(self.cfg, self.robot, self.net, self.low, self.high, epoch=self.epoch, **extra)

    def save_last(self, **extra: Any) -> None:
        """``last.pt``: the sampler (a sampler checkpoint) with the trainer state to resume from."""
        state = {
            "epoch": self.epoch,
            **optimizer_and_random_state(self.opt, self.rng),
            "best": list(self.best) if self.best is not None else None,
            "rows": [_plain(r) for r in self.rows],
            "train_time_s": self.train_time,
        }
        self.folder.save("last.pt", {**self.payload(**extra), "lsample_trainer": state})

    def train_epoch(self, ep: int, stop: Callable[[], bool]) -> dict[str, Any] | None:
        """One pass over the training problems; None when ``stop`` ended it early."""
        cfg, train = self.cfg, self.train
        perm = self.rng.permutation(len(train))
        tot, nb = 0.0, 0
        for s in range(0, len(perm), cfg.batch_problems):
            loss, _, _ = batch_loss(
                self.net,
                _batch(train, perm[s : s + cfg.batch_problems], cfg.per_problem, self.rng),
                cfg.per_problem,
                cfg.kl_weight,
            )
            self.opt.zero_grad(set_to_none=True)
            loss.backward()
            self.opt.step()
            tot += float(loss.detach())
            nb += 1
            if stop():
                return None
        self.epoch = ep
        return {"epoch": ep, "train_loss": tot / max(nb, 1), "train_time_s": self.train_time}

    def validate(self, row: dict[str, Any]) -> None:
        """The validation loss; when due, the planner on validation problems (``best.pt``:
        the fewest mean nodes at lambda 0.9, ties to the later epoch)."""
        cfg, ep = self.cfg, int(row["epoch"])
        row.update({f"val_{k}": v for k, v in validation_loss(self.net, self.val, cfg).items()})
        if not cfg.plan_problems or not (ep % cfg.eval_every == 0 or ep == cfg.epochs):
            return
        self.save_last()  # (the planner reads the sampler from a file)
        plans = plan_validation(self.folder.last, self.scenario, cfg.plan_problems, cfg.seed)
        for name, m in plans.items():
            for key in ("success_rate", "nodes_mean", "nodes_median", "collision_checks_mean", "time_mean_s"):
                row[f"{name}_{key}"] = m[key]
        score = float(plans["lsample-0.9"]["nodes_mean"])
        if self.best is None or score <= self.best[0]:
            self.best = (score, ep)
            self.folder.save("best.pt", self.payload(val=_plain(row)))


def train_lsample(
    cfg: LSampleConfig,
    run_dir: str | Path,
    progress: bool = True,
    pool: DemoPool | None = None,
    resume: str | Path | None = None,
) -> dict[str, Any]:
    """Plan the data (or load it; Bi-RRT on ``pool`` if given), fit the CVAE, select the
    epoch on validation problems; writes ``best.pt``, ``last.pt`` (the trainer state, also
    on Ctrl-C; ``resume`` continues from it), ``metrics.csv`` and TensorBoard logs to
    ``run_dir``. Returns a summary."""
    folder = RunDir(run_dir, "pointplan lsample-train")
    torch.set_num_threads(1)
    try:
        run = _LSampleRun(cfg, folder, progress, pool, resume)
    except KeyboardInterrupt:
        say_interrupted_early("planning the demonstrations")
        return {"run_dir": str(folder.path), "epochs": 0, "interrupted": True}
    epochs = epoch_range(run.epoch, cfg.epochs, resume, "lsample-train", progress)
    with folder.ctrl_c() as stop:
        for ep in epochs:
            row = run.train_epoch(ep, stop)
            if row is None:
                break
            run.validate(row)
            run.rows.append(row)
            folder.log(row)
            if progress:
                post = {
                    "loss": f"{row['train_loss']:.4f}",
                    "val": f"{row['val_loss']:.4f}",
                    "near": f"{row['val_near']:.3f}",
                }
                if run.best is not None:
                    post["best_nodes_0.9"] = f"{run.best[0]:.1f}@{run.best[1]}"
                epochs.set_postfix(post, refresh=False)
            if stop():
                break
    if progress:
        epochs.close()
    summary = {
        "run_dir": str(folder.path),
        "epochs": run.epoch,
        "data_time_s": run.data_time,
        "interrupted": run.epoch < cfg.epochs,
    }
    if summary["interrupted"]:
        folder.interrupted(f"in epoch {run.epoch + 1} of {cfg.epochs}", run.save_last)
    else:
        last = run.rows[-1]
        run.save_last(val=_plain(last), train_time_s=run.train_time)
        if run.best is None:  # no planning evaluation: the last epoch
            folder.save("best.pt", run.payload(val=_plain(last)))
    folder.close()
    return {
        **summary,
        "best_epoch": run.best[1] if run.best else run.epoch,
        "best_val_nodes_0.9": run.best[0] if run.best else None,
        "train_problems": len(run.train),
        "train_configs": int(run.train.counts.sum()),
        "val_problems": len(run.val),
        "train_time_s": run.train_time,
    }


def _plain(row: dict[str, Any]) -> dict[str, Any]:
    return {k: (v.item() if isinstance(v, np.generic) else v) for k, v in row.items()}


__all__ = [
    "LSampleConfig",
    "PathSet",
    "path_set",
    "plan_validation",
    "resample_by_length",
    "sampler_payload",
    "train_lsample",
]
