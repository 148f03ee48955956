"""Does the trained critic pick better actions than the actor's mean? (exploratory)

Loads a SAC trainer state (a run's ``last.pt``: actor and critics), and rolls out on the
validation problems (seeded) with, at every step, the actor's mean action, one sampled
action, or the best of ``N`` candidates (the mean and ``N - 1`` samples) by the critics'
``min(Q1, Q2)``:

    python experiments/q_select_success.py runs/sac_sshape_r10/last.pt --episodes 200 --candidates 1 8 32

``--candidates 1`` is the mean action; ``--sampled`` adds the plain sampled policy.
"""

from __future__ import annotations

import argparse

import numpy as np
import torch


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("state", help="a trainer state (last.pt)")
    ap.add_argument("--episodes", type=int, default=200)
    ap.add_argument("--split", default="val", choices=["train", "val"])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--candidates", type=int, nargs="*", default=[1, 8, 32])
    ap.add_argument("--sampled", action="store_true", help="also the plain sampled policy")
    ap.add_argument("--averaged", action="store_true", help="the running average of the actor (when kept)")
    args = ap.parse_args()
    if any(n < 1 for n in args.candidates):
        ap.error("--candidates must be >= 1")
    torch.set_num_threads(1)
    from pointplan.config import from_dict
    from pointplan.envs.core import EnvConfig
    from pointplan.learning.sac import SAC
    from pointplan.learning.train import TrainConfig
    from pointplan.models.checkpoint import load_checkpoint
    from pointplan.models.inputs import goal_input, obs_input
    from pointplan.planners.policy import rollout_batch
    from pointplan.scenes.scenarios import make_scenario

    state = load_checkpoint(args.state)
    if "trainer" not in state:
        ap.error(f"{args.state} holds no trainer state (use a run's last.pt)")
    cfg = from_dict(TrainConfig, state["train_config"])
    scenario = make_scenario(cfg.env, robot=cfg.robot)
    robot = scenario.robot
    env = EnvConfig(observation=cfg.observation, n_points=cfg.n_points, split=args.split, action_cost=cfg.action_cost)
    agent = SAC(robot, env, tuple(state["obs_shape"]), cfg.net, cfg.sac)
    agent.load_state_dict(state["trainer"]["agent"])
    actor = agent.policy_actor if args.averaged else agent.actor
    critic = agent.critic
    problems = scenario.problems(args.split, args.episodes, seed=args.seed)

    def run(n: int, sampled: bool = False) -> None:
        torch.manual_seed(args.seed)

        def act(o: np.ndarray, q: np.ndarray, g: np.ndarray) -> np.ndarray:
            with torch.no_grad():
                obs = torch.as_tensor(obs_input(robot, o), dtype=torch.float32)
                goal = torch.as_tensor(goal_input(robot, q, g), dtype=torch.float32)
                mean, log_std = actor(obs, goal)
                if sampled:
                    return torch.tanh(mean + log_std.exp() * torch.randn_like(mean)).numpy()
                if n == 1:
                    return torch.tanh(mean).numpy()
                b = obs.shape[0]
                noise = torch.randn((n - 1, *mean.shape))
                cand = torch.cat([torch.tanh(mean)[None], torch.tanh(mean + log_std.exp() * noise)])  # (n, B, A)
                obs_n = obs[None].expand(n, *obs.shape).reshape(n * b, *obs.shape[1:])
                goal_n = goal[None].expand(n, *goal.shape).reshape(n * b, -1)
                q1, q2 = critic(obs_n, goal_n, cand.reshape(n * b, -1))
                best = torch.min(q1, q2).reshape(n, b).argmax(0)
                return cand[best, torch.arange(b)].numpy()

        res = rollout_batch(act, robot, env, problems, scenario.horizon, seed=args.seed)
        ok = np.array([r.success for r in res])
        steps = np.mean([len(r.path) - 1 for r in res if r.success]) if ok.any() else float("nan")
        name = "sampled" if sampled else ("mean" if n == 1 else f"best of {n} by Q")
        print(f"{name:16s} {100 * ok.mean():5.1f}% of {len(ok)} {args.split} problems, {steps:.1f} steps when solved", flush=True)

    for n in args.candidates:
        run(n)
    if args.sampled:
        run(1, sampled=True)


if __name__ == "__main__":
    main()
