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

import csv
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ..models.checkpoint import save_checkpoint, to_dict
from ..models.cvae import POINT_SPACING, CVAEConfig, LearnedSamplerNet, normalise, pad_cloud, scene_cloud
from ..robots.base import Robot
from ..scenes.scenarios import Scenario, make_scenario
from .bc import Demos, generate_demos, load_demos, save_demos


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


def path_set(demos: Demos, robot: Robot, low: np.ndarray, high: np.ndarray, spacing: float, n_points: int | None = None) -> PathSet:
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


def batch_loss(net: LearnedSamplerNet, batch: tuple[torch.Tensor, ...], k: int, kl_weight: float) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
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
def near_fraction(net: LearnedSamplerNet, data: PathSet, rng: np.random.Generator, n: int = 64, radius: float = 0.1) -> float:
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
        x = net.from_target(y, start.repeat_interleave(n, 0), goal.repeat_interleave(n, 0)).numpy().reshape(len(rows), n, -1)
        for k, r in enumerate(rows):
            path = data.configs[data.offsets[r] : data.offsets[r] + data.counts[r]]
            d = np.min(np.linalg.norm(x[k][:, None] - path[None], axis=-1), axis=1)
            hits.append(float(np.mean(d < radius)))
    return float(np.mean(hits))


def sampler_payload(cfg: LSampleConfig, robot: Robot, net: LearnedSamplerNet, low: np.ndarray, high: np.ndarray, **extra: Any) -> dict[str, Any]:
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


def plan_validation(checkpoint: Path, scenario: Scenario, n: int, seed: int, lams: tuple[float, ...] = (0.5, 0.9)) -> dict[str, dict[str, Any]]:
    """Metrics of the learned-sampling planner at each ``lam`` on validation problems
    ``0..n-1`` (problem seed 0, planner seed ``seed``)."""
    from ..evaluation import evaluate
    from ..planners.learned_sampling import LearnedSamplingPlanner

    problems = scenario.problems("val", n, seed=0)
    out = {}
    for lam in lams:
        planner = LearnedSamplingPlanner(scenario.robot, lam=lam, checkpoint=checkpoint, seed=seed, max_nodes=20000)
        out[f"lsample-{lam:g}"] = evaluate(planner, problems, scenario.robot, progress=False).metrics()
    return out


def _demos(scenario: Scenario, cfg: LSampleConfig, split: str, n: int, file: str | None, progress: bool, pool: Any = None) -> Demos:
    if file and Path(file).exists():
        return load_demos(file, scenario)
    demos = generate_demos(scenario, n, cfg.seed, cfg.max_nodes, progress=progress, split=split, workers=cfg.workers, pool=pool)
    if file:
        save_demos(file, scenario, demos, split, cfg.seed)
    return demos


def train_lsample(cfg: LSampleConfig, run_dir: str | Path, progress: bool = True, pool: Any = None) -> dict[str, Any]:
    """Plan the data (or load it; Bi-RRT on ``pool`` if given), fit the CVAE, select the
    epoch on validation problems; writes ``best.pt``, ``last.pt``, ``metrics.csv`` to
    ``run_dir``. Returns a summary."""
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(1)
    scenario = make_scenario(cfg.env)
    robot = scenario.robot
    low, high = scenario.bounds
    rng = np.random.default_rng(cfg.seed)
    torch.manual_seed(cfg.seed)
    t0 = time.perf_counter()
    train_demos = _demos(scenario, cfg, "train", cfg.n_problems, cfg.demos, progress, pool)
    val_demos = _demos(scenario, cfg, "val", cfg.val_problems, cfg.val_demos, progress, pool)
    t_data = time.perf_counter() - t0
    train = path_set(train_demos, robot, low, high, cfg.path_spacing)
    val = path_set(val_demos, robot, low, high, cfg.path_spacing)
    net = LearnedSamplerNet(cfg.net, robot.dim)
    opt = torch.optim.Adam(net.parameters(), lr=cfg.lr)
    epochs: Any = range(1, cfg.epochs + 1)
    bar = None
    if progress:
        from tqdm import tqdm

        epochs = bar = tqdm(epochs, desc="lsample-train", unit="epoch")
    rows: list[dict[str, Any]] = []
    best: tuple[float, int] | None = None
    t1 = time.perf_counter()
    interrupted = False
    try:
        for ep in epochs:
            perm = rng.permutation(len(train))
            tot, nb = 0.0, 0
            for s in range(0, len(perm), cfg.batch_problems):
                loss, _, _ = batch_loss(net, _batch(train, perm[s : s + cfg.batch_problems], cfg.per_problem, rng), cfg.per_problem, cfg.kl_weight)
                opt.zero_grad(set_to_none=True)
                loss.backward()
                opt.step()
                tot += float(loss.detach())
                nb += 1
            row: dict[str, Any] = {"epoch": ep, "train_loss": tot / max(nb, 1), "train_time_s": time.perf_counter() - t1}
            row.update({f"val_{k}": v for k, v in validation_loss(net, val, cfg).items()})
            if cfg.plan_problems and (ep % cfg.eval_every == 0 or ep == cfg.epochs):
                save_checkpoint(run_dir / "last.pt", sampler_payload(cfg, robot, net, low, high, epoch=ep))
                plans = plan_validation(run_dir / "last.pt", scenario, cfg.plan_problems, cfg.seed)
                for name, m in plans.items():
                    for key in ("success_rate", "nodes_mean", "nodes_median", "collision_checks_mean", "time_mean_s"):
                        row[f"{name}_{key}"] = m[key]
                score = float(plans["lsample-0.9"]["nodes_mean"])
                if best is None or score <= best[0]:
                    best = (score, ep)
                    save_checkpoint(run_dir / "best.pt", sampler_payload(cfg, robot, net, low, high, epoch=ep, val=_plain(row)))
            rows.append(row)
            if bar is not None:
                post = {"loss": f"{row['train_loss']:.4f}", "val": f"{row['val_loss']:.4f}", "near": f"{row['val_near']:.3f}"}
                if best is not None:
                    post["best_nodes_0.9"] = f"{best[0]:.1f}@{best[1]}"
                bar.set_postfix(post)
    except KeyboardInterrupt:
        interrupted = True
        print(f"\ninterrupted after {len(rows)} epochs: keeping them")
    train_time = time.perf_counter() - t1
    last = rows[-1] if rows else {"epoch": 0}
    save_checkpoint(run_dir / "last.pt", sampler_payload(cfg, robot, net, low, high, epoch=int(last["epoch"]), val=_plain(last), train_time_s=train_time))
    if best is None:  # no planning evaluation: the last epoch
        save_checkpoint(run_dir / "best.pt", sampler_payload(cfg, robot, net, low, high, epoch=int(last["epoch"]), val=_plain(last)))
    if rows:
        keys = sorted({k for r in rows for k in r}, key=lambda k: (k != "epoch", k))
        with open(run_dir / "metrics.csv", "w", newline="") as f:
            w = csv.DictWriter(f, keys)
            w.writeheader()
            w.writerows(rows)
    return {
        "run_dir": str(run_dir),
        "best_epoch": best[1] if best else int(last["epoch"]),
        "best_val_nodes_0.9": best[0] if best else None,
        "epochs": len(rows),
        "train_problems": len(train),
        "train_configs": int(train.counts.sum()),
        "val_problems": len(val),
        "data_time_s": t_data,
        "train_time_s": train_time,
        "interrupted": interrupted,
    }


def _plain(row: dict[str, Any]) -> dict[str, Any]:
    return {k: (v.item() if isinstance(v, np.generic) else v) for k, v in row.items()}


__all__ = ["LSampleConfig", "PathSet", "path_set", "plan_validation", "resample_by_length", "sampler_payload", "train_lsample"]
