"""Soft actor-critic with automatic entropy tuning, on goal-conditioned batches.

One file, top to bottom: ``SAC.update`` takes a replay ``Batch`` (with hindsight goals),
recomputes rewards and goal vectors in the robot frame, and takes one gradient step for
the critics, the actor and the temperature.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch
from torch import nn

from ..envs.core import EnvConfig, goal_reached, step_reward
from ..models.actor_critic import Actor, NetConfig, build_networks
from ..models.inputs import goal_dim, goal_input, obs_input
from ..robots.base import Robot
from .replay import Batch


@dataclass
class DemoBatch:
    """Demonstration steps for the cloning term: observations and goal vectors as network
    inputs, and the expert's actions in [-1, 1]."""

    obs: torch.Tensor
    goal: torch.Tensor
    action: torch.Tensor


@dataclass(frozen=True)
class SACConfig:
    """SAC hyperparameters; defaults are the paper's."""

    #: Adam step size of actor, critics and temperature
    lr: float = 3e-4
    #: transitions per gradient step
    batch_size: int = field(default=256, metadata={"min": 1})
    #: discount factor
    gamma: float = 0.99
    #: rate of the target critics' running average
    tau: float = 5e-3
    #: target entropy per action dimension (the target is this times dim(A))
    target_entropy_scale: float = -1.0
    #: initial entropy temperature
    init_alpha: float = 1.0
    #: share of sampled transitions whose goal is relabelled (hindsight)
    her_ratio: float = 0.8
    #: replay buffer capacity in transitions
    buffer_size: int = field(default=1_000_000, metadata={"min": 1})
    #: critic-only updates before the actor and temperature start to move (useful when the
    #: actor starts from behavioural cloning and the critic from scratch)
    actor_delay: int = 0
    #: rate of a running (exponential) average of the actor's weights, updated after every
    #: gradient step; when > 0 the averaged actor is the one evaluated and saved as the policy
    #: (0: off). 3e-5 averages over roughly the last 30,000 updates.
    policy_avg: float = 0.0
    #: weight of a behavioural-cloning term in the actor's loss: the squared distance from
    #: the actor's mean action to the expert's on a batch of demonstration steps (0: off;
    #: needs demonstrations, ``TrainConfig.demos``). Keeps the actor near the demonstrations
    #: while the critics are poor (as in Nair et al. 2018 and TD3+BC)
    bc_weight: float = field(default=0.0, metadata={"min": 0})
    #: apply the cloning term only where the critics rate the expert's action above the
    #: actor's (Nair et al.'s Q-filter)
    bc_q_filter: bool = False
    #: divide the actor's SAC term by the batch's mean |Q| (detached), so that the cloning
    #: term's weight does not depend on the scale of the values (as TD3+BC does)
    bc_q_normalise: bool = False


def batch_rewards(robot: Robot, env: EnvConfig, b: Batch) -> tuple[np.ndarray, np.ndarray]:
    """Rewards and success flags of (possibly relabelled) transitions, as the env gives them."""
    success = goal_reached(robot, env, b.q_next, b.goal, b.collided)
    return step_reward(env, b.action_norm, b.collided, success), success


class SAC:
    """Actor, twin critic, target critic and temperature, with their optimisers."""

    def __init__(
        self,
        robot: Robot,
        env: EnvConfig,
        obs_shape: tuple[int, ...],
        net: NetConfig,
        cfg: SACConfig,
        device: str = "cpu",
    ) -> None:
        self.robot, self.env, self.cfg, self.net_cfg = robot, env, cfg, net
        self.device = torch.device(device)
        self.actor, self.critic = build_networks(obs_shape, goal_dim(robot), robot.twist_dim, net)
        self.actor.to(self.device)
        self.critic.to(self.device)
        self.critic_target = copy.deepcopy(self.critic).requires_grad_(False)
        actor_params = self.actor.head.parameters() if self.actor.detach_encoder else self.actor.parameters()
        self.actor_opt = torch.optim.Adam(actor_params, lr=cfg.lr)
        self.critic_opt = torch.optim.Adam(self.critic.parameters(), lr=cfg.lr)
        self.log_alpha = torch.tensor(
            np.log(cfg.init_alpha), dtype=torch.float32, device=self.device, requires_grad=True
        )
        self.alpha_opt = torch.optim.Adam([self.log_alpha], lr=cfg.lr)
        self.target_entropy = cfg.target_entropy_scale * robot.twist_dim
        self.updates = 0
        #: the running average of the actor (weights and encoder), or None when off
        self.actor_avg = self._new_average() if cfg.policy_avg > 0 else None

    def _new_average(self) -> Actor:
        avg = copy.deepcopy(self.actor).requires_grad_(False).eval()
        avg.detach_encoder = False  # its encoder is its own copy
        # (average, actor) tensor pairs, found once: state_dict tensors share storage with the
        # modules, and loading a state copies into them in place
        pairs = list(zip(avg.state_dict().values(), self.actor.state_dict().values()))
        self._avg_float = [(a, p) for a, p in pairs if a.dtype.is_floating_point]
        self._avg_other = [(a, p) for a, p in pairs if not a.dtype.is_floating_point]
        return avg

    @property
    def policy_actor(self) -> Actor:
        """The actor that evaluation and checkpoints use: the averaged one when kept."""
        return self.actor_avg if self.actor_avg is not None else self.actor

    # ------------------------------------------------------------------ helpers
    def tensor(self, x: np.ndarray) -> torch.Tensor:
        return torch.as_tensor(np.asarray(x, np.float32), device=self.device)

    def goal_vectors(self, q: np.ndarray, goal: np.ndarray) -> torch.Tensor:
        return self.tensor(goal_input(self.robot, q, goal))

    def observations(self, obs: np.ndarray) -> torch.Tensor:
        return self.tensor(obs_input(self.robot, obs))

    @torch.no_grad()
    def act(
        self, obs: np.ndarray, q: np.ndarray, goal: np.ndarray, deterministic: bool = False, averaged: bool = False
    ) -> np.ndarray:
        """Actions for collection (sampled) or evaluation (``deterministic``); ``averaged``
        uses the running average of the actor when one is kept."""
        o, g = self.observations(obs), self.goal_vectors(q, goal)
        actor = self.policy_actor if averaged else self.actor
        a = actor.act(o, g) if deterministic else actor.sample(o, g)[0]
        return a.cpu().numpy()

    # ------------------------------------------------------------------ update
    def update(self, b: Batch, demo: DemoBatch | None = None) -> dict[str, float]:
        """One gradient step; ``demo`` adds the cloning term (``cfg.bc_weight``) to the
        actor's loss."""
        reward, success = batch_rewards(self.robot, self.env, b)
        obs, next_obs = self.observations(b.obs), self.observations(b.next_obs)
        g, g_next = self.goal_vectors(b.q, b.goal), self.goal_vectors(b.q_next, b.goal)
        a = self.tensor(b.action)
        r = self.tensor(reward)
        not_done = self.tensor(~success)  # bootstrapping stops only on success
        alpha = self.log_alpha.exp().detach()

        encoder = self.critic.shared
        with torch.no_grad():
            h_next = encoder(next_obs) if encoder is not None else None
            a2, logp2 = self.actor.sample(next_obs, g_next, h_next)
            q1t, q2t = self.critic_target(next_obs, g_next, a2)
            target = r + self.cfg.gamma * not_done * (torch.min(q1t, q2t) - alpha * logp2)
        h = encoder(obs) if encoder is not None else None
        q1, q2 = self.critic(obs, g, a, h)
        critic_loss = nn.functional.mse_loss(q1, target) + nn.functional.mse_loss(q2, target)
        self.critic_opt.zero_grad(set_to_none=True)
        critic_loss.backward()
        self.critic_opt.step()

        if self.updates < self.cfg.actor_delay:
            self._soft_update()
            self._average()
            self.updates += 1
            return {"critic_loss": critic_loss.item(), "alpha": float(alpha), "q_mean": q1.mean().item()}

        # With a shared encoder the actor and the critic heads reuse the pooled features
        # computed for the critic loss (detached: only the critic's loss trains the encoder).
        h_pi = h.detach() if h is not None else None
        self.critic.requires_grad_(False)
        a_pi, logp = self.actor.sample(obs, g, h_pi)
        q1p, q2p = self.critic(obs, g, a_pi, h_pi)
        q_pi = torch.min(q1p, q2p)
        actor_loss = (alpha * logp - q_pi).mean()
        if self.cfg.bc_q_normalise:
            actor_loss = actor_loss / q_pi.detach().abs().mean().clamp_min(1e-6)
        extra: dict[str, float] = {}
        if demo is not None and self.cfg.bc_weight > 0:
            bc = self._cloning_loss(demo)
            extra["bc_loss"] = bc.item()
            actor_loss = actor_loss + self.cfg.bc_weight * bc
        self.actor_opt.zero_grad(set_to_none=True)
        actor_loss.backward()
        self.actor_opt.step()
        self.critic.requires_grad_(True)

        alpha_loss = -(self.log_alpha * (logp.detach() + self.target_entropy)).mean()
        self.alpha_opt.zero_grad(set_to_none=True)
        alpha_loss.backward()
        self.alpha_opt.step()

        self._soft_update()
        self._average()
        self.updates += 1
        return {
            "critic_loss": critic_loss.item(),
            "actor_loss": actor_loss.item(),
            "alpha": float(alpha),
            "q_mean": q1.mean().item(),
            "entropy": -logp.mean().item(),
            **extra,
        }

    def _cloning_loss(self, demo: DemoBatch) -> torch.Tensor:
        """Mean squared distance (summed over the action's axes) from the actor's mean
        action to the expert's; with the Q-filter, only over the steps where the critics
        (frozen here) prefer the expert's action."""
        mean_action = self.actor.act(demo.obs, demo.goal)
        err = ((mean_action - demo.action) ** 2).sum(-1)
        if not self.cfg.bc_q_filter:
            return err.mean()
        with torch.no_grad():
            q_expert = torch.min(*self.critic(demo.obs, demo.goal, demo.action))
            q_actor = torch.min(*self.critic(demo.obs, demo.goal, mean_action.detach()))
            keep = (q_expert > q_actor).float()
        return (err * keep).sum() / keep.sum().clamp(min=1.0)

    @torch.no_grad()
    def _soft_update(self) -> None:
        for p, pt in zip(self.critic.parameters(), self.critic_target.parameters()):
            pt.mul_(1 - self.cfg.tau).add_(p, alpha=self.cfg.tau)

    @torch.no_grad()
    def _average(self) -> None:
        if self.actor_avg is None:
            return
        rate = self.cfg.policy_avg
        for pa, p in self._avg_float:
            pa.mul_(1 - rate).add_(p, alpha=rate)
        for pa, p in self._avg_other:
            pa.copy_(p)

    # ------------------------------------------------------------------ state
    def state_dict(self) -> dict[str, Any]:
        return {
            "actor": self.actor.state_dict(),
            "critic": self.critic.state_dict(),
            "critic_target": self.critic_target.state_dict(),
            "log_alpha": self.log_alpha.detach().cpu(),
            "actor_opt": self.actor_opt.state_dict(),
            "critic_opt": self.critic_opt.state_dict(),
            "alpha_opt": self.alpha_opt.state_dict(),
            "updates": self.updates,
            **({"actor_avg": self.actor_avg.state_dict()} if self.actor_avg is not None else {}),
        }

    def load_actor(self, actor_state: dict[str, Any]) -> None:
        """Start from given actor weights (e.g. behavioural cloning's): the running average,
        when kept, starts from them too (not from the random weights it was built with)."""
        self.actor.load_state_dict(actor_state)
        if self.actor_avg is not None:
            self.actor_avg.load_state_dict(actor_state)

    def set_lr(self, lr: float) -> None:
        """Change the Adam step size of every optimiser (e.g. when resuming a run)."""
        for opt in (self.actor_opt, self.critic_opt, self.alpha_opt):
            for group in opt.param_groups:
                group["lr"] = lr

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.actor.load_state_dict(state["actor"])
        self.critic.load_state_dict(state["critic"])
        self.critic_target.load_state_dict(state["critic_target"])
        with torch.no_grad():
            self.log_alpha.copy_(state["log_alpha"])
        self.actor_opt.load_state_dict(state["actor_opt"])
        self.critic_opt.load_state_dict(state["critic_opt"])
        self.alpha_opt.load_state_dict(state["alpha_opt"])
        self.updates = int(state["updates"])
        if self.actor_avg is not None:  # a run that kept no average starts one from its actor
            self.actor_avg.load_state_dict(state.get("actor_avg", state["actor"]))
