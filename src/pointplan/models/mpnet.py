"""MPNet's networks (Qureshi et al. 2019): an obstacle encoder and a planning network.

The **encoder** is a PointNet (:class:`~pointplan.models.encoders.PointNetEncoder`) on the
scene's boundary points with outward normals in the world frame (the ``surface-normals``
observer's point set, every point of it: no random subset), computed once per workspace.
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
from .checkpoint import CheckpointError, load_checkpoint, to_dict
from .encoders import PointNetEncoder

#: what ``kind`` an MPNet checkpoint says it holds
KIND = "mpnet"
#: the observation the encoder reads (the point set of the surface-normals observer)
OBSERVATION = "surface-normals"
#: MPNet checkpoints that ship inside the package: robot -> file in ``pointplan/data``
SHIPPED_MPNET: dict[str, str] = {"disc2d": "narrow2d_mpnet.pt"}


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
    return layer.weight.detach().cpu().numpy().astype(np.float32).T.copy(), layer.bias.detach().cpu().numpy().astype(np.float32).copy()


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

    def numpy(self) -> NumpyMPNet:
        return NumpyMPNet(self.model, self.center, self.step)

    @classmethod
    def from_checkpoint(cls, path: str | Path) -> MPNet:
        data = load_checkpoint(path)
        if data.get("kind") != KIND:
            raise CheckpointError(f"{path}: not an MPNet checkpoint (train one with `pointplan mpnet-train`)")
        robot = make_robot(data["robot"])
        cfg = from_dict(MPNetNetConfig, data["net"])
        model = MPNetModel(robot.dim, int(data["point_features"]), cfg)
        model.load_state_dict(data["model"])
        meta = {k: v for k, v in data.items() if k != "model"}
        return cls(model.eval(), robot, np.asarray(data["center"], np.float64), float(data["step"]), meta)


def mpnet_payload(model: MPNetModel, env: str, robot: Robot, center: np.ndarray, step: float, **extra: Any) -> dict[str, Any]:
    """What an MPNet checkpoint holds (``extra``: plain data such as the training config)."""
    return {
        "kind": KIND,
        "env": env,
        "robot": robot.name,
        "observation": OBSERVATION,
        "point_features": 2 * robot.dim,
        "net": to_dict(model.cfg),
        "model": model.state_dict(),
        "center": [float(c) for c in center],
        "step": float(step),
        **extra,
    }


def shipped_mpnet(robot: str = "disc2d") -> Path:
    """The MPNet checkpoint shipped for ``robot`` (docs/results.md: how it was trained)."""
    from importlib.resources import files

    name = SHIPPED_MPNET.get(robot)
    path = Path(str(files("pointplan") / "data" / name)) if name else None
    if path is None or not path.is_file():
        raise ValueError(
            f"no MPNet ships for robot {robot!r} (shipped: {', '.join(SHIPPED_MPNET)}); pass checkpoint=PATH, or train one with `pointplan mpnet-train`"
        )
    return path


__all__ = ["MPNet", "MPNetModel", "MPNetNetConfig", "NumpyMPNet", "encoder_input", "mpnet_payload", "scale_positions", "shipped_mpnet"]
