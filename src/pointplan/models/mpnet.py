"""MPNet's networks (Qureshi et al. 2019): an obstacle encoder and a planning network.

The **encoder** is a PointNet (:class:`~pointplan.models.encoders.PointNetEncoder`) on the
scene's obstacle surface points with outward normals in the world frame, computed once per
workspace. In 2D: the ``surface-normals`` observer's point set, every point of it (no
random subset). In 3D: ``n_points`` (512) points drawn on the obstacles' faces in
proportion to their area, the ``global`` observer's pool with that many points (drawn once
per workspace from a generator seeded by the workspace's name, so a scene has one point set
and one encoding). The checkpoint records which (``observation``, ``n_points``).
The **planning network** ("Pnet") is an MLP with dropout after every hidden layer; from the
encoding ``z``, a configuration ``q`` and a goal ``g`` it predicts the next configuration on
the way, ``q + step * f(z, q, g)``. Its dropout stays on when planning: it is the planner's
source of randomness (MPNet's stochastic sampling), drawn from a seeded numpy generator.

Inputs are expressed in units of one step (0.07, see :mod:`pointplan.models.inputs`):
positions (points, ``q``, ``g``) relative to the centre of the workspace and divided by the
step; normals as they are. The network's output is the displacement to the next
configuration, in steps.

Planning runs the network in numpy (:class:`NumpyMPNet`, a dozen numpy calls on weights
copied once): a planner asks for one configuration at a time, where PyTorch's per-call
overhead dominates. It agrees with the PyTorch module to float32 round-off.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from ..config import from_dict
from ..robots import make_robot
from ..robots.base import Robot
from .checkpoint import (
    CheckpointError,
    check_finite_weights,
    check_sizes,
    check_weights,
    finite_number,
    load_checkpoint,
    rebuilding,
    short_repr,
    to_dict,
)
from .encoders import PointNetEncoder

#: what ``kind`` an MPNet checkpoint says it holds
KIND = "mpnet"
#: the observation the encoder reads in 2D (the point set of the surface-normals observer)
OBSERVATION = "surface-normals"
#: the observation the encoder reads in 3D (the global observer's area-weighted surface pool)
OBSERVATION_3D = "global"
#: surface points per workspace in 3D (the global observer's pool size)
N_POINTS_3D = 512
#: the most surface points per workspace a checkpoint may ask for
MAX_POINTS = 1 << 20
#: MPNet checkpoints that ship inside the package: robot -> file in ``pointplan/data``
SHIPPED_MPNET: dict[str, str] = {"disc2d": "narrow2d_mpnet.pt", "sphere3d": "boxes3d_sphere_mpnet.pt"}


def default_observation(robot: Robot) -> str:
    """The encoder's observation for ``robot``: ``surface-normals`` in 2D, ``global`` in 3D."""
    return OBSERVATION_3D if robot.dim == 3 else OBSERVATION


def check_translating(robot: Robot) -> None:
    """MPNet here plans positions: robots whose configuration is their position (the 2D disc,
    the 3D sphere). Raises ValueError for others (the S-shape's pose has a rotation)."""
    if robot.config_dim != robot.dim:
        raise ValueError(
            f"MPNet plans translating robots only (disc2d, sphere3d); {robot.name!r} has a {robot.config_dim}-dimensional configuration in {robot.dim}D"
        )


@dataclass(frozen=True)
class MPNetNetConfig:
    """Shape of the encoder and of the planning network."""

    #: width of the PointNet's per-point layers (its feature size)
    encoder_width: int = 64
    #: per-point layers of the PointNet
    encoder_layers: int = 3
    #: width of the planning network's hidden layers
    width: int = 128
    #: hidden layers of the planning network
    layers: int = 3
    #: dropout probability after every hidden layer of the planning network (kept on when planning)
    dropout: float = 0.1


class MPNetModel(nn.Module):
    """Encoder + planning network. ``encode(points) -> z``; ``forward(z, q_in, g_in)`` gives
    the displacement to the next configuration, in steps (inputs from :func:`scale_positions`)."""

    def __init__(self, dim: int, point_features: int, cfg: MPNetNetConfig) -> None:
        super().__init__()
        self.dim = int(dim)
        self.cfg = cfg
        self.encoder = PointNetEncoder(point_features, cfg.encoder_width, cfg.encoder_layers)
        sizes = [cfg.encoder_width + 2 * dim] + [cfg.width] * cfg.layers
        layers: list[nn.Module] = []
        for a, b in zip(sizes[:-1], sizes[1:]):
            layers += [nn.Linear(a, b), nn.ELU(), nn.Dropout(cfg.dropout)]
        layers.append(nn.Linear(sizes[-1], dim))
        self.pnet = nn.Sequential(*layers)

    def encode(self, points: torch.Tensor) -> torch.Tensor:
        """``points: (B, N, F)`` (padded by duplicates: the max-pool ignores them) -> ``(B, width)``."""
        return self.encoder(points)

    def forward(self, z: torch.Tensor, q_in: torch.Tensor, g_in: torch.Tensor) -> torch.Tensor:
        return self.pnet(torch.cat([z, q_in, g_in], -1))


def scale_positions(x: np.ndarray, center: np.ndarray, step: float) -> np.ndarray:
    """Positions relative to the workspace centre, in steps (float32)."""
    return ((np.asarray(x, np.float64) - center) / step).astype(np.float32)


def encoder_input(points: np.ndarray, normals: np.ndarray, center: np.ndarray, step: float) -> np.ndarray:
    """``(P, 2 dim)`` float32: scaled positions, then normals (at least one row: an empty
    scene is one point far away, pointing nowhere)."""
    if len(points) == 0:
        far = np.full((1, points.shape[-1]), 1e3 / step, np.float32)
        return np.concatenate([far, np.zeros_like(far)], -1)
    return np.concatenate([scale_positions(points, center, step), np.asarray(normals, np.float32)], -1)


def _elu(x: np.ndarray) -> np.ndarray:
    neg = np.minimum(x, 0.0)
    np.expm1(neg, out=neg)
    return np.maximum(x, neg, out=x)


def _wb(layer: nn.Linear) -> tuple[np.ndarray, np.ndarray]:
    return layer.weight.detach().cpu().numpy().astype(np.float32).T.copy(), layer.bias.detach().cpu().numpy().astype(
        np.float32
    ).copy()


class NumpyMPNet:
    """:class:`MPNetModel` in numpy, with the planning network's dropout drawn from a numpy
    generator (no global random state), for the planner.

    ``encode(points_in)`` takes :func:`encoder_input`'s array; ``next(z, q, g, rng)`` returns
    the predicted next configuration (world units, not clipped)."""

    def __init__(self, model: MPNetModel, center: np.ndarray, step: float) -> None:
        enc = model.encoder
        self.inp = _wb(enc.inp)
        self.hidden = [_wb(m) for m in enc.hidden]  # type: ignore[arg-type]
        self.layers = [_wb(m) for m in model.pnet if isinstance(m, nn.Linear)]
        self.dropout = float(model.cfg.dropout)
        self.center = np.asarray(center, np.float64)
        self.step = float(step)
        self.dim = model.dim

    def encode(self, points_in: np.ndarray) -> np.ndarray:
        """The PointNet's feature ``(width,)`` for one scene's points ``(P, F)``."""
        w, b = self.inp
        h = _elu(np.asarray(points_in, np.float32) @ w + b)
        last = len(self.hidden) - 1
        for i, (w, b) in enumerate(self.hidden):
            y = h @ w + b
            h = _elu(y + h) if i < last else y
        return np.asarray(h.max(axis=0), np.float32)

    def displacement(self, z: np.ndarray, q: np.ndarray, g: np.ndarray, rng: np.random.Generator | None) -> np.ndarray:
        """The network's output (steps) for ``q, g: (..., dim)`` (world); dropout masks from
        ``rng`` (``None``: no dropout, the deterministic network)."""
        q_in = scale_positions(q, self.center, self.step)
        g_in = scale_positions(g, self.center, self.step)
        lead = q_in.shape[:-1]
        h = np.concatenate([np.broadcast_to(z, lead + z.shape[-1:]), q_in, g_in], -1).astype(np.float32)
        keep = 1.0 - self.dropout
        for i, (w, b) in enumerate(self.layers):
            h = h @ w + b
            if i < len(self.layers) - 1:
                h = _elu(h)
                if rng is not None and self.dropout > 0.0:
                    h *= (rng.random(h.shape) < keep).astype(np.float32) / np.float32(keep)
        return np.asarray(h, np.float64)

    def next(self, z: np.ndarray, q: np.ndarray, g: np.ndarray, rng: np.random.Generator | None) -> np.ndarray:
        """The predicted next configuration after ``q`` toward ``g``."""
        return np.asarray(q, np.float64) + self.step * self.displacement(z, q, g, rng)


@dataclass
class MPNet:
    """A trained MPNet: the module, the robot, the input scaling and the checkpoint's metadata."""

    model: MPNetModel
    robot: Robot
    center: np.ndarray
    step: float
    meta: dict[str, Any]
    #: the observation the encoder reads (``surface-normals`` in 2D, ``global`` in 3D)
    observation: str = OBSERVATION
    #: surface points per workspace (``global`` only; 0: the observer's whole point set)
    n_points: int = 0

    def numpy(self) -> NumpyMPNet:
        return NumpyMPNet(self.model, self.center, self.step)

    @classmethod
    def from_checkpoint(cls, path: str | Path) -> MPNet:
        """The MPNet of a checkpoint. Anything wrong with the file or its contents raises
        a one-line :class:`~pointplan.models.checkpoint.CheckpointError`."""
        data = load_checkpoint(path)
        if data.get("kind") != KIND:
            raise CheckpointError(f"{path}: not an MPNet checkpoint (train one with `pointplan mpnet-train`)")
        with rebuilding(path, "MPNet"):
            _check_mpnet_fields(data, path)
            robot = make_robot(data["robot"])
            check_translating(robot)
            cfg = from_dict(MPNetNetConfig, data["net"])
            _check_mpnet_settings(data, path, robot, cfg)
            with torch.device("meta"):  # the shapes of the weights, allocating nothing
                expected = MPNetModel(robot.dim, 2 * robot.dim, cfg).state_dict()
            check_weights(path, expected, data["model"], "MPNet")
            check_finite_weights(path, data["model"], "MPNet")
            model = MPNetModel(robot.dim, 2 * robot.dim, cfg)
            model.load_state_dict(data["model"])
        meta = {k: v for k, v in data.items() if k != "model"}
        observation = str(data.get("observation", default_observation(robot)))
        n_points = int(data.get("n_points", N_POINTS_3D if observation == OBSERVATION_3D else 0))
        return cls(
            model.eval(),
            robot,
            np.asarray(data["center"], np.float64),
            float(data["step"]),
            meta,
            observation,
            n_points,
        )


def _check_mpnet_fields(data: dict[str, Any], path: str | Path) -> None:
    """The fields of an MPNet checkpoint that loading it reads, as far as they can be
    checked before its robot is known."""
    for key in ("robot", "point_features", "net", "model", "center", "step"):
        if key not in data:
            raise CheckpointError(f"{path}: not an MPNet checkpoint (it has no {key!r})")
    if not isinstance(data["robot"], str):
        raise CheckpointError(f"{path}: its robot must be a name (a string), got {short_repr(data['robot'])}")
    if not isinstance(data["net"], dict):
        raise CheckpointError(f"{path}: net must hold the network's settings, got {type(data['net']).__name__}")
    observation = data.get("observation", OBSERVATION)
    if observation not in (OBSERVATION, OBSERVATION_3D):
        raise CheckpointError(
            f"{path}: its observation must be {OBSERVATION!r} or {OBSERVATION_3D!r}, got {short_repr(observation)}"
        )
    n_points = data.get("n_points", 0)
    if type(n_points) is not int or not 0 <= n_points <= MAX_POINTS:
        raise CheckpointError(f"{path}: n_points must be an integer from 0 to {MAX_POINTS}, got {short_repr(n_points)}")
    step = data["step"]
    if not finite_number(step) or step <= 0:
        raise CheckpointError(f"{path}: step must be a positive number, got {short_repr(step)}")


def _check_mpnet_settings(data: dict[str, Any], path: str | Path, robot: Robot, cfg: MPNetNetConfig) -> None:
    """What an MPNet checkpoint's robot and network settings decide: the size of the
    points' features and of the centre, and the network's sizes and dropout."""
    features = data["point_features"]
    if type(features) is not int or features != 2 * robot.dim:
        raise CheckpointError(
            f"{path}: point_features must be {2 * robot.dim} (position and normal in {robot.dim}D), got {short_repr(features)}"
        )
    center = data["center"]
    if not isinstance(center, (list, tuple)) or len(center) != robot.dim or not all(map(finite_number, center)):
        raise CheckpointError(f"{path}: center must be {robot.dim} numbers, got {short_repr(center)}")
    check_sizes(path, cfg, ("encoder_width", "width"), ("encoder_layers", "layers"), "MPNet")
    if not finite_number(cfg.dropout) or not 0.0 <= cfg.dropout < 1.0:
        raise CheckpointError(
            f"{path}: the MPNet's dropout must be a number from 0 to below 1, got {short_repr(cfg.dropout)}"
        )


def mpnet_payload(
    model: MPNetModel,
    env: str,
    robot: Robot,
    center: np.ndarray,
    step: float,
    observation: str | None = None,
    n_points: int = 0,
    **extra: Any,
) -> dict[str, Any]:
    """What an MPNet checkpoint holds (``extra``: plain data such as the training config)."""
    return {
        "kind": KIND,
        "env": env,
        "robot": robot.name,
        "observation": observation or default_observation(robot),
        "n_points": int(n_points),
        "point_features": 2 * robot.dim,
        "net": to_dict(model.cfg),
        "model": model.state_dict(),
        "center": [float(c) for c in center],
        "step": float(step),
        **extra,
    }


def shipped_mpnet(robot: str = "disc2d") -> Path:
    """The MPNet checkpoint shipped for ``robot`` (``disc2d``: trained in 2D-Narrow;
    ``sphere3d``: trained in 3D-Boxes, used in every 3D scenario; docs/results/README.md)."""
    from importlib.resources import files

    name = SHIPPED_MPNET.get(robot)
    path = Path(str(files("pointplan") / "data" / name)) if name else None
    if path is None or not path.is_file():
        raise ValueError(
            f"no MPNet ships for robot {robot!r} (shipped for: {', '.join(SHIPPED_MPNET)}; MPNet plans translating robots only); "
            "pass checkpoint=PATH (--checkpoint), or train one with `pointplan mpnet-train`"
        )
    return path


__all__ = [
    "MPNet",
    "MPNetModel",
    "MPNetNetConfig",
    "NumpyMPNet",
    "check_translating",
    "default_observation",
    "encoder_input",
    "mpnet_payload",
    "scale_positions",
    "shipped_mpnet",
]
