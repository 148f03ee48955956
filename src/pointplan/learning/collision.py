"""Collision classification (Strudel et al. 2020, section 4.2): from what the robot observes
at a configuration ``q`` and an action ``a``, predict whether the robot collides after
executing the action.

Label. The 2D disc moves by ``a * action_scale`` (``a`` in ``[-1, 1]^2``, 0.07 per axis);
the end ``q' = clip(q + 0.07 a)`` (clipped into the workspace as the environment does). The
label ``end`` (the paper's: "the robot configuration after executing the action is
colliding") is whether the disc at ``q'`` touches an obstacle; the label ``swept`` is whether
the disc touches one anywhere on the straight move from ``q`` to ``q'`` (what the
environment's ``q_free`` would call a collided step). Both come from exact geometry: the
distance from a point, or from a segment, to each box, against the disc's radius. Starts are
always free (a policy only ever stands on free configurations).

Data. For each workspace, starts are drawn uniformly among free configurations and actions
uniformly in ``[-1, 1]^2``; the candidates are then sorted by the end's signed clearance
``c`` (distance to the nearest obstacle minus the radius; ``c <= 0`` is a collision) into
four strata of equal quota: colliding and near (``-band < c <= 0``), colliding and deep
(``c <= -band``), free and near (``0 < c < band``), free and far (``c >= band``). So the
classes are balanced and half of the samples lie within ``band`` of the boundary. With
``sampling="uniform"`` (the paper's protocol) the candidates are kept as drawn: starts uniform
among free configurations, actions uniform, the classes as they fall. Train, validation and
test samples come from the scenario's disjoint workspace splits; the test is run on both
kinds of samples (``accuracy`` on the strata, ``accuracy_uniform`` on uniform samples of the
same test workspaces), whichever kind the classifier was trained on.

Classifier. An obstacle encoder (PointNet for point sets, the CNN for the occupancy image;
:mod:`pointplan.models.encoders`) of the robot-centred observation at ``q``, then an MLP on
``[pooled feature, action]`` giving one logit; binary cross-entropy, Adam. The model of the
epoch with the best validation accuracy is kept and evaluated once on the test samples.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from numpy.typing import NDArray
from torch import nn

from ..geometry.shapes import Box, Sphere
from ..models.checkpoint import to_dict
from ..models.encoders import EncoderConfig, make_encoder, mlp
from ..models.inputs import obs_input
from ..observers import make_observer
from ..robots.base import Robot
from ..scenes.scenarios import Scenario, make_scenario
from ..scenes.scene import Scene
from .rundir import (
    CtrlC,
    RunDir,
    atomic_write,
    load_trainer_state,
    optimizer_and_random_state,
    restore_optimizer_and_random_state,
)

Array = NDArray[np.float64]

#: the two labels: the end configuration, or the whole straight move
LABELS = ("end", "swept")
#: how samples are drawn: four clearance strata of equal quota, or uniformly (the paper's)
SAMPLINGS = ("strata", "uniform")
#: observations of the 2D disc the classifier can read
OBSERVATIONS = ("image", "interior", "surface", "surface-normals")


# ---------------------------------------------------------------------------- exact geometry
def point_clearance(scene: Scene, p: Array, radius: float) -> Array:
    """Signed clearance of a disc of ``radius`` centred at ``p: (n, 2)``: the (signed)
    distance from the centre to the nearest obstacle, minus the radius. ``<= 0`` means the
    disc touches or overlaps an obstacle. Boxes (any orientation) and discs."""
    p = np.asarray(p, np.float64)
    best = np.full(len(p), np.inf)
    for s in scene.obstacles:
        if isinstance(s, Box):
            local = (p - s.center) @ s.rotation
            d = np.abs(local) - s.half
            outside = np.linalg.norm(np.maximum(d, 0.0), axis=1)
            inside = np.minimum(d.max(axis=1), 0.0)
            sd = outside + inside
        elif isinstance(s, Sphere):
            sd = np.linalg.norm(p - s.center, axis=1) - s.radius
        else:
            raise NotImplementedError(f"exact clearance to {type(s).__name__} is not implemented")
        best = np.minimum(best, sd)
    return best - radius


def _point_segment_distance(p: Array, a: Array, b: Array) -> Array:
    """Distance from points ``p: (n, 2)`` (or ``(2,)``) to segments ``a -> b: (n, 2)``."""
    ab = b - a
    den = np.einsum("ij,ij->i", ab, ab)
    t = np.where(den > 0, np.einsum("ij,ij->i", p - a, ab) / np.where(den > 0, den, 1.0), 0.0)
    t = np.clip(t, 0.0, 1.0)
    return np.linalg.norm(a + t[:, None] * ab - p, axis=1)


def _segment_hits_box(a: Array, b: Array, half: Array) -> NDArray[np.bool_]:
    """Does segment ``a -> b`` (box frame, ``(n, 2)``) meet the box ``|x| <= half``? (slabs)"""
    d = b - a
    t0 = np.zeros(len(a))
    t1 = np.ones(len(a))
    ok = np.ones(len(a), dtype=bool)
    for i in range(a.shape[1]):
        flat = np.abs(d[:, i]) < 1e-15
        ok &= ~flat | (np.abs(a[:, i]) <= half[i])
        safe = np.where(flat, 1.0, d[:, i])
        ta = (-half[i] - a[:, i]) / safe
        tb = (half[i] - a[:, i]) / safe
        lo, hi = np.minimum(ta, tb), np.maximum(ta, tb)
        t0 = np.where(flat, t0, np.maximum(t0, lo))
        t1 = np.where(flat, t1, np.minimum(t1, hi))
    return ok & (t0 <= t1)


def segment_clearance(scene: Scene, a: Array, b: Array, radius: float) -> Array:
    """Clearance of the disc swept along the segments ``a -> b: (n, 2)``: the distance from
    the segment to the nearest obstacle minus the radius (``-radius`` when the segment meets
    one). Exact for boxes and discs: two disjoint convex sets in the plane are closest at a
    vertex of one and the boundary of the other, so the distance is the least of the
    endpoints' distances to the box and the box corners' distances to the segment."""
    a = np.asarray(a, np.float64)
    b = np.asarray(b, np.float64)
    best = np.full(len(a), np.inf)
    for s in scene.obstacles:
        if isinstance(s, Box):
            la, lb = (a - s.center) @ s.rotation, (b - s.center) @ s.rotation
            ends = np.minimum(
                np.linalg.norm(np.maximum(np.abs(la) - s.half, 0.0), axis=1),
                np.linalg.norm(np.maximum(np.abs(lb) - s.half, 0.0), axis=1),
            )
            corners = np.array([[sx, sy] for sx in (-1, 1) for sy in (-1, 1)]) * s.half
            for c in corners:
                ends = np.minimum(ends, _point_segment_distance(c, la, lb))
            d = np.where(_segment_hits_box(la, lb, s.half), 0.0, ends)
        elif isinstance(s, Sphere):
            d = np.maximum(_point_segment_distance(s.center, a, b) - s.radius, 0.0)
        else:
            raise NotImplementedError(f"exact clearance to {type(s).__name__} is not implemented")
        best = np.minimum(best, d)
    return best - radius


def end_configuration(robot: Robot, q: Array, action: Array, low: Array, high: Array) -> Array:
    """Where action ``a`` in ``[-1, 1]`` takes the robot from ``q``, clipped into the bounds."""
    return robot.clip(robot.integrate(q, np.clip(action, -1.0, 1.0) * robot.action_scale), low, high)


# ---------------------------------------------------------------------------- data
def label_clearance(label: str, end: Array, swept: Array) -> Array:
    """The signed clearance a label thresholds at 0: ``end``, the end's; ``swept``, the
    move's where it is free, else the deeper of the move's (at most ``-radius`` once the
    centre's path meets an obstacle) and the end's, so that a move ending deep inside an
    obstacle counts as deep."""
    if label == "end":
        return end
    return np.where(swept > 0.0, swept, np.minimum(end, swept))


@dataclass
class CollisionSamples:
    """Configurations, actions and their exact labels, over a list of workspaces."""

    scenes: list[Scene]
    #: index into ``scenes`` of each sample
    scene: NDArray[np.int64]
    q: Array
    action: NDArray[np.float32]
    end: Array
    #: signed clearance of the disc at the end configuration (``<= 0``: collision)
    end_clearance: Array
    #: signed clearance of the disc swept from ``q`` to the end
    swept_clearance: Array

    def __len__(self) -> int:
        return len(self.q)

    def clearance(self, label: str) -> Array:
        """The signed clearance behind ``label`` (see :func:`label_clearance`)."""
        return label_clearance(label, self.end_clearance, self.swept_clearance)

    def labels(self, label: str) -> NDArray[np.bool_]:
        """True where the robot collides (``end``: at the end; ``swept``: on the way)."""
        return self.clearance(label) <= 0.0

    def near(self, label: str, band: float) -> NDArray[np.bool_]:
        """Samples whose clearance lies within ``band`` of the boundary."""
        return np.abs(self.clearance(label)) < band


def _scene_samples(
    robot: Robot,
    scene: Scene,
    where: str,
    radius: float,
    per_scene: int,
    quota: NDArray[np.int64],
    rng: np.random.Generator,
    band: float,
    label: str,
    sampling: str,
) -> dict[str, Array]:
    """The samples of one workspace (``where``, for the error), ``quota[k]`` in stratum
    ``k``: arrays ``q``, ``a``, ``e``, ``ce``, ``cs`` (see :func:`draw_samples`)."""
    taken: list[list[NDArray[np.int64]]] = [[] for _ in range(4)]
    pool: dict[str, list[Array]] = {"q": [], "a": [], "e": [], "ce": [], "cs": []}
    have = np.zeros(4, dtype=np.int64)
    offset = 0
    for _ in range(1000):
        if np.all(have >= quota):
            break
        n = 8 * per_scene
        q = rng.uniform(scene.low, scene.high, size=(n, 2))
        q = q[point_clearance(scene, q, radius) > 0.0]  # free starts
        a = rng.uniform(-1.0, 1.0, size=(len(q), 2))
        e = end_configuration(robot, q, a, scene.low, scene.high)
        c_end = point_clearance(scene, e, radius)
        c_sw = segment_clearance(scene, q, e, radius)
        c = label_clearance(label, c_end, c_sw)
        strata = np.where(c <= 0.0, np.where(c > -band, 0, 1), np.where(c < band, 2, 3))
        if sampling == "uniform":
            strata = np.zeros(len(c), dtype=np.int64)
        for k in range(4):
            pick = np.flatnonzero(strata == k)[: max(quota[k] - have[k], 0)]
            taken[k].append(pick + offset)
            have[k] += len(pick)
        for key, v in zip(("q", "a", "e", "ce", "cs"), (q, a, e, c_end, c_sw)):
            pool[key].append(v)
        offset += len(q)
    else:
        raise RuntimeError(f"workspace {where}: could not fill the strata ({have.tolist()} of {quota.tolist()})")
    sel = np.concatenate([np.concatenate(t) for t in taken])
    return {k: np.concatenate(v)[sel] for k, v in pool.items()}


def draw_samples(
    scenario: Scenario,
    split: str,
    n_scenes: int,
    per_scene: int,
    rng: np.random.Generator,
    band: float = 0.02,
    label: str = "end",
    progress: bool = False,
    sampling: str = "strata",
) -> CollisionSamples:
    """``per_scene`` samples (a multiple of 4) in each of workspaces ``0..n_scenes-1`` of
    ``split``: a quarter in each stratum of the ``label``'s clearance (colliding near,
    colliding deep, free near, free far; see the module's description), or with
    ``sampling="uniform"`` the first ``per_scene`` free starts with uniform actions."""
    if sampling not in SAMPLINGS:
        raise ValueError(f"sampling must be one of {', '.join(SAMPLINGS)}, not {sampling!r}")
    if label not in LABELS:
        raise ValueError(f"label must be one of {', '.join(LABELS)}, not {label!r}")
    if per_scene < 4 or per_scene % 4:
        raise ValueError(f"per_scene must be a positive multiple of 4, got {per_scene}")
    robot = scenario.robot
    if robot.dim != 2 or robot.config_dim != 2:
        raise ValueError("collision classification is implemented for the 2D disc")
    radius = float(robot.parts.sphere_radii.max())
    # samples wanted per stratum; uniform sampling puts every candidate in the first
    quota = np.array([per_scene, 0, 0, 0]) if sampling == "uniform" else np.full(4, per_scene // 4)
    scenes, idx, qs, acts, ends, ce, cs = [], [], [], [], [], [], []
    it: Any = range(n_scenes)
    if progress:
        from ..progress import progress_bar

        it = progress_bar(it, desc=f"{split} samples", unit="workspace")
    for i in it:
        scene = scenario.scene(split, i)
        cat = _scene_samples(robot, scene, f"{split}/{i}", radius, per_scene, quota, rng, band, label, sampling)
        scenes.append(scene)
        idx.append(np.full(len(cat["q"]), len(scenes) - 1, np.int64))
        qs.append(cat["q"])
        acts.append(cat["a"])
        ends.append(cat["e"])
        ce.append(cat["ce"])
        cs.append(cat["cs"])
    return CollisionSamples(
        scenes,
        np.concatenate(idx),
        np.concatenate(qs),
        np.concatenate(acts).astype(np.float32),
        np.concatenate(ends),
        np.concatenate(ce),
        np.concatenate(cs),
    )


def observe_samples(
    samples: CollisionSamples,
    robot: Robot,
    observation: str,
    n_points: int,
    rng: np.random.Generator,
    chunk: int = 1024,
) -> NDArray[Any]:
    """The robot-centred observation at each sample's start, as the policies see it:
    point sets scaled to steps (:func:`pointplan.models.inputs.obs_input`, float32), or
    occupancy images (uint8, to keep them small)."""
    kwargs: dict[str, Any] = {} if observation == "image" else {"n_points": n_points}
    out = []
    for c in range(0, len(samples), chunk):
        sl = slice(c, c + chunk)
        obs = make_observer(observation, robot, **kwargs)
        obs.bind([samples.scenes[j] for j in samples.scene[sl]])
        o = obs.observe(samples.q[sl], rng)
        out.append(o.astype(np.uint8) if observation == "image" else obs_input(robot, o))
    return np.concatenate(out)


# ---------------------------------------------------------------------------- model
class CollisionClassifier(nn.Module):
    """Encoder of the observation, then an MLP on ``[feature, action]`` to one logit."""

    def __init__(
        self,
        obs_shape: tuple[int, ...],
        encoder: EncoderConfig,
        action_dim: int = 2,
        head_width: int = 256,
        head_layers: int = 3,
    ) -> None:
        super().__init__()
        self.encoder = make_encoder(encoder, obs_shape)
        feat = int(self.encoder.features_dim)  # type: ignore[arg-type]
        self.head = mlp([feat + action_dim] + [head_width] * head_layers + [1])

    def forward(self, obs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        return self.head(torch.cat([self.encoder(obs), action], -1))[:, 0]


# ---------------------------------------------------------------------------- run
@dataclass(frozen=True)
class CollisionConfig:
    """A collision-classification run: data, classifier and training budget."""

    env: str = "narrow2d"
    #: what the classifier sees: image (CNN), interior, surface or surface-normals (PointNet)
    observation: str = "surface-normals"
    #: observed points (point observations)
    n_points: int = field(default=128, metadata={"min": 1})
    #: ``end``: the disc collides at the end of the action (the paper's task); ``swept``: anywhere on the move
    label: str = "end"
    #: training workspaces (from the train split)
    train_scenes: int = field(default=200, metadata={"min": 1})
    #: validation workspaces (model selection)
    val_scenes: int = field(default=50, metadata={"min": 1})
    #: test workspaces (evaluated once, at the end)
    test_scenes: int = field(default=200, metadata={"min": 1})
    #: samples per workspace, a multiple of 4 (a quarter per clearance stratum)
    per_scene: int = field(default=64, metadata={"min": 4})
    #: width of the near-boundary strata: end clearance within this of the boundary
    band: float = 0.02
    #: training and validation samples: ``strata`` (half near a wall) or ``uniform`` (the paper's)
    sampling: str = "strata"
    #: passes over the training samples (at most, with ``patience``)
    epochs: int = field(default=12, metadata={"min": 1})
    #: stop once validation accuracy has not improved for this many epochs (0: run every epoch)
    patience: int = field(default=0, metadata={"min": 0})
    #: Adam step size
    lr: float = 1e-3
    #: step size reached at the last epoch by a cosine schedule (0 or ``lr``: constant)
    lr_end: float = 0.0
    #: samples per gradient step
    batch_size: int = field(default=256, metadata={"min": 1})
    #: encoder: ``pointnet``, ``mlp`` or ``cnn``; empty picks cnn for the image, pointnet otherwise
    encoder: str = ""
    #: encoder and head width
    width: int = field(default=128, metadata={"min": 1})
    seed: int = 0
    device: str = "cpu"

    def __post_init__(self) -> None:
        if self.label not in LABELS:
            raise ValueError(f"label must be one of {', '.join(LABELS)}, not {self.label!r}")
        if self.observation not in OBSERVATIONS:
            raise ValueError(f"observation must be one of {', '.join(OBSERVATIONS)}, not {self.observation!r}")
        if self.per_scene % 4:
            raise ValueError(f"per_scene must be a multiple of 4, got {self.per_scene}")
        if self.sampling not in SAMPLINGS:
            raise ValueError(f"sampling must be one of {', '.join(SAMPLINGS)}, not {self.sampling!r}")

    @property
    def encoder_kind(self) -> str:
        return self.encoder or ("cnn" if self.observation == "image" else "pointnet")


@dataclass
class SplitData:
    """Samples of one split with their observations and labels as tensors."""

    samples: CollisionSamples
    obs: torch.Tensor
    action: torch.Tensor
    label: torch.Tensor


#: the sample sets of a run: name -> (workspace split, sampling; None: the run's own)
SAMPLE_SETS: dict[str, tuple[str, str | None]] = {
    "train": ("train", None),
    "val": ("val", None),
    "test": ("test", "strata"),
    "test_uniform": ("test", "uniform"),
}


def make_data(cfg: CollisionConfig, progress: bool = False) -> dict[str, CollisionSamples]:
    """The sample sets of ``cfg`` (:data:`SAMPLE_SETS`; independent of the observation:
    every representation gets the same samples for one seed). Train and val follow
    ``cfg.sampling``; the test workspaces give both a stratified and a uniform set."""
    scenario = make_scenario(cfg.env)
    sizes = {"train": cfg.train_scenes, "val": cfg.val_scenes, "test": cfg.test_scenes}
    out = {}
    for k, (name, (split, sampling)) in enumerate(SAMPLE_SETS.items()):
        rng = np.random.default_rng(np.random.SeedSequence([cfg.seed, k, 0xC011]))
        how = sampling or cfg.sampling
        out[name] = draw_samples(
            scenario,
            split,
            sizes[split],
            cfg.per_scene,
            rng,
            cfg.band,
            cfg.label,
            progress and name != "test_uniform",
            how,
        )
    return out


def _tensors(cfg: CollisionConfig, samples: CollisionSamples, robot: Robot, k: int) -> SplitData:
    rng = np.random.default_rng(np.random.SeedSequence([cfg.seed, k, 0x0B5]))
    obs = observe_samples(samples, robot, cfg.observation, cfg.n_points, rng)
    return SplitData(
        samples,
        torch.as_tensor(obs),
        torch.as_tensor(samples.action),
        torch.as_tensor(samples.labels(cfg.label).astype(np.float32)),
    )


def predict(model: CollisionClassifier, data: SplitData, batch_size: int = 1024) -> NDArray[np.bool_]:
    """Predicted collisions (logit > 0) for every sample of ``data``."""
    model.eval()
    device = next(model.parameters()).device
    out = []
    with torch.inference_mode():
        for s in range(0, len(data.label), batch_size):
            o = data.obs[s : s + batch_size].to(device, torch.float32)
            out.append((model(o, data.action[s : s + batch_size].to(device)) > 0).cpu().numpy())
    return np.concatenate(out) if out else np.zeros(0, dtype=bool)


def accuracy_report(pred: NDArray[np.bool_], samples: CollisionSamples, label: str, band: float) -> dict[str, Any]:
    """Accuracy overall, near the boundary, away from it and per class."""
    truth = samples.labels(label)
    ok = pred == truth
    near = samples.near(label, band)

    def acc(mask: NDArray[np.bool_]) -> float:
        return float(ok[mask].mean()) if mask.any() else float("nan")

    return {
        "n": int(len(ok)),
        "accuracy": acc(np.ones_like(ok)),
        "accuracy_near": acc(near),
        "accuracy_far": acc(~near),
        "n_near": int(near.sum()),
        "recall_collision": acc(truth),
        "recall_free": acc(~truth),
        "collision_share": float(truth.mean()) if len(truth) else float("nan"),
    }


@dataclass
class CollisionResult:
    """What :func:`train_classifier` returns."""

    model: CollisionClassifier
    history: list[dict[str, float]]
    best_epoch: int
    test: dict[str, Any]
    val: dict[str, Any]
    train_time_s: float
    data_time_s: float
    interrupted: bool = False
    test_pred: NDArray[np.bool_] | None = None
    test_samples: CollisionSamples | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    def summary(self, cfg: CollisionConfig) -> dict[str, Any]:
        return {
            "config": to_dict(cfg),
            "best_epoch": self.best_epoch,
            "val": self.val,
            "test": self.test,
            "history": self.history,
            "train_time_s": self.train_time_s,
            "data_time_s": self.data_time_s,
            "interrupted": self.interrupted,
            **self.extra,
        }


@dataclass
class _Fit:
    """A classifier being trained: network, optimiser, random stream and counters."""

    model: CollisionClassifier
    opt: torch.optim.Optimizer
    rng: np.random.Generator
    epoch: int = 0
    history: list[dict[str, float]] = field(default_factory=list)
    best_acc: float = -1.0
    best_epoch: int = 0
    best_state: dict[str, torch.Tensor] | None = None
    train_before: float = 0.0

    def state(
        self, cfg: CollisionConfig, obs_shape: list[int], queue: Sequence[str], train_time: float
    ) -> dict[str, Any]:
        """``last.pt``: the classifier (as :func:`save_classifier` keeps it) and the trainer state."""
        trainer = {
            "epoch": self.epoch,
            **optimizer_and_random_state(self.opt, self.rng),
            "history": [dict(r) for r in self.history],
            "best_acc": self.best_acc,
            "best_epoch": self.best_epoch,
            "best_model": self.best_state,
            "train_time_s": train_time,
            "queue": list(queue),
        }
        return {
            "config": to_dict(cfg),
            "obs_shape": obs_shape,
            "model": self.model.state_dict(),
            "collision_trainer": trainer,
        }

    def resume(self, path: str | Path) -> None:
        state = load_trainer_state(path, "collision_trainer", "pointplan collision-classify")
        self.model.load_state_dict(state["model"])
        t = state["collision_trainer"]
        restore_optimizer_and_random_state(t, self.opt, self.rng)
        self.epoch, self.best_acc, self.best_epoch = int(t["epoch"]), float(t["best_acc"]), int(t["best_epoch"])
        self.history, self.best_state, self.train_before = (
            [dict(r) for r in t["history"]],
            t["best_model"],
            float(t["train_time_s"]),
        )


def _set_lr(opt: torch.optim.Optimizer, cfg: CollisionConfig, epoch: int) -> None:
    """The step size of ``epoch`` (1-based): ``lr`` at the first, then a cosine down to
    ``lr_end`` at the last (constant when ``lr_end`` is 0)."""
    end = cfg.lr_end or cfg.lr
    frac = (epoch - 1) / max(cfg.epochs - 1, 1)
    # a plain float: a checkpoint (the optimiser's state) holds no numpy scalars
    lr = float(end + 0.5 * (cfg.lr - end) * (1.0 + np.cos(np.pi * frac)))
    for g in opt.param_groups:
        g["lr"] = lr


def _train_epoch(fit: _Fit, tr: SplitData, cfg: CollisionConfig, bar: Any, stop: Callable[[], bool]) -> float | None:
    """One pass over the training samples: the mean loss, or None when ``stop`` ended it early."""
    model, device = fit.model, next(fit.model.parameters()).device
    loss_fn = nn.BCEWithLogitsLoss()
    model.train()
    n = len(tr.label)
    perm = torch.as_tensor(fit.rng.permutation(n))
    total, seen = 0.0, 0
    for s in range(0, n, cfg.batch_size):
        b = perm[s : s + cfg.batch_size]
        loss = loss_fn(model(tr.obs[b].to(device, torch.float32), tr.action[b].to(device)), tr.label[b].to(device))
        fit.opt.zero_grad(set_to_none=True)
        loss.backward()
        fit.opt.step()
        total += float(loss.detach()) * len(b)
        seen += len(b)
        if bar is not None:
            bar.update()
        if stop():
            return None
    return total / max(seen, 1)


def _fit_epochs(
    fit: _Fit,
    data: dict[str, SplitData],
    cfg: CollisionConfig,
    bar: Any,
    folder: RunDir | None,
    train_time: Callable[[], float],
) -> None:
    """The epochs after ``fit.epoch`` up to ``cfg.epochs``, each validated (the best model
    kept in ``fit``); stops early when validation stops improving (``cfg.patience``) or on
    Ctrl-C (after the current gradient step)."""
    model = fit.model
    with CtrlC() as stop:
        for ep in range(fit.epoch + 1, cfg.epochs + 1):
            if cfg.patience and ep - fit.best_epoch > cfg.patience and fit.best_epoch:
                break  # validation has stopped improving
            _set_lr(fit.opt, cfg, ep)
            loss = _train_epoch(fit, data["train"], cfg, bar, stop)
            if loss is None:
                break
            val = accuracy_report(predict(model, data["val"]), data["val"].samples, cfg.label, cfg.band)
            row = {
                "epoch": ep,
                "train_loss": loss,
                "val_accuracy": val["accuracy"],
                "val_accuracy_near": val["accuracy_near"],
                "wall_time_s": train_time(),
            }
            fit.epoch = ep
            fit.history.append(row)
            if folder is not None:
                folder.log(row)
            if val["accuracy"] > fit.best_acc:
                fit.best_acc, fit.best_epoch = val["accuracy"], ep
                fit.best_state = {k: v.detach().clone() for k, v in model.state_dict().items()}
            if bar is not None:
                bar.set_postfix(
                    loss=f"{loss:.3f}", val=f"{val['accuracy']:.3f}", best=f"{fit.best_acc:.3f}", refresh=False
                )
            if stop():
                break


def train_classifier(
    cfg: CollisionConfig,
    run_dir: str | Path | None = None,
    progress: bool = True,
    samples: dict[str, CollisionSamples] | None = None,
    resume: str | Path | None = None,
    queue: Sequence[str] = (),
) -> CollisionResult:
    """Draw the data (unless given), train, select on validation, test once.

    With ``run_dir``, writes ``<observation>.pt`` (the classifier), ``<observation>.json``
    (the summary), ``<observation>_metrics.csv`` and TensorBoard logs. Ctrl-C stops after
    the current gradient step: with ``run_dir`` the trainer state goes to ``last.pt``
    (``resume`` continues from it; ``queue``, the observations the command trains after
    this one, is kept there too); the result says it was interrupted and nothing is tested."""
    folder = (
        RunDir(run_dir, "pointplan collision-classify", f"{cfg.observation}_metrics.csv", f"tb/{cfg.observation}")
        if run_dir is not None
        else None
    )
    torch.manual_seed(cfg.seed)
    robot = make_scenario(cfg.env).robot
    t0 = time.perf_counter()
    if samples is None:
        samples = make_data(cfg, progress)
    data = {name: _tensors(cfg, samples[name], robot, k) for k, name in enumerate(SAMPLE_SETS)}
    t_data = time.perf_counter() - t0
    obs_shape = tuple(data["train"].obs.shape[1:])
    model = CollisionClassifier(
        obs_shape, EncoderConfig(kind=cfg.encoder_kind, width=cfg.width, layers=3), robot.twist_dim, cfg.width, 3
    ).to(torch.device(cfg.device))
    fit = _Fit(
        model,
        torch.optim.Adam(model.parameters(), lr=cfg.lr),
        np.random.default_rng(np.random.SeedSequence([cfg.seed, 0x7EA1])),
    )
    if resume is not None:
        fit.resume(resume)
        if folder is not None:
            folder.metrics.drop_after(fit.epoch)
    bar: Any = None
    if progress:
        from ..progress import progress_bar

        steps = int(np.ceil(len(data["train"].label) / cfg.batch_size))
        bar = progress_bar(
            total=cfg.epochs * steps,
            initial=fit.epoch * steps,
            desc=f"{cfg.observation} classifier",
            unit="step",
            dynamic_ncols=True,
        )
    t1 = time.perf_counter()
    train_time = lambda: fit.train_before + time.perf_counter() - t1
    _fit_epochs(fit, data, cfg, bar, folder, train_time)
    if bar is not None:
        bar.close()
    stopped_early = bool(cfg.patience) and fit.epoch - fit.best_epoch >= cfg.patience and fit.best_epoch > 0
    res = CollisionResult(
        model, fit.history, fit.best_epoch, {}, {}, 0.0, t_data, fit.epoch < cfg.epochs and not stopped_early
    )
    res.extra["obs_shape"] = list(obs_shape)
    if res.interrupted:
        res.train_time_s = train_time()
        if folder is not None:
            note = (
                f"best validation accuracy {fit.best_acc:.3f} at epoch {fit.best_epoch}"
                if fit.best_state is not None
                else "no validation yet"
            )
            folder.interrupted(
                f"in epoch {fit.epoch + 1} of {cfg.epochs}",
                lambda: folder.save("last.pt", fit.state(cfg, list(obs_shape), queue, res.train_time_s)),
                note,
            )
        return res
    res.train_time_s = train_time()
    return _test_classifier(cfg, res, fit, data, samples, folder)


def _test_classifier(
    cfg: CollisionConfig,
    res: CollisionResult,
    fit: _Fit,
    data: dict[str, SplitData],
    samples: dict[str, CollisionSamples],
    folder: RunDir | None,
) -> CollisionResult:
    """The best epoch's classifier on validation and test samples; saved with ``folder``."""
    assert fit.best_state is not None
    model = res.model
    model.load_state_dict(fit.best_state)
    res.val = accuracy_report(predict(model, data["val"]), data["val"].samples, cfg.label, cfg.band)
    res.test_pred = predict(model, data["test"])
    res.test_samples = samples["test"]
    res.test = accuracy_report(res.test_pred, data["test"].samples, cfg.label, cfg.band)
    uniform = accuracy_report(predict(model, data["test_uniform"]), data["test_uniform"].samples, cfg.label, cfg.band)
    res.test["accuracy_uniform"] = uniform["accuracy"]
    res.test["uniform"] = uniform
    if cfg.label == "end":  # the same predictions against the swept-move label
        res.extra["test_vs_swept_label"] = accuracy_report(res.test_pred, samples["test"], "swept", cfg.band)
        res.extra["test_labels_differ"] = float(
            np.mean(samples["test"].labels("end") != samples["test"].labels("swept"))
        )
    res.extra["parameters"] = int(sum(p.numel() for p in model.parameters()))
    if folder is not None:
        save_classifier(folder.path, cfg, res, folder)
        folder.close()
    return res


def save_classifier(run_dir: Path, cfg: CollisionConfig, res: CollisionResult, folder: RunDir | None = None) -> None:
    """``<observation>.pt`` (weights, config, shape), ``<observation>.json`` (summary) and
    ``<observation>_test.npz`` (the test predictions), each written atomically."""
    folder = folder or RunDir(run_dir, "pointplan collision-classify")
    folder.save_torch(
        f"{cfg.observation}.pt",
        {"config": to_dict(cfg), "obs_shape": res.extra["obs_shape"], "model": res.model.state_dict()},
    )
    folder.write_json(f"{cfg.observation}.json", res.summary(cfg))
    if res.test_pred is not None and res.test_samples is not None:
        t = res.test_samples
        arrays = {
            "pred": res.test_pred,
            "end_clearance": t.end_clearance,
            "swept_clearance": t.swept_clearance,
            "scene": t.scene,
            "q": t.q,
            "action": t.action,
        }
        atomic_write(folder.path / f"{cfg.observation}_test.npz", lambda tmp: _savez(tmp, arrays))


def _savez(path: Path, arrays: dict[str, Any]) -> None:
    with path.open("wb") as f:  # (a file object: np.savez would add .npz to a name)
        np.savez_compressed(f, **arrays)


def load_classifier(path: str | Path) -> tuple[CollisionClassifier, CollisionConfig]:
    """A classifier saved by :func:`save_classifier` (data only: loaded with ``weights_only``)."""
    from ..config import from_dict

    data = torch.load(path, map_location="cpu", weights_only=True)
    cfg = from_dict(CollisionConfig, data["config"])
    enc = EncoderConfig(kind=cfg.encoder_kind, width=cfg.width, layers=3)
    model = CollisionClassifier(tuple(data["obs_shape"]), enc, 2, cfg.width, 3)
    model.load_state_dict(data["model"])
    return model.eval(), cfg


def grid_predictions(
    model: CollisionClassifier, cfg: CollisionConfig, scene: Scene, action: Array, resolution: int = 100, seed: int = 0
) -> dict[str, NDArray[Any]]:
    """Predictions on a grid of free starts in ``scene`` for one fixed ``action``: the
    starts ``(n, 2)``, the exact labels and the predictions (for the error picture)."""
    scenario = make_scenario(cfg.env)
    robot = scenario.robot
    radius = float(robot.parts.sphere_radii.max())
    u = (np.arange(resolution) + 0.5) / resolution
    g = np.stack(np.meshgrid(u, u, indexing="ij"), -1).reshape(-1, 2)
    g = scene.low + g * (scene.high - scene.low)
    q = g[point_clearance(scene, g, radius) > 0.0]
    a = np.broadcast_to(np.asarray(action, np.float32), q.shape).copy()
    end = end_configuration(robot, q, a, scene.low, scene.high)
    ce = point_clearance(scene, end, radius)
    cs = segment_clearance(scene, q, end, radius)
    samples = CollisionSamples([scene], np.zeros(len(q), np.int64), q, a, end, ce, cs)
    rng = np.random.default_rng(seed)
    obs = observe_samples(samples, robot, cfg.observation, cfg.n_points, rng)
    data = SplitData(
        samples, torch.as_tensor(obs), torch.as_tensor(a), torch.as_tensor(samples.labels(cfg.label).astype(np.float32))
    )
    return {"q": q, "end": end, "truth": samples.labels(cfg.label), "pred": predict(model, data)}
