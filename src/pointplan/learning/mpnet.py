"""Training MPNet (Qureshi et al. 2019) on Bi-RRT paths of the training split.

Data. Bi-RRT solutions (shortcut) of training problems (2D-Narrow with the disc, or a 3D
scenario with the sphere: the shipped 3D network is trained on 3D-Boxes), as behavioural cloning plans them
(:func:`pointplan.learning.bc.generate_demos`, one problem per training workspace). Those
come cut into policy steps; the shortcut path's own vertices are recovered (consecutive
collinear pieces merged) and every segment is cut again into equal pieces no longer than
``waypoint_step`` (0: the vertices alone, as in MPNet's paths). Each path is used in both
directions. A sample is a waypoint ``w_i``, the next one ``w_{i+1}`` and a goal: the path's
end, or with probability ``subgoal_prob`` a later waypoint drawn anew every epoch (the
planner asks the network for the way to the end of the *other* chain, not only to the goal).

Loss. Mean squared error between the network's displacement and ``(w_{i+1} - w_i) / step``
(the next configuration in units of one step, 0.07), dropout on (as MPNet trains and plans);
Adam, with the step size decaying along a cosine from ``lr`` to ``lr * lr_end``.
A batch is ``paths_per_batch`` paths with all their samples, so the encoder runs once per
workspace of the batch on the workspace's whole point set.

Model selection. Every ``eval_every`` epochs the neural planner (``mpnet-nr``) plans
``val_problems`` problems of the validation split, checked by the evaluator; the epoch with
the best success (then the lowest validation loss, on Bi-RRT paths of validation problems)
is kept as ``best.pt``. It is evaluated once, at the end, on ``test_problems`` test problems,
as ``mpnet-nr`` and ``mpnet-hr``.
"""

from __future__ import annotations

import copy
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import torch

from ..evaluation import evaluate
from ..models.checkpoint import to_dict
from ..models.mpnet import (
    OBSERVATION_3D,
    MPNet,
    MPNetModel,
    MPNetNetConfig,
    check_translating,
    default_observation,
    encoder_input,
    mpnet_payload,
    scale_positions,
)
from ..planners.mpnet import MPNetPlanner, scene_points
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
class MPNetTrainConfig:
    """An MPNet training run (saved with its checkpoints)."""

    env: str = "narrow2d"
    #: the robot (None: the scenario's default; in 3D only the sphere, ``sphere3d``, translates)
    robot: str | None = None
    #: 3D: area-weighted surface points per workspace the encoder reads (the global observer's pool)
    n_points: int = field(default=512, metadata={"min": 1})
    #: training problems planned by Bi-RRT (one per training workspace)
    n_problems: int = field(default=4000, metadata={"min": 1})
    #: a file of training demonstrations: loaded if it exists, written after planning otherwise
    demos_file: str | None = None
    #: validation problems planned by Bi-RRT for the validation loss
    val_demo_problems: int = field(default=200, metadata={"min": 1})
    #: a file of validation demonstrations (as demos_file)
    val_demos_file: str | None = None
    #: validation problems the neural planner plans for model selection
    val_problems: int = field(default=200, metadata={"min": 1})
    #: test problems the best model plans once at the end (mpnet-nr and mpnet-hr; 0: none)
    test_problems: int = 400
    #: longest waypoint spacing along the training paths (0: the shortcut paths' vertices only)
    waypoint_step: float = 0.07
    #: probability that a sample's goal is a later waypoint of its path instead of its end
    subgoal_prob: float = 0.5
    #: passes over the training paths
    epochs: int = field(default=30, metadata={"min": 1})
    #: Adam step size
    lr: float = 1e-3
    #: the step size decays along a cosine to this fraction of lr at the last epoch (1: constant)
    lr_end: float = 0.05
    #: paths per gradient step (all their samples, both directions)
    paths_per_batch: int = field(default=16, metadata={"min": 1})
    #: validate every this many epochs (and after the last)
    eval_every: int = field(default=5, metadata={"min": 1})
    #: Bi-RRT node budget of the hybrid planner in the final test
    max_nodes: int = field(default=20000, metadata={"min": 1})
    net: MPNetNetConfig = field(default_factory=MPNetNetConfig)
    #: workers planning the demonstrations (Ray when installed, else processes)
    workers: int = field(default=1, metadata={"min": 1})
    seed: int = 0


# ---------------------------------------------------------------------------- data
def path_vertices(path: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    """The vertices of a piecewise-straight path given with extra points along its segments:
    repeated points dropped, then interior points where the path goes straight on."""
    path = np.asarray(path, np.float64)
    keep = np.concatenate([[True], np.linalg.norm(np.diff(path, axis=0), axis=1) > tol])
    path = path[keep]
    if len(path) < 3:
        return path
    d = np.diff(path, axis=0)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    straight = np.einsum("ij,ij->i", d[:-1], d[1:]) > 1.0 - tol
    return path[np.concatenate([[True], ~straight, [True]])]


def cut_path(path: np.ndarray, step: float) -> np.ndarray:
    """Every segment cut into equal pieces no longer than ``step`` (``step <= 0``: as is)."""
    path = np.asarray(path, np.float64)
    if step <= 0 or len(path) < 2:
        return path
    out = [path[:1]]
    for a, b in zip(path[:-1], path[1:]):
        k = max(1, int(np.ceil(np.linalg.norm(b - a) / step - 1e-9)))
        out.append(a + (b - a) * (np.arange(1, k + 1) / k)[:, None])
    return np.concatenate(out)


@dataclass
class PathSet:
    """Directed waypoint paths (both directions of each demonstration) and their scenes'
    encoder inputs, ready for batches."""

    #: encoder inputs per demonstration ``(D, P, F)`` float32 (padded by duplicates)
    points: torch.Tensor
    #: waypoints of all directed paths, concatenated ``(W, dim)``
    waypoints: np.ndarray
    #: per directed path: first waypoint, number of waypoints, demonstration index
    offset: np.ndarray
    length: np.ndarray
    demo: np.ndarray

    @property
    def n_demos(self) -> int:
        return int(self.points.shape[0])


def make_path_set(
    demos: Demos,
    robot: Robot,
    center: np.ndarray,
    step: float,
    waypoint_step: float,
    observation: str | None = None,
    n_points: int = 0,
) -> PathSet:
    """The training (or validation) paths of ``demos``."""
    ins: list[np.ndarray] = []
    wps: list[np.ndarray] = []
    offset, length, demo = [], [], []
    at = 0
    # demos.problems holds the problems in the order their indices first appear in demos.paths
    unique = list(dict.fromkeys(index for index, _ in demos.paths))
    problem_of = dict(zip(unique, demos.problems))
    for d, (index, steps) in enumerate(demos.paths):
        problem = problem_of[index]
        pts, nrm = scene_points(robot, problem.scene, observation, n_points)
        ins.append(encoder_input(pts, nrm, center, step))
        w = cut_path(path_vertices(steps), waypoint_step)
        for seq in (w, w[::-1]):
            wps.append(seq)
            offset.append(at)
            length.append(len(seq))
            demo.append(d)
            at += len(seq)
    pmax = max(len(x) for x in ins)
    padded = np.stack([np.concatenate([x, np.repeat(x[:1], pmax - len(x), 0)]) for x in ins]).astype(np.float32)
    return PathSet(torch.as_tensor(padded), np.concatenate(wps), np.array(offset), np.array(length), np.array(demo))


def batch_samples(
    ps: PathSet, demos_idx: np.ndarray, rng: np.random.Generator | None, subgoal_prob: float
) -> tuple[np.ndarray, ...]:
    """Samples of the directed paths of demonstrations ``demos_idx``: current, next, goal
    waypoint indices and the batch-local scene index. ``rng is None``: every goal is the end."""
    local = {int(d): k for k, d in enumerate(demos_idx)}
    rows = np.flatnonzero(np.isin(ps.demo, demos_idx))
    cur, goal, scene = [], [], []
    for r in rows:
        o, n = int(ps.offset[r]), int(ps.length[r])
        i = np.arange(n - 1)
        g = np.full(n - 1, n - 1)
        if rng is not None and subgoal_prob > 0:
            sub = rng.random(n - 1) < subgoal_prob
            later = i + 1 + (rng.random(n - 1) * (n - 1 - i)).astype(np.int64)  # uniform in i+1 .. n-1
            g = np.where(sub, later, g)
        cur.append(o + i)
        goal.append(o + g)
        scene.append(np.full(n - 1, local[int(ps.demo[r])]))
    c = np.concatenate(cur)
    return c, c + 1, np.concatenate(goal), np.concatenate(scene)


def batch_loss(
    model: MPNetModel,
    ps: PathSet,
    demos_idx: np.ndarray,
    center: np.ndarray,
    step: float,
    rng: np.random.Generator | None,
    subgoal_prob: float,
) -> tuple[torch.Tensor, int]:
    """Mean squared error (sum over coordinates) of the batch; and its number of samples."""
    cur, nxt, goal, scene = batch_samples(ps, demos_idx, rng, subgoal_prob)
    z = model.encode(ps.points[torch.as_tensor(demos_idx)])
    q = ps.waypoints[cur]
    target = torch.as_tensor(((ps.waypoints[nxt] - q) / step).astype(np.float32))
    pred = model(
        z[torch.as_tensor(scene)],
        torch.as_tensor(scale_positions(q, center, step)),
        torch.as_tensor(scale_positions(ps.waypoints[goal], center, step)),
    )
    return ((pred - target) ** 2).sum(-1).mean(), len(cur)


def validation_loss(model: MPNetModel, ps: PathSet, center: np.ndarray, step: float, per_batch: int = 64) -> float:
    """Mean loss over every sample of ``ps`` (goal: each path's end; dropout off)."""
    model.eval()
    total, n = 0.0, 0
    with torch.inference_mode():
        for s in range(0, ps.n_demos, per_batch):
            loss, k = batch_loss(model, ps, np.arange(s, min(s + per_batch, ps.n_demos)), center, step, None, 0.0)
            total += float(loss) * k
            n += k
    model.train()
    return total / max(n, 1)


def _demos(
    scenario: Scenario,
    n: int,
    split: str,
    path: str | None,
    cfg: MPNetTrainConfig,
    progress: bool,
    pool: DemoPool | None = None,
    keep: Path | None = None,
) -> Demos:
    """The demonstrations of ``split``: ``path``'s if it exists, else planned and written to
    ``path`` (or ``keep``, the run folder's copy a resumed run reads back)."""
    if path and Path(path).exists():
        with np.load(path, allow_pickle=False) as f:
            if str(f["split"]) != split:
                raise ValueError(f"{path}: demonstrations of the {f['split']} split, not {split}")
        return load_demos(path, scenario)
    demos = generate_demos(scenario, n, cfg.seed, progress=progress, split=split, workers=cfg.workers, pool=pool)
    if path or keep:
        save_demos(path or str(keep), scenario, demos, split, cfg.seed)
    return demos


@dataclass
class MPNetTrainResult:
    """What :func:`train_mpnet` returns."""

    run_dir: Path
    best_epoch: int
    best_val: dict[str, float]
    history: list[dict[str, float]]
    test: dict[str, dict[str, Any]]
    demo_time_s: float
    train_time_s: float
    summary: dict[str, Any] = field(default_factory=dict)
    #: stopped by Ctrl-C (the trainer state is in ``last.pt``; no test ran)
    interrupted: bool = False


class _MPNetRun:
    """The data, the network and the counters of an MPNet training run (see :func:`train_mpnet`)."""

    def __init__(
        self, cfg: MPNetTrainConfig, folder: RunDir, progress: bool, pool: DemoPool | None, resume: str | Path | None
    ) -> None:
        self.cfg, self.folder = cfg, folder
        torch.manual_seed(cfg.seed)
        self.rng = np.random.default_rng(np.random.SeedSequence([cfg.seed, 0x3B9E7]))
        self.scenario = make_scenario(cfg.env, robot=cfg.robot)
        robot = self.robot = self.scenario.robot
        check_translating(robot)
        self.observation = default_observation(robot)
        self.n_points = int(cfg.n_points) if self.observation == OBSERVATION_3D else 0
        low, high = self.scenario.bounds
        self.center = (np.asarray(low) + np.asarray(high)) / 2
        self.step = float(robot.action_scale[0])
        t0 = time.perf_counter()
        self.train_demos = self._demos(cfg.n_problems, "train", cfg.demos_file, progress, pool, resume is not None)
        val_demos = self._demos(cfg.val_demo_problems, "val", cfg.val_demos_file, progress, pool, resume is not None)
        self.train_set = make_path_set(
            self.train_demos, robot, self.center, self.step, cfg.waypoint_step, self.observation, self.n_points
        )
        self.val_set = make_path_set(
            val_demos, robot, self.center, self.step, cfg.waypoint_step, self.observation, self.n_points
        )
        self.val_problems = self.scenario.problems("val", cfg.val_problems, seed=cfg.seed)
        self.demo_time = time.perf_counter() - t0
        self.model = MPNetModel(robot.dim, 2 * robot.dim, cfg.net)
        self.opt = torch.optim.Adam(self.model.parameters(), lr=cfg.lr)
        self.sched = torch.optim.lr_scheduler.LambdaLR(
            self.opt,
            lambda e: (
                cfg.lr_end
                + (1.0 - cfg.lr_end) * 0.5 * (1.0 + float(np.cos(np.pi * min(e / max(cfg.epochs - 1, 1), 1.0))))
            ),
        )
        self.extra = {
            "train_config": to_dict(cfg),
            "demo_problems": len(self.train_demos.paths),
            "waypoints": int(len(self.train_set.waypoints)),
        }
        self.history: list[dict[str, float]] = []
        self.best: tuple[float, float] | None = None
        self.best_val: dict[str, float] = {}
        self.best_epoch, self.epoch, self.train_before = 0, 0, 0.0
        if resume is not None:
            self._resume(resume)
        self.t1 = time.perf_counter()

    def _demos(
        self, n: int, split: str, path: str | None, progress: bool, pool: DemoPool | None, resumed: bool
    ) -> Demos:
        keep = self.folder.path / f"demos_{split}.npz"
        if not path and resumed and keep.exists():  # planned by the run resumed
            path = str(keep)
        return _demos(self.scenario, n, split, path, self.cfg, progress, pool, keep)

    def _resume(self, path: str | Path) -> None:
        state = load_trainer_state(path, "mpnet_trainer", "pointplan mpnet-train")
        self.model.load_state_dict(state["model"])
        t = state["mpnet_trainer"]
        restore_optimizer_and_random_state(t, self.opt, self.rng)
        self.sched.load_state_dict(t["scheduler"])
        self.epoch, self.best_epoch, self.train_before = int(t["epoch"]), int(t["best_epoch"]), float(t["train_time_s"])
        self.best = (float(t["best"][0]), float(t["best"][1])) if t["best"] is not None else None
        self.best_val, self.history = dict(t["best_val"]), [dict(r) for r in t["history"]]
        self.folder.metrics.drop_after(self.epoch)

    @property
    def train_time(self) -> float:
        return self.train_before + time.perf_counter() - self.t1

    def snapshot(self) -> MPNet:
        return MPNet(
            copy.deepcopy(self.model).eval(), self.robot, self.center, self.step, {}, self.observation, self.n_points
        )

    def train_epoch(self, ep: int, stop: Callable[[], bool]) -> dict[str, float] | None:
        """One pass over the training paths; None when ``stop`` ended it early."""
        cfg = self.cfg
        self.model.train()
        order = self.rng.permutation(self.train_set.n_demos)
        total, n = 0.0, 0
        for s in range(0, len(order), cfg.paths_per_batch):
            loss, k = batch_loss(
                self.model,
                self.train_set,
                order[s : s + cfg.paths_per_batch],
                self.center,
                self.step,
                self.rng,
                cfg.subgoal_prob,
            )
            self.opt.zero_grad(set_to_none=True)
            loss.backward()
            self.opt.step()
            total += float(loss.detach()) * k
            n += k
            if stop():
                return None
        row: dict[str, float] = {
            "epoch": ep,
            "lr": float(self.opt.param_groups[0]["lr"]),
            "train_loss": total / max(n, 1),
            "time_s": self.train_time,
        }
        self.sched.step()
        self.epoch = ep
        return row

    def validate(self, row: dict[str, float]) -> None:
        """The validation loss and the neural planner on validation problems; ``best.pt``
        when the epoch is the best so far (success, then validation loss)."""
        row["val_loss"] = validation_loss(self.model, self.val_set, self.center, self.step)
        report = evaluate(
            MPNetPlanner(self.snapshot(), self.robot, seed=self.cfg.seed), self.val_problems, self.robot, progress=False
        )
        if report.interrupted:  # (a second Ctrl-C): a partial validation selects nothing
            raise KeyboardInterrupt
        m = report.metrics()
        row.update(
            val_success=m["success_rate"],
            val_nodes=m["nodes_mean"],
            val_checks=m["collision_checks_mean"],
            val_path_length=m["path_length_mean"],
        )
        key = (row["val_success"], -row["val_loss"])
        if self.best is None or key > self.best:
            self.best, self.best_epoch, self.best_val = key, int(row["epoch"]), dict(row)
            self.folder.save("best.pt", self.payload(val={k: float(v) for k, v in row.items()}))

    def payload(self, **extra: Any) -> dict[str, Any]:
        return mpnet_payload(
            self.model,
            self.scenario.name,
            self.robot,
            self.center,
            self.step,
            self.observation,
            self.n_points,
            epoch=self.epoch,
            **self.extra,
            **extra,
        )

    def save_last(self, **extra: Any) -> None:
        """``last.pt``: the network (an MPNet checkpoint) with the trainer state to resume from."""
        state = {
            "epoch": self.epoch,
            **optimizer_and_random_state(self.opt, self.rng),
            "scheduler": self.sched.state_dict(),
            "best": list(self.best) if self.best is not None else None,
            "best_epoch": self.best_epoch,
            "best_val": _plain(self.best_val),
            "history": [_plain(r) for r in self.history],
            "train_time_s": self.train_time,
        }
        self.folder.save("last.pt", {**self.payload(**extra), "mpnet_trainer": state})

    def test(self, progress: bool) -> dict[str, dict[str, Any]]:
        """The best model on the test problems, as mpnet-nr and mpnet-hr."""
        out: dict[str, dict[str, Any]] = {}
        if self.cfg.test_problems > 0:
            best_net = MPNet.from_checkpoint(self.folder.path / "best.pt")
            problems = self.scenario.problems("test", self.cfg.test_problems, seed=self.cfg.seed)
            for hybrid in (False, True):
                planner = MPNetPlanner(
                    best_net, self.robot, hybrid=hybrid, seed=self.cfg.seed, max_nodes=self.cfg.max_nodes
                )
                out[planner.name] = evaluate(planner, problems, self.robot, progress=progress).metrics()
        return out


def train_mpnet(
    cfg: MPNetTrainConfig,
    run_dir: str | Path,
    progress: bool = True,
    pool: DemoPool | None = None,
    resume: str | Path | None = None,
) -> MPNetTrainResult:
    """Train on the training split, select on the validation split, test once. Writes
    ``best.pt``, ``last.pt`` (the trainer state, also on Ctrl-C; ``resume`` continues from
    it), ``metrics.csv``, TensorBoard logs and ``summary.json`` to ``run_dir``. The
    demonstrations are planned on ``pool`` if given (see :func:`~.bc.generate_demos`)."""
    folder = RunDir(run_dir, "pointplan mpnet-train")
    try:
        run = _MPNetRun(cfg, folder, progress, pool, resume)
    except KeyboardInterrupt:
        say_interrupted_early("planning the demonstrations")
        return MPNetTrainResult(folder.path, 0, {}, [], {}, 0.0, 0.0, interrupted=True)
    epochs = epoch_range(run.epoch, cfg.epochs, resume, "mpnet", progress)
    with folder.ctrl_c() as stop:
        for ep in epochs:
            row = run.train_epoch(ep, stop)
            if row is None:
                break
            if ep % cfg.eval_every == 0 or ep == cfg.epochs:
                run.validate(row)
            run.history.append(row)
            folder.log(row)
            if "val_success" in row:
                run.save_last(val={k: float(v) for k, v in row.items()})
            if progress:
                post = {"loss": f"{row['train_loss']:.3f}"}
                if "val_success" in row:
                    post.update(
                        val=f"{row['val_success']:.3f}", best=f"{run.best_val['val_success']:.3f}@{run.best_epoch}"
                    )
                epochs.set_postfix(post, refresh=False)
            if stop():
                break
    if progress:
        epochs.close()
    if run.epoch < cfg.epochs:
        folder.interrupted(
            f"in epoch {run.epoch + 1} of {cfg.epochs}", run.save_last, _mpnet_note(run.best_val, run.best_epoch)
        )
        folder.close()
        return MPNetTrainResult(
            folder.path, run.best_epoch, run.best_val, run.history, {}, run.demo_time, run.train_time, interrupted=True
        )
    return _finish_mpnet(run, progress)


def _plain(row: dict[str, Any]) -> dict[str, Any]:
    """A metrics row with numpy scalars as Python numbers (for a checkpoint)."""
    return {k: (v.item() if hasattr(v, "item") else v) for k, v in row.items()}


def _mpnet_note(best_val: dict[str, float], epoch: int) -> str:
    return (
        f"best validation success {best_val['val_success']:.3f} at epoch {epoch}" if best_val else "no validation yet"
    )


def _finish_mpnet(run: _MPNetRun, progress: bool) -> MPNetTrainResult:
    """The test of the best model and ``summary.json``."""
    train_time = run.train_time
    test = run.test(progress)
    summary = {
        "config": to_dict(run.cfg),
        "run_dir": str(run.folder.path),
        "best_epoch": run.best_epoch,
        "best_val": run.best_val,
        "demo_problems": len(run.train_demos.paths),
        "training_samples_per_epoch": int(len(run.train_set.waypoints) - len(run.train_set.offset)),
        "demo_time_s": run.demo_time,
        "train_time_s": train_time,
        "test": test,
    }
    run.folder.write_json("summary.json", summary)
    run.folder.close()
    return MPNetTrainResult(
        run.folder.path, run.best_epoch, run.best_val, run.history, test, run.demo_time, train_time, summary
    )


__all__ = ["MPNetTrainConfig", "MPNetTrainResult", "cut_path", "path_vertices", "train_mpnet"]
