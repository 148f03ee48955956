"""Actor and critics built on an obstacle encoder.

Inputs are ``obs`` (points ``(B, N, F)`` or an image ``(B, 1, S, S)``) and ``goal``, the goal
as seen from the robot (``(B, G)``, ``log(q^-1 q_goal)``). The actor is a tanh-Gaussian; the
critic is a pair of Q-networks. Where the critic sees the action is a choice:

- ``points`` (the paper): the action is appended to every point before the PointNet.
- ``pooled``: the action joins the goal after pooling (cheaper: the per-point layers run once
  per observation, whatever the action).

With ``shared_encoder`` the actor and both critics use one per-point network (only the
critics' loss trains it; the actor sees its features detached); it requires ``pooled``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import torch
from torch import nn

from .encoders import EncoderConfig, make_encoder, mlp

LOG_STD_MIN, LOG_STD_MAX = -20.0, 2.0


@dataclass(frozen=True)
class NetConfig:
    """Shape of the actor and critic networks."""

    encoder: EncoderConfig = field(default_factory=EncoderConfig)
    #: hidden width and depth of the MLP on [pooled feature, goal]
    head_width: int = 256
    head_layers: int = 3
    #: ``points`` (action on every point, as in the paper) or ``pooled``
    critic_action: str = "points"
    #: one encoder for actor and critics
    shared_encoder: bool = False

    def __post_init__(self) -> None:
        if self.critic_action not in ("points", "pooled"):
            raise ValueError("critic_action must be 'points' or 'pooled'")
        if self.shared_encoder and self.critic_action != "pooled":
            raise ValueError("a shared encoder needs critic_action='pooled'")


class Actor(nn.Module):
    """Tanh-Gaussian policy: ``forward(obs, goal) -> (mean, log_std)`` before the tanh."""

    def __init__(
        self,
        obs_shape: tuple[int, ...],
        goal_dim: int,
        action_dim: int,
        cfg: NetConfig,
        encoder: nn.Module | None = None,
    ) -> None:
        super().__init__()
        self.encoder = encoder if encoder is not None else make_encoder(cfg.encoder, obs_shape)
        self.detach_encoder = encoder is not None
        feat = int(self.encoder.features_dim)  # type: ignore[arg-type]
        self.head = mlp([feat + goal_dim] + [cfg.head_width] * cfg.head_layers + [2 * action_dim])
        self.action_dim = action_dim

    def forward(
        self, obs: torch.Tensor, goal: torch.Tensor, features: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Mean and log-std; pass ``features`` (the pooled encoding) to skip the encoder."""
        h = self.encoder(obs) if features is None else features
        if self.detach_encoder:
            h = h.detach()
        out = self.head(torch.cat([h, goal], -1))
        mean, log_std = out.split(self.action_dim, -1)
        return mean, log_std.clamp(LOG_STD_MIN, LOG_STD_MAX)

    def sample(
        self, obs: torch.Tensor, goal: torch.Tensor, features: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """A reparameterised action in (-1, 1) and its log-probability ``(B,)``."""
        mean, log_std = self(obs, goal, features)
        std = log_std.exp()
        u = mean + std * torch.randn_like(mean)
        a = torch.tanh(u)
        logp = (-0.5 * ((u - mean) / std) ** 2 - log_std - 0.5 * math.log(2 * math.pi)).sum(-1)
        # log|d tanh(u)/du| = 2 (log 2 - u - softplus(-2u)), numerically stable
        logp = logp - (2 * (math.log(2) - u - nn.functional.softplus(-2 * u))).sum(-1)
        return a, logp

    def act(self, obs: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
        """The deterministic action ``tanh(mean)`` used for evaluation."""
        return torch.tanh(self(obs, goal)[0])


class QNetwork(nn.Module):
    """One Q-function ``Q(obs, goal, action) -> (B,)``."""

    def __init__(
        self,
        obs_shape: tuple[int, ...],
        goal_dim: int,
        action_dim: int,
        cfg: NetConfig,
        encoder: nn.Module | None = None,
    ) -> None:
        super().__init__()
        self.on_points = cfg.critic_action == "points"
        extra = action_dim if self.on_points else 0
        self.encoder = encoder if encoder is not None else make_encoder(cfg.encoder, obs_shape, extra=extra)
        feat = int(self.encoder.features_dim)  # type: ignore[arg-type]
        head_in = feat + goal_dim + (0 if self.on_points else action_dim)
        self.head = mlp([head_in] + [cfg.head_width] * cfg.head_layers + [1])

    def forward(
        self, obs: torch.Tensor, goal: torch.Tensor, action: torch.Tensor, features: torch.Tensor | None = None
    ) -> torch.Tensor:
        if self.on_points:
            h = self.encoder(obs, action)
            x = torch.cat([h, goal], -1)
        else:
            h = self.encoder(obs) if features is None else features
            x = torch.cat([h, goal, action], -1)
        return self.head(x).squeeze(-1)


class TwinCritic(nn.Module):
    """Two Q-networks; with a shared encoder the pooled features are computed once."""

    shared: nn.Module | None

    def __init__(
        self,
        obs_shape: tuple[int, ...],
        goal_dim: int,
        action_dim: int,
        cfg: NetConfig,
        encoder: nn.Module | None = None,
    ) -> None:
        super().__init__()
        self.shared = encoder
        self.q1 = QNetwork(obs_shape, goal_dim, action_dim, cfg, encoder)
        self.q2 = QNetwork(obs_shape, goal_dim, action_dim, cfg, encoder)

    def forward(
        self, obs: torch.Tensor, goal: torch.Tensor, action: torch.Tensor, features: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Both Q-values; with a shared encoder, ``features`` skips it."""
        if self.shared is not None and features is None:
            features = self.shared(obs)
        return self.q1(obs, goal, action, features), self.q2(obs, goal, action, features)


def build_networks(
    obs_shape: tuple[int, ...], goal_dim: int, action_dim: int, cfg: NetConfig
) -> tuple[Actor, TwinCritic]:
    """Actor and twin critic; with ``shared_encoder`` they share one encoder module (owned
    by the critic)."""
    if cfg.shared_encoder:
        enc = make_encoder(cfg.encoder, obs_shape)
        critic = TwinCritic(obs_shape, goal_dim, action_dim, cfg, enc)
        actor = Actor(obs_shape, goal_dim, action_dim, cfg, encoder=enc)
        return actor, critic
    return Actor(obs_shape, goal_dim, action_dim, cfg), TwinCritic(obs_shape, goal_dim, action_dim, cfg)
