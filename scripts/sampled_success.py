"""Success of a policy checkpoint's deterministic (mean) and sampled actions.

The critics of SAC learn the value of the *sampled* policy; a cloned actor whose spread was
never fitted can solve many problems with its mean action and few with its samples. This
measures both on the validation problems (seeded):

    python scripts/sampled_success.py runs/bc_sshape_spread/bc.pt --episodes 200
"""

from __future__ import annotations

import argparse

import numpy as np
import torch


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("checkpoint")
    ap.add_argument("--episodes", type=int, default=200)
    ap.add_argument("--split", default="val", choices=["train", "val"])
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    torch.set_num_threads(1)
    from pointplan.envs.core import EnvConfig
    from pointplan.models.inputs import goal_input, obs_input
    from pointplan.models.policy import Policy
    from pointplan.planners.policy import rollout_batch
    from pointplan.scenes.scenarios import make_scenario

    policy = Policy.from_checkpoint(args.checkpoint)
    scenario = make_scenario(policy.env, robot=policy.robot.name)
    robot = scenario.robot
    env = EnvConfig(observation=policy.observation, n_points=policy.n_points, split=args.split)
    problems = scenario.problems(args.split, args.episodes, seed=args.seed)
    actor = policy.actor
    for mode in ("mean", "sampled"):
        torch.manual_seed(args.seed)

        def act(o: np.ndarray, q: np.ndarray, g: np.ndarray, mode: str = mode) -> np.ndarray:
            with torch.no_grad():
                obs = torch.as_tensor(obs_input(robot, o), dtype=torch.float32)
                goal = torch.as_tensor(goal_input(robot, q, g), dtype=torch.float32)
                a = actor.act(obs, goal) if mode == "mean" else actor.sample(obs, goal)[0]
                return a.numpy()

        res = rollout_batch(act, robot, env, problems, scenario.horizon, seed=args.seed)
        ok = np.array([r.success for r in res])
        print(f"{mode:8s} {100 * ok.mean():5.1f}% of {len(ok)} {args.split} problems")


if __name__ == "__main__":
    main()
