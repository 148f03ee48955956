"""Fine-tuning a policy on-policy with PPO (clipped surrogate, GAE).

SAC improves the actor along its critics' action gradient; for the cloned S-shape those
critics ranked actions worse than chance draws from the actor itself, and every actor that
followed them lost its cloned skill (docs/notebook/sshape.md). PPO needs no
action gradient from a critic: it raises the probability of the sampled actions whose
return beat a state-value baseline, so a critic's error costs variance, not direction.
The actor starts from a cloned one (``init_actor``), whose sampled policy already solves
far more than its mean; PPO sharpens what the samples find.

``E`` workspaces step together through the batched core for ``rollout_steps`` steps; the
actions' pre-tanh draws ``u`` are stored, so the tanh's Jacobian cancels in the ratio of
new to old probabilities. A separate value network (same encoder shape as the actor) is
fitted to the returns; for ``value_warmup`` iterations it learns alone while the actor is
frozen. Every ``eval_every`` environment steps the mean action is rolled out on the
validation problems (the paper's protocol) and, optionally, with the robot's default
escape; ``best.pt`` keeps the best by the chosen criterion, ``last.pt`` the trainer state.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from ..config import from_dict
from ..envs.core import BatchedCore, EnvConfig
from ..models.actor_critic import Actor, NetConfig
from ..models.checkpoint import CheckpointError, load_checkpoint, to_dict
from ..models.encoders import make_encoder, mlp
from ..models.inputs import goal_dim, goal_input, obs_input
from ..scenes.scenarios import make_scenario
from ..scenes.scene import Problem
from .rundir import RunDir, best_note, best_or_none


@dataclass(frozen=True)
class PPOConfig:
    """A PPO fine-tuning run (saved with its checkpoints)."""

    #: the policy checkpoint whose actor (and network shape, scenario, observation) the run starts from
    init_actor: str = ""
    #: the scenario to train in; empty takes the initial policy's
    env: str = ""
    #: environments stepping together
    num_envs: int = field(default=32, metadata={"min": 1})
    #: steps of every environment per iteration (one batch of num_envs x rollout_steps transitions)
    rollout_steps: int = field(default=80, metadata={"min": 1})
    #: environment transitions to collect; the last rollout is cut short to stop here (rounded
    #: up to a multiple of num_envs, which step together)
    total_steps: int = field(default=2_000_000, metadata={"min": 1})
    #: passes over each batch
    epochs: int = field(default=4, metadata={"min": 1})
    #: transitions per gradient step
    minibatch: int = field(default=512, metadata={"min": 1})
    #: Adam step size of the actor
    lr: float = 3e-5
    #: Adam step size of the value network
    value_lr: float = 3e-4
    #: the ratio of new to old action probabilities is clipped to 1 +- this
    clip: float = 0.2
    #: stop an iteration's actor epochs once the approximate KL from the old policy passes this (0: never)
    target_kl: float = 0.02
    gamma: float = 0.99
    #: GAE's lambda
    lam: float = 0.95
    #: weight of the pre-tanh Gaussian's entropy in the actor's loss
    entropy_coef: float = 0.0
    #: iterations in which only the value network learns (the actor acts, frozen)
    value_warmup: int = 10
    #: rewards are multiplied by this for the value network (returns of order 1)
    reward_scale: float = 0.1
    #: gradient norm clip of both networks
    max_grad_norm: float = 0.5
    #: weight of the action's norm in the reward (the paper: 1; see ``EnvConfig.action_cost``)
    action_cost: float = field(default=1.0, metadata={"min": 0})
    #: reward of a step that collided (the environment's default: -4); a milder penalty
    #: keeps PPO from buying fewer collisions with less of the noise that finds the way round
    reward_collision: float = -4.0
    #: environment transitions between two validations (and checkpoints)
    eval_every: int = field(default=51_200, metadata={"min": 1})
    #: validation problems (the ``val`` split)
    eval_episodes: int = field(default=200, metadata={"min": 1})
    #: also validate with the robot's default escape (the planner's default rollout)
    eval_escape: bool = True
    #: what ``best.pt`` is chosen by: ``mean`` (the plain mean-action rollout) or ``escape``
    select: str = "mean"
    #: end an episode as solved once the straight edge to the goal is certified free, as the
    #: planner does (``PolicyPlanner(greedy_goal=True)``; static scenes); validation too
    greedy_goal: bool = False
    #: a demonstrations file (the one ``pointplan bc --demos FILE`` plans where FILE is
    #: missing, or ``scripts/slot_expert.py demos --save-demos FILE``) of this scenario: a share of the episodes start on its paths, a few steps
    #: before their goal, and further back as they succeed (a reverse curriculum)
    start_demos: str = ""
    #: the share of episodes started on a demonstration (the rest: fresh problems)
    start_share: float = field(default=0.8, metadata={"min": 0})
    #: a demonstration start is this many steps before its goal at most, at first (a path
    #: shorter than that starts at its own start)
    start_back: int = field(default=8, metadata={"min": 1})
    #: the frontier: the last this many steps of that range
    start_band: int = field(default=8, metadata={"min": 1})
    #: the share of demonstration starts drawn at the frontier (the rest: anywhere in the range)
    start_frontier_share: float = 0.5
    #: the range grows by this many steps once the frontier's episodes succeed often enough
    start_back_step: int = field(default=4, metadata={"min": 1})
    #: ... that is, once this share of the last ``start_min_episodes`` frontier episodes
    #: since the range last grew succeeded
    start_advance: float = 0.6
    #: frontier episodes judged each time (a sliding window, emptied when the range grows)
    start_min_episodes: int = field(default=32, metadata={"min": 1})
    seed: int = 0
    device: str = "cpu"

    def __post_init__(self) -> None:
        if self.select not in ("mean", "escape"):
            raise ValueError(f"select must be 'mean' or 'escape', not {self.select!r}")
        if self.select == "escape" and not self.eval_escape:
            raise ValueError("select='escape' needs eval_escape")
        if not 0 < self.gamma <= 1 or not 0 <= self.lam <= 1:
            raise ValueError("gamma must be in (0, 1] and lam in [0, 1]")
        if self.clip <= 0:
            raise ValueError(f"clip must be > 0, not {self.clip}")
        if not 0 <= self.start_share <= 1 or not 0 <= self.start_frontier_share <= 1 or not 0 < self.start_advance <= 1:
            raise ValueError("start_share and start_frontier_share must be in [0, 1], start_advance in (0, 1]")


class ValueNetwork(nn.Module):
    """``V(obs, goal) -> (B,)``: an encoder of its own and an MLP head."""

    def __init__(self, obs_shape: tuple[int, ...], goal_dim: int, cfg: NetConfig) -> None:
        super().__init__()
        self.encoder = make_encoder(cfg.encoder, obs_shape)
        feat = int(self.encoder.features_dim)  # type: ignore[arg-type]
        self.head = mlp([feat + goal_dim] + [cfg.head_width] * cfg.head_layers + [1])

    def forward(self, obs: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
        return self.head(torch.cat([self.encoder(obs), goal], -1)).squeeze(-1)


def gaussian_logp(u: torch.Tensor, mean: torch.Tensor, log_std: torch.Tensor) -> torch.Tensor:
    """Log-density of pre-tanh draws ``u`` under ``N(mean, exp(log_std))``, summed over the
    action's axes (the tanh's Jacobian depends on ``u`` only and cancels in PPO's ratio)."""
    z = (u - mean) * torch.exp(-log_std)
    return (-0.5 * z**2 - log_std - 0.5 * math.log(2 * math.pi)).sum(-1)


def gae(
    rewards: np.ndarray, values: np.ndarray, next_values: np.ndarray, dones: np.ndarray, gamma: float, lam: float
) -> tuple[np.ndarray, np.ndarray]:
    """Advantages and returns of ``(T, E)`` arrays: ``next_values[t]`` is the value of what
    follows step ``t`` (0 after a success, the final state's value after a time limit);
    ``dones[t]`` cuts the sum of TD errors where an episode ended."""
    T = rewards.shape[0]
    adv = np.zeros_like(rewards)
    last = np.zeros(rewards.shape[1:], dtype=rewards.dtype)
    for t in range(T - 1, -1, -1):
        delta = rewards[t] + gamma * next_values[t] - values[t]
        last = delta + gamma * lam * (1.0 - dones[t]) * last
        adv[t] = last
    return adv, adv + values


@dataclass
class _Batch:
    obs: np.ndarray
    goal: np.ndarray
    u: np.ndarray
    logp: np.ndarray
    adv: np.ndarray
    ret: np.ndarray


class PPORun:
    """The pieces of a PPO run and its counters (built by :func:`train_ppo`)."""

    def __init__(self, cfg: PPOConfig, run_dir: Path | RunDir, resume: str | Path | None) -> None:
        self.cfg = cfg
        self.folder = run_dir if isinstance(run_dir, RunDir) else RunDir(run_dir, "pointplan ppo")
        self.run_dir = self.folder.path
        init = load_checkpoint(resume if resume is not None else cfg.init_actor, cfg.device)
        self.meta = {k: init[k] for k in ("env", "robot", "observation", "n_points", "obs_shape", "net")}
        if cfg.env:
            self.meta["env"] = cfg.env
        self.scenario = make_scenario(self.meta["env"], robot=self.meta["robot"])
        self.robot = self.scenario.robot
        self.env_cfg = EnvConfig(
            observation=self.meta["observation"],
            n_points=self.meta["n_points"],
            split="train",
            action_cost=cfg.action_cost,
            reward_collision=cfg.reward_collision,
        )
        self.core = BatchedCore(self.scenario, cfg.num_envs, self.env_cfg)
        self.obs_shape = tuple(self.core.observer.space.shape)
        if list(self.obs_shape) != list(self.meta["obs_shape"]):
            raise CheckpointError(
                f"the initial policy sees observations of shape {self.meta['obs_shape']}, this environment gives {list(self.obs_shape)}"
            )
        self.net = from_dict(NetConfig, self.meta["net"])
        self.device = torch.device(cfg.device)
        torch.manual_seed(cfg.seed)
        k = self.robot.twist_dim
        self.actor = Actor(self.obs_shape, goal_dim(self.robot), k, self.net).to(self.device)
        self.actor.detach_encoder = False
        self.actor.load_state_dict(init["actor"])
        self.value = ValueNetwork(self.obs_shape, goal_dim(self.robot), self.net).to(self.device)
        self.opt_actor = torch.optim.Adam(self.actor.parameters(), lr=cfg.lr)
        self.opt_value = torch.optim.Adam(self.value.parameters(), lr=cfg.value_lr)
        self.rng = np.random.default_rng(cfg.seed)
        self.steps = 0
        self.iterations = 0
        self.best = -1.0
        self.elapsed_before = 0.0
        self.recent: list[float] = []
        if resume is not None:
            self._restore(resume, init)
            before = init.get("ppo_config", {})
            if (before.get("eval_episodes"), before.get("select")) != (cfg.eval_episodes, cfg.select):
                self.best = -1.0  # another validation: the best so far is not comparable, best.pt starts afresh
        for g in self.opt_actor.param_groups:  # a resumed run takes the step sizes given now
            g["lr"] = cfg.lr
        for g in self.opt_value.param_groups:
            g["lr"] = cfg.value_lr
        self.val_problems = self.scenario.problems("val", cfg.eval_episodes, seed=cfg.seed)
        if cfg.greedy_goal and any(p.scene.dynamic for p in self.val_problems):
            raise ValueError("greedy_goal connects to the goal in static scenes only")
        # the reverse curriculum: starts on demonstration paths, ``back`` steps from the goal at most
        self.demo_paths: list[tuple[Problem, np.ndarray]] = []
        self.back = cfg.start_back
        self.from_demo = np.zeros(cfg.num_envs, bool)
        self.at_frontier = np.zeros(cfg.num_envs, bool)
        self.recent_demo: list[float] = []
        self.frontier: list[float] = []  # outcomes of the frontier episodes since the range last grew
        if cfg.start_demos:
            from .bc import load_demos

            demos = load_demos(cfg.start_demos, self.scenario)
            by_index: dict[int, Problem] = {}
            for k, _ in demos.paths:  # the problems are listed in the order their indices first appear
                if k not in by_index:  # (a problem may have several paths: a roadmap expert's)
                    by_index[k] = demos.problems[len(by_index)]
            self.demo_paths = [(by_index[k], path) for k, path in demos.paths if len(path) >= 2]
            if not self.demo_paths:
                raise ValueError(f"{cfg.start_demos}: no demonstration path to start on")
        if resume is not None and "back" in init["ppo"]:
            self.back = int(init["ppo"]["back"])
            self.frontier = [float(x) for x in init["ppo"].get("frontier", [])]
        self.reset(range(cfg.num_envs))
        self.obs = self.core.observe(self.rng)["observation"]
        self.t_start = time.perf_counter()
        self.next_eval = (self.steps // cfg.eval_every + 1) * cfg.eval_every
        self.history: list[dict[str, float]] = []

    def _restore(self, resume: str | Path, init: dict[str, Any]) -> None:
        """Continue the run saved in ``resume`` (read as ``init``): the value network, the
        optimisers, the counters and the random state."""
        if "ppo" not in init:
            raise CheckpointError(f"{resume}: not a PPO trainer state (resume from a PPO run's last.pt)")
        st = init["ppo"]
        self.value.load_state_dict(st["value"])
        self.opt_actor.load_state_dict(st["opt_actor"])
        self.opt_value.load_state_dict(st["opt_value"])
        self.steps, self.iterations, self.best = int(st["steps"]), int(st["iterations"]), float(st["best"])
        self.elapsed_before = float(st["wall_time_s"])
        self.rng.bit_generator.state = st["rng"]
        torch.set_rng_state(st["torch_rng"])

    def reset(self, idx: Iterable[int]) -> None:
        """New episodes in environments ``idx``: on a demonstration path (a share
        ``start_share`` of them, when there are demonstrations) or a fresh problem."""
        cfg = self.cfg
        idx = list(idx)
        problems: list[Problem | None] = []
        for i in idx:
            use = bool(self.demo_paths) and self.rng.random() < cfg.start_share
            self.from_demo[i] = use
            self.at_frontier[i] = False
            if not use:
                problems.append(None)
                continue
            prob, path = self.demo_paths[int(self.rng.integers(len(self.demo_paths)))]
            low = max(1, self.back - cfg.start_band + 1) if self.rng.random() < cfg.start_frontier_share else 1
            k = min(int(self.rng.integers(low, self.back + 1)), len(path) - 1)
            self.at_frontier[i] = k > self.back - cfg.start_band
            problems.append(Problem(prob.scene, path[len(path) - 1 - k].copy(), prob.goal, prob.tag))
        self.core.reset_envs(idx, self.rng, problems)

    def greedy(
        self, reward: np.ndarray, term: np.ndarray, trunc: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The planner's goal test after a step: where the episode goes on and the straight
        edge to the goal is free, it ends solved, with the arrival reward."""
        from ..planners.edges import edge_free

        core = self.core
        reward, term, trunc = reward.copy(), term.copy(), trunc.copy()
        for i in np.flatnonzero(~term):
            sc = core.scenes[i]
            assert sc is not None
            if edge_free(self.robot, sc.world, core.q[i], core.goal[i], 0.01, sc.low, sc.high)[0]:
                term[i], trunc[i] = True, False
                reward[i] += self.env_cfg.reward_success
        return reward, term, trunc

    def advance(self) -> None:
        """Move the demonstration starts further back once enough of those at the frontier
        succeed (judged on the last ``start_min_episodes`` of them since the last move)."""
        cfg = self.cfg
        longest = max((len(p) - 1 for _, p in self.demo_paths), default=0)
        self.frontier = self.frontier[-cfg.start_min_episodes :]
        if (
            len(self.frontier) == cfg.start_min_episodes
            and np.mean(self.frontier) >= cfg.start_advance
            and self.back < longest
        ):
            self.back = min(self.back + cfg.start_back_step, longest)
            self.frontier = []

    @property
    def wall(self) -> float:
        return self.elapsed_before + time.perf_counter() - self.t_start

    def tensor(self, x: np.ndarray) -> torch.Tensor:
        return torch.as_tensor(np.asarray(x, np.float32), device=self.device)

    # ------------------------------------------------------------------ collection
    def collect(self, steps: int | None = None) -> _Batch:
        """``steps`` (default ``rollout_steps``) steps of every environment with sampled actions."""
        cfg, core, robot = self.cfg, self.core, self.robot
        T, E = steps or cfg.rollout_steps, cfg.num_envs
        obs_b = np.zeros((T, E) + self.obs_shape, np.float32)
        goal_b = np.zeros((T, E, goal_dim(robot)), np.float32)
        u_b = np.zeros((T, E, robot.twist_dim), np.float32)
        logp_b = np.zeros((T, E), np.float32)
        val_b = np.zeros((T, E), np.float32)
        rew_b = np.zeros((T, E), np.float32)
        next_b = np.zeros((T, E), np.float32)
        done_b = np.zeros((T, E), np.float32)
        truncated_at: list[tuple[int, np.ndarray, np.ndarray, np.ndarray]] = []
        with torch.no_grad():
            for t in range(T):
                o = obs_input(robot, self.obs)
                g = goal_input(robot, core.q, core.goal)
                ot, gt = self.tensor(o), self.tensor(g)
                mean, log_std = self.actor(ot, gt)
                u = mean + log_std.exp() * torch.randn_like(mean)
                obs_b[t], goal_b[t], u_b[t] = o, g, u.cpu().numpy()
                logp_b[t] = gaussian_logp(u, mean, log_std).cpu().numpy()
                val_b[t] = self.value(ot, gt).cpu().numpy()
                reward, term, trunc, _ = core.step(torch.tanh(u).cpu().numpy())
                if cfg.greedy_goal:
                    reward, term, trunc = self.greedy(reward, term, trunc)
                rew_b[t] = reward * cfg.reward_scale
                done = term | trunc
                done_b[t] = done
                nxt = core.observe(self.rng)["observation"]
                if trunc.any():  # a time limit: what follows is worth the final state's value
                    idx = np.flatnonzero(trunc)
                    truncated_at.append(
                        (t, idx, obs_input(robot, nxt[idx]), goal_input(robot, core.q[idx], core.goal[idx]))
                    )
                if done.any():
                    ended = np.flatnonzero(done)
                    demo = [i for i in ended if self.from_demo[i]]
                    self.frontier += [float(term[i]) for i in ended if self.at_frontier[i]]
                    self.recent_demo = (self.recent_demo + [float(term[i]) for i in demo])[-400:]
                    self.recent = (self.recent + [float(term[i]) for i in ended if not self.from_demo[i]])[-400:]
                    self.reset(ended.tolist())
                    fresh = core.observe(self.rng)["observation"]
                    nxt = np.where(done.reshape((-1,) + (1,) * len(self.obs_shape)), fresh, nxt)
                self.obs = nxt
            last_v = (
                self.value(self.tensor(obs_input(robot, self.obs)), self.tensor(goal_input(robot, core.q, core.goal)))
                .cpu()
                .numpy()
            )
            next_b[:-1] = val_b[1:]
            next_b[-1] = last_v
            next_b *= 1.0 - done_b  # successes and time limits: nothing (time limits get their value below)
            for t, idx, o, g in truncated_at:
                next_b[t, idx] = self.value(self.tensor(o), self.tensor(g)).cpu().numpy()
        adv, ret = gae(rew_b, val_b, next_b, done_b, cfg.gamma, cfg.lam)
        self.steps += T * E
        if self.demo_paths:
            self.advance()
        flat = lambda x: x.reshape((T * E,) + x.shape[2:])  # noqa: E731
        return _Batch(flat(obs_b), flat(goal_b), flat(u_b), flat(logp_b), flat(adv), flat(ret))

    # ------------------------------------------------------------------ learning
    def update(self, batch: _Batch) -> dict[str, float]:
        cfg = self.cfg
        n = len(batch.adv)
        adv = (batch.adv - batch.adv.mean()) / (batch.adv.std() + 1e-8)
        obs, goal, u = self.tensor(batch.obs), self.tensor(batch.goal), self.tensor(batch.u)
        old_logp, adv_t, ret = self.tensor(batch.logp), self.tensor(adv), self.tensor(batch.ret)
        train_actor = self.iterations >= cfg.value_warmup
        stats: dict[str, list[float]] = {
            "value_loss": [],
            "policy_loss": [],
            "approx_kl": [],
            "clip_frac": [],
            "entropy": [],
        }
        actor_on = train_actor
        for _ in range(cfg.epochs):
            perm = torch.as_tensor(self.rng.permutation(n), device=self.device)
            kls = []
            for s in range(0, n, cfg.minibatch):
                b = perm[s : s + cfg.minibatch]
                v = self.value(obs[b], goal[b])
                v_loss = ((v - ret[b]) ** 2).mean()
                self.opt_value.zero_grad(set_to_none=True)
                v_loss.backward()
                nn.utils.clip_grad_norm_(self.value.parameters(), cfg.max_grad_norm)
                self.opt_value.step()
                stats["value_loss"].append(float(v_loss.detach()))
                if not actor_on:
                    continue
                mean, log_std = self.actor(obs[b], goal[b])
                logp = gaussian_logp(u[b], mean, log_std)
                log_ratio = logp - old_logp[b]
                ratio = log_ratio.exp()
                surr = torch.min(ratio * adv_t[b], ratio.clamp(1 - cfg.clip, 1 + cfg.clip) * adv_t[b])
                entropy = (log_std + 0.5 * math.log(2 * math.pi * math.e)).sum(-1).mean()
                loss = -surr.mean() - cfg.entropy_coef * entropy
                self.opt_actor.zero_grad(set_to_none=True)
                loss.backward()
                nn.utils.clip_grad_norm_(self.actor.parameters(), cfg.max_grad_norm)
                self.opt_actor.step()
                with torch.no_grad():
                    kl = float(((ratio - 1) - log_ratio).mean())  # the k3 estimator of KL(old || new)
                    kls.append(kl)
                    stats["approx_kl"].append(kl)
                    stats["clip_frac"].append(float(((ratio - 1).abs() > cfg.clip).float().mean()))
                stats["policy_loss"].append(float(loss.detach()))
                stats["entropy"].append(float(entropy.detach()))
            if actor_on and cfg.target_kl > 0 and kls and np.mean(kls) > cfg.target_kl:
                actor_on = False  # the value network finishes its epochs alone
        self.iterations += 1
        return {k: float(np.mean(v)) for k, v in stats.items() if v}  # (the actor's are missing while it is frozen)

    # ------------------------------------------------------------------ validation
    def validate(self) -> dict[str, float]:
        from ..planners.rollout import default_escape, rollout_batch

        robot, actor = self.robot, self.actor
        env = EnvConfig(observation=self.meta["observation"], n_points=self.meta["n_points"], split="val")

        def act(o: np.ndarray, q: np.ndarray, g: np.ndarray, noise: np.ndarray | None = None) -> np.ndarray:
            with torch.no_grad():
                mean, log_std = actor(self.tensor(obs_input(robot, o)), self.tensor(goal_input(robot, q, g)))
                if noise is not None:
                    mean = mean + log_std.exp() * self.tensor(noise)
                return torch.tanh(mean).cpu().numpy()

        actor.eval()
        row: dict[str, float] = {}
        greedy = self.cfg.greedy_goal
        res = rollout_batch(
            act, robot, env, self.val_problems, self.scenario.horizon, seed=self.cfg.seed, greedy_goal=greedy
        )
        row["val_success"] = float(np.mean([r.success for r in res]))
        solved = [r.nodes for r in res if r.success]
        row["val_steps"] = float(np.mean(solved)) if solved else 0.0
        escape = default_escape(robot)
        if self.cfg.eval_escape and escape is not None:
            res = rollout_batch(
                act,
                robot,
                env,
                self.val_problems,
                self.scenario.horizon,
                seed=self.cfg.seed,
                escape=escape,
                noise_rng=np.random.default_rng(self.cfg.seed),
                greedy_goal=greedy,
            )
            row["val_success_escape"] = float(np.mean([r.success for r in res]))
        actor.train()
        return row

    # ------------------------------------------------------------------ checkpoints
    def payload(self) -> dict[str, Any]:
        return {
            **self.meta,
            "actor": self.actor.state_dict(),
            "horizon": self.scenario.horizon,
            "ppo_config": to_dict(self.cfg),
            "env_steps": self.steps,
        }

    def save(self, row: dict[str, float] | None) -> None:
        payload = self.payload()
        state = {
            "value": self.value.state_dict(),
            "opt_actor": self.opt_actor.state_dict(),
            "opt_value": self.opt_value.state_dict(),
            "steps": self.steps,
            "iterations": self.iterations,
            "best": self.best,
            "back": self.back,
            "frontier": list(self.frontier),
            "wall_time_s": self.wall,
            "rng": self.rng.bit_generator.state,
            "torch_rng": torch.get_rng_state(),
        }
        if row is not None:
            key = "val_success_escape" if self.cfg.select == "escape" else "val_success"
            if row[key] > self.best:
                self.best = row[key]
                state["best"] = self.best
                self.folder.save(
                    "best.pt",
                    {**payload, "val_success": row["val_success"], **{k: row[k] for k in row if k.startswith("val_")}},
                )
        self.folder.save("last.pt", {**payload, "ppo": state})

    def next_rollout(self) -> int:
        """Steps of every environment in the next iteration: ``rollout_steps``, fewer for
        the last one, so that the run stops at ``total_steps`` (rounded up to a multiple of
        ``num_envs``)."""
        left = self.cfg.total_steps - self.steps
        return max(1, min(self.cfg.rollout_steps, -(-left // self.cfg.num_envs)))

    def row(self, losses: dict[str, float]) -> dict[str, float]:
        """The metrics of a validation now: counters, validation, training success, curriculum, losses."""
        row = {"env_steps": float(self.steps), "iterations": float(self.iterations), "wall_time_s": self.wall}
        row.update(self.validate())
        row["train_success"] = float(np.mean(self.recent)) if self.recent else 0.0
        if self.demo_paths:
            row["start_back"] = float(self.back)
            row["demo_start_success"] = float(np.mean(self.recent_demo)) if self.recent_demo else 0.0
            if self.frontier:
                row["frontier_success"] = float(np.mean(self.frontier))
        row.update(losses)
        return row

    def postfix(self) -> dict[str, str]:
        """The progress bar's figures."""
        post = {"train_success": f"{np.mean(self.recent) if self.recent else 0:.2f}"}
        if self.best >= 0:
            post["best"] = f"{self.best:.3f}"
        if self.demo_paths:
            post.update(back=str(self.back), demo_success=f"{np.mean(self.recent_demo) if self.recent_demo else 0:.2f}")
        return post


def train_ppo(
    cfg: PPOConfig, run_dir: str | Path, resume: str | Path | None = None, progress: bool = True
) -> dict[str, Any]:
    """Fine-tune ``cfg.init_actor`` (or continue ``resume``'s run) with PPO; checkpoints
    ``best.pt`` and ``last.pt``, ``metrics.csv`` and TensorBoard logs in ``run_dir``. Ctrl-C
    stops after the current iteration and saves the trainer state. Returns a summary."""
    if not cfg.init_actor and resume is None:
        raise ValueError("PPO fine-tunes a policy: give init_actor (a checkpoint, e.g. from `pointplan bc`)")
    folder = RunDir(run_dir, "pointplan ppo")
    run = PPORun(cfg, folder, resume)
    if run.steps >= cfg.total_steps:
        raise ValueError(
            f"{resume}: the run has done {run.steps} steps already; set total_steps above that to continue it"
        )
    if resume is not None:
        folder.metrics.drop_after(run.steps)
    bar = None
    if progress:
        from ..progress import progress_bar

        bar = progress_bar(total=cfg.total_steps, initial=run.steps, unit="step", dynamic_ncols=True)
    if run.steps == 0:  # the starting policy, for the curve
        row = {"env_steps": 0.0, "iterations": 0.0, "wall_time_s": run.wall, **run.validate()}
        folder.log(row)
        run.history.append(row)
        if bar is not None:
            bar.write("start: " + " ".join(f"{k}={v:.4g}" for k, v in row.items()))
    with folder.ctrl_c() as ctrl_c:
        while run.steps < cfg.total_steps and not ctrl_c.requested:
            before = run.steps
            losses = run.update(run.collect(run.next_rollout()))
            if bar is not None:
                bar.set_postfix(run.postfix(), refresh=False)  # first: the update may draw the bar
                bar.update(min(run.steps, cfg.total_steps) - min(before, cfg.total_steps))
            if run.steps >= run.next_eval or run.steps >= cfg.total_steps:
                run.next_eval += cfg.eval_every
                row = run.row(losses)
                folder.log(row)
                run.history.append(row)
                run.save(row)
                if bar is not None:
                    bar.write(" ".join(f"{k}={v:.4g}" for k, v in row.items()))
    if bar is not None:
        bar.close()
    best = best_or_none(run.best)
    if ctrl_c.requested:
        folder.interrupted(f"at step {run.steps}", lambda: run.save(None), best_note(best))
    folder.close()
    return {
        "run_dir": str(run.run_dir),
        "best_success": best,
        "steps": run.steps,
        "wall_time_s": run.wall,
        "interrupted": ctrl_c.requested,
    }
