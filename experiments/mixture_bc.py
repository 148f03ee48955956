"""Does a multi-modal policy clone the S-shape's expert better? (exploratory)

The cloned S-shape actor's mean action stalls at the first obstacle, while its sampled
actions get round it (docs/notebook/sshape.md). One reading: where the
demonstrations go round an obstacle on either side, a single Gaussian's mean points between
them. This fits a mixture of ``K`` Gaussians (diagonal, in action space) on the same
demonstrations, with the same PointNet encoder and head as ``pointplan bc``, and rolls out
on the validation problems:

- ``mode``: the mean of the most probable component (one deterministic action, as the
  paper evaluates a policy);
- ``sample``: a component drawn by its weight, then its mean.

    python experiments/mixture_bc.py runs/demos_boxes3d_sshape_3k.npz --components 1 5 --epochs 40

``--components 1`` is the single-Gaussian baseline under the same training loop.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
import torch
from torch import nn


class MixtureActor(nn.Module):
    """PointNet encoder and an MLP head giving ``K`` mixture logits, means and log-stds."""

    def __init__(self, obs_shape: tuple[int, ...], goal_dim: int, action_dim: int, k: int, width: int, layers: int) -> None:
        super().__init__()
        from pointplan.models.encoders import EncoderConfig, make_encoder, mlp

        self.encoder = make_encoder(EncoderConfig("pointnet", width, layers), obs_shape)
        feat = int(getattr(self.encoder, "features_dim"))
        self.k, self.dim = k, action_dim
        self.head = mlp([feat + goal_dim] + [width] * layers + [k * (1 + 2 * action_dim)])

    def forward(self, obs: torch.Tensor, goal: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        out = self.head(torch.cat([self.encoder(obs), goal], -1))
        logits = out[..., : self.k]
        mu = out[..., self.k : self.k * (1 + self.dim)].reshape(*out.shape[:-1], self.k, self.dim)
        log_std = out[..., self.k * (1 + self.dim) :].reshape(*out.shape[:-1], self.k, self.dim).clamp(-5.0, 1.0)
        return logits, mu, log_std

    def nll(self, obs: torch.Tensor, goal: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
        """Mean negative log-likelihood of the expert's actions ``a`` under the mixture."""
        logits, mu, log_std = self(obs, goal)
        z = (a[..., None, :] - mu) / log_std.exp()
        comp = (-0.5 * z**2 - log_std - 0.5 * np.log(2 * np.pi)).sum(-1)  # (B, K)
        return -torch.logsumexp(torch.log_softmax(logits, -1) + comp, -1).mean()

    def act(self, obs: torch.Tensor, goal: torch.Tensor, gen: torch.Generator | None = None) -> torch.Tensor:
        """The mean of the most probable component, or (with ``gen``) of a drawn one."""
        logits, mu, _ = self(obs, goal)
        if gen is None:
            pick = logits.argmax(-1)
        else:
            pick = torch.multinomial(torch.softmax(logits, -1), 1, generator=gen)[:, 0]
        return mu[torch.arange(len(mu)), pick].clamp(-1.0, 1.0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("demos", help="a demonstrations file written by `pointplan bc --demos`")
    ap.add_argument("--env", default="boxes3d")
    ap.add_argument("--robot", default="sshape")
    ap.add_argument("--observation", default="local")
    ap.add_argument("--components", type=int, nargs="+", default=[1, 5])
    ap.add_argument("--epochs", type=int, default=40)
    ap.add_argument("--eval-every", type=int, default=10)
    ap.add_argument("--width", type=int, default=64)
    ap.add_argument("--episodes", type=int, default=200)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", help="write the curves here")
    args = ap.parse_args()
    torch.set_num_threads(1)
    from pointplan.envs.core import EnvConfig
    from pointplan.learning.bc import load_demos, observe_demos
    from pointplan.models.inputs import goal_input, obs_input
    from pointplan.planners.policy import rollout_batch
    from pointplan.scenes.scenarios import make_scenario

    scenario = make_scenario(args.env, robot=args.robot)
    robot = scenario.robot
    demos = load_demos(args.demos, scenario)
    env = EnvConfig(observation=args.observation, n_points=64, split="train")
    val = scenario.problems("val", args.episodes, seed=args.seed)
    act_t = torch.as_tensor(demos.action, dtype=torch.float32)
    g_all = torch.as_tensor(goal_input(robot, demos.q, demos.goal))
    results = {}
    for k in args.components:
        rng = np.random.default_rng(args.seed)
        torch.manual_seed(args.seed)
        obs = torch.as_tensor(obs_input(robot, observe_demos(demos, robot, env, rng)))
        net = MixtureActor(tuple(obs.shape[1:]), g_all.shape[1], act_t.shape[1], k, args.width, 3)
        opt = torch.optim.Adam(net.parameters(), lr=1e-3)
        curve = []
        t0 = time.perf_counter()
        for ep in range(1, args.epochs + 1):
            if ep % 5 == 0:
                obs = torch.as_tensor(obs_input(robot, observe_demos(demos, robot, env, rng)))
            perm = torch.as_tensor(rng.permutation(len(demos)))
            total = 0.0
            net.train()
            for s in range(0, len(perm), 256):
                b = perm[s : s + 256]
                loss = net.nll(obs[b], g_all[b], act_t[b])
                opt.zero_grad(set_to_none=True)
                loss.backward()
                opt.step()
                total += float(loss.detach()) * len(b)
            row: dict[str, float] = {"epoch": ep, "nll": total / len(perm), "wall_time_s": time.perf_counter() - t0}
            if ep % args.eval_every == 0 or ep == args.epochs:
                net.eval()
                for how in ("mode", "sample"):
                    gen = torch.Generator().manual_seed(args.seed) if how == "sample" else None

                    def act(o: np.ndarray, q: np.ndarray, g: np.ndarray, gen: torch.Generator | None = gen) -> np.ndarray:
                        with torch.no_grad():
                            return net.act(torch.as_tensor(obs_input(robot, o)), torch.as_tensor(goal_input(robot, q, g)), gen).numpy()

                    res = rollout_batch(act, robot, EnvConfig(observation=args.observation, n_points=64, split="val"), val, scenario.horizon, seed=args.seed)
                    row[how] = float(np.mean([r.success for r in res]))
            curve.append(row)
            msg = f"K={k} epoch {ep}: nll {row['nll']:.3f}"
            if "mode" in row:
                msg += f", validation {100 * row['mode']:.1f}% (mode) {100 * row['sample']:.1f}% (sampled component)"
            print(msg, flush=True)
        results[str(k)] = curve
        if args.json:
            with open(args.json, "w") as f:
                json.dump({"demos": args.demos, "episodes": args.episodes, "curves": results}, f, indent=1)


if __name__ == "__main__":
    main()
