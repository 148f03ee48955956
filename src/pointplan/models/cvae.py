"""A conditional variational autoencoder of configurations (learned sampling, after Ichter,
Harrison and Pavone, "Learning Sampling Distributions for Robot Motion Planning", ICRA 2018).

The model learns ``p(x | c)``: configurations ``x`` that lie on solutions of the problem
``c``. The condition ``c`` is ``[PointNet(obstacle points with normals), start, goal]``;
the points are the scene's boundary points (on the 0.015 grid of the ``surface-normals``
observer), all of them, expressed like the configurations in the problem's start-goal
frame (``frame="start-goal"``, the default; see :class:`LearnedSamplerNet`). Positions
(configurations, start, goal, points) are mapped to ``[-1, 1]`` by the workspace bounds,
and scaled by ``input_scale`` where they enter a network (the decoder's output stays in
``[-1, 1]``).

- recognition network ``q(z | x, c)``: an MLP giving a mean and a log-variance;
- decoder ``p(x | z, c)``: an MLP giving the configuration (its mean; samples are decoder
  means of latents drawn from the prior ``N(0, I)``, as Ichter et al. do);
- loss: squared error of the reconstruction (summed over coordinates) plus ``kl_weight``
  times the KL divergence to the prior.

Only translation configurations (disc, sphere) are supported: the decoder's output is a
position.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from numpy.typing import NDArray
from torch import nn

from ..geometry.sampling import surface_points
from .encoders import PointNetEncoder, mlp

Array = NDArray[np.float64]

#: spacing of the scene's boundary points (the paper's thinning distance, as the observers)
POINT_SPACING = 0.015


@dataclass(frozen=True)
class CVAEConfig:
    """Shape of the learned sampler's network."""

    #: size of the latent ``z``
    latent: int = 2
    #: hidden width of the recognition and decoder MLPs
    width: int = 128
    #: hidden layers of the recognition and decoder MLPs
    layers: int = 2
    #: width of the PointNet on the obstacle points
    point_width: int = 64
    #: per-point layers of the PointNet
    point_layers: int = 3
    #: positions entering the networks (points, start, goal, the recognition network's
    #: configuration) are the normalised ones times this (7: about one step, 0.07, per unit)
    input_scale: float = 7.0
    #: coordinates of the sampled configurations and the points: ``start-goal`` (the
    #: problem's frame, see :class:`LearnedSamplerNet`) or ``world``
    frame: str = "start-goal"
    #: smallest half distance between start and goal used as the frame's unit (normalised)
    min_half: float = 0.1


class ConditionalVAE(nn.Module):
    """``q(z | x, c)`` and ``p(x | z, c)`` as MLPs with ELU; ``x: (B, x_dim)``, ``c: (B, c_dim)``."""

    def __init__(
        self, x_dim: int, c_dim: int, latent: int = 3, width: int = 128, layers: int = 2, input_scale: float = 1.0
    ) -> None:
        super().__init__()
        self.x_dim, self.c_dim, self.latent = int(x_dim), int(c_dim), int(latent)
        self.input_scale = float(input_scale)
        self.recognition = mlp([x_dim + c_dim] + [width] * layers + [2 * latent])
        self.decoder = mlp([latent + c_dim] + [width] * layers + [x_dim])

    def encode(self, x: torch.Tensor, c: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        mu, logvar = self.recognition(torch.cat([x * self.input_scale, c], -1)).chunk(2, -1)
        return mu, logvar.clamp(-12.0, 6.0)

    def decode(self, z: torch.Tensor, c: torch.Tensor) -> torch.Tensor:
        return self.decoder(torch.cat([z, c], -1))  # type: ignore[no-any-return]

    def forward(self, x: torch.Tensor, c: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Reconstruction (through a reparameterised latent), mean and log-variance of ``q``."""
        mu, logvar = self.encode(x, c)
        z = mu + torch.randn_like(mu) * (0.5 * logvar).exp()
        return self.decode(z, c), mu, logvar

    def loss(
        self, x: torch.Tensor, c: torch.Tensor, kl_weight: float
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """``(loss, reconstruction, kl)``, each a batch mean; reconstruction is the squared
        error summed over coordinates, kl the KL divergence of ``q`` from ``N(0, I)``."""
        x_hat, mu, logvar = self(x, c)
        rec = ((x_hat - x) ** 2).sum(-1).mean()
        kl = (0.5 * (mu**2 + logvar.exp() - 1.0 - logvar).sum(-1)).mean()
        return rec + kl_weight * kl, rec, kl

    @torch.no_grad()
    def sample(self, c: torch.Tensor, z: torch.Tensor) -> torch.Tensor:
        """Decoder means for latents ``z: (B, latent)`` (draw them from ``N(0, I)``) under
        conditions ``c: (B, c_dim)`` or ``(1, c_dim)``."""
        return self.decode(z, c.expand(len(z), -1))


class LearnedSamplerNet(nn.Module):
    """The obstacle PointNet and the CVAE. ``condition(points, start, goal)`` with
    normalised inputs (:func:`normalise`) gives ``c``; the CVAE models configurations in
    the coordinates of ``to_target`` (``from_target`` maps its samples back).

    With ``frame="start-goal"`` (2D) the CVAE's configurations and the obstacle points are
    expressed in the problem's own frame: origin at the midpoint of start and goal, first
    axis toward the goal, lengths in units of half their distance (at least ``min_half``),
    so the start is always ``(-1, 0)`` and the goal ``(1, 0)``; the condition still holds
    the absolute (normalised) start and goal. With ``"world"`` everything stays normalised
    world coordinates."""

    _point_scale: torch.Tensor

    def __init__(self, config: CVAEConfig, dim: int) -> None:
        super().__init__()
        if config.frame not in ("world", "start-goal"):
            raise ValueError(f"unknown frame {config.frame!r}; use 'world' or 'start-goal'")
        if config.frame == "start-goal" and dim != 2:
            raise ValueError("the start-goal frame is defined in 2D only")
        self.config, self.dim = config, int(dim)
        self.obstacles = PointNetEncoder(2 * dim, config.point_width, config.point_layers)
        self.cvae = ConditionalVAE(
            dim, config.point_width + 2 * dim, config.latent, config.width, config.layers, config.input_scale
        )
        scale = torch.ones(2 * dim)
        scale[:dim] = config.input_scale if config.frame == "world" else 1.0
        self.register_buffer("_point_scale", scale, persistent=False)

    def _frame(
        self, start: torch.Tensor, goal: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """Origin, half distance ``(B, 1)`` and the two unit axes of the start-goal frame."""
        mid = 0.5 * (start + goal)
        delta = 0.5 * (goal - start)
        norm = delta.norm(dim=-1, keepdim=True)
        e1 = torch.where(norm > 1e-9, delta / norm.clamp_min(1e-9), torch.tensor([1.0, 0.0], dtype=delta.dtype))
        e2 = torch.stack([-e1[..., 1], e1[..., 0]], -1)
        return mid, norm.clamp_min(self.config.min_half), e1, e2

    def to_target(self, x: torch.Tensor, start: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
        """Normalised configurations ``(B, dim)`` in the CVAE's coordinates."""
        if self.config.frame == "world":
            return x
        mid, half, e1, e2 = self._frame(start, goal)
        r = (x - mid) / half
        return torch.stack([(r * e1).sum(-1), (r * e2).sum(-1)], -1)

    def from_target(self, y: torch.Tensor, start: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
        """The inverse of :meth:`to_target`."""
        if self.config.frame == "world":
            return y
        mid, half, e1, e2 = self._frame(start, goal)
        return mid + half * (y[..., :1] * e1 + y[..., 1:] * e2)

    def condition(self, points: torch.Tensor, start: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
        """``points: (B, N, 2 dim)`` (normalised position, normal), ``start``, ``goal``:
        ``(B, dim)`` normalised."""
        k = self.config.input_scale
        if self.config.frame == "start-goal":
            mid, half, e1, e2 = self._frame(start, goal)
            r = (points[..., :2] - mid[:, None]) / half[:, None]
            n = points[..., 2:]
            e1, e2 = e1[:, None], e2[:, None]
            points = torch.stack([(r * e1).sum(-1), (r * e2).sum(-1), (n * e1).sum(-1), (n * e2).sum(-1)], -1)
        return torch.cat([self.obstacles(points * self._point_scale), start * k, goal * k], -1)


def normalise(q: Array, low: Array, high: Array) -> Array:
    """Positions to ``[-1, 1]`` over the bounds."""
    return 2.0 * (np.asarray(q, np.float64) - low) / (high - low) - 1.0


def denormalise(u: Array, low: Array, high: Array) -> Array:
    return low + (np.asarray(u, np.float64) + 1.0) * 0.5 * (high - low)


def scene_cloud(scene: object, spacing: float = POINT_SPACING) -> Array:
    """The scene's boundary points with outward normals in the world frame, positions
    normalised by the bounds: ``(N, 2 dim)``. Cached on the scene."""
    cache = scene.__dict__.setdefault("_observer_cache", {})
    key = ("cvae-cloud", float(spacing))
    if key not in cache:
        low, high = scene.low, scene.high  # type: ignore[attr-defined]
        p, n = surface_points(scene.obstacles, spacing, low, high)  # type: ignore[attr-defined]
        if len(p) == 0:  # an empty scene: one point far outside, facing nowhere
            p, n = np.full((1, len(low)), 3.0), np.zeros((1, len(low)))
        else:
            p = normalise(p, low, high)
        cache[key] = np.concatenate([p, n], -1)
    return cache[key]  # type: ignore[no-any-return]


def pad_cloud(cloud: Array, n: int) -> Array:
    """``cloud`` resized to ``n`` points by repeating its points in order (a max-pool does
    not see repeated points, so the encoding is that of the whole cloud); clouds with more
    than ``n`` points are refused."""
    if len(cloud) > n:
        raise ValueError(f"a cloud of {len(cloud)} points does not fit in {n}")
    return cloud[np.arange(n) % len(cloud)]


__all__ = [
    "POINT_SPACING",
    "CVAEConfig",
    "ConditionalVAE",
    "LearnedSamplerNet",
    "denormalise",
    "normalise",
    "pad_cloud",
    "scene_cloud",
]
