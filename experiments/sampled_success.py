"""Success of a policy checkpoint's deterministic (mean) and sampled actions.

The critics of SAC learn the value of the *sampled* policy; a cloned actor whose spread was
never fitted can solve many problems with its mean action and few with its samples. This
measures both on the validation problems (seeded):

    python experiments/sampled_success.py runs/bc_sshape_spread/bc.pt --episodes 200
    python experiments/sampled_success.py runs/bc_sshape_spread/bc.pt --scales 0 0.25 0.5 1

``--scales`` samples ``tanh(mean + s * std * noise)`` for each ``s`` (0 is the mean action,
1 the policy's own spread).
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
    ap.add_argument("--scales", type=float, nargs="*", default=[0.0, 1.0], help="noise scales to try (0: the mean action)")
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
    if any(s < 0 for s in args.scales):
        ap.error("--scales must be >= 0")
    for scale in args.scales:
        torch.manual_seed(args.seed)

        def act(o: np.ndarray, q: np.ndarray, g: np.ndarray, scale: float = scale) -> np.ndarray:
            with torch.no_grad():
                obs = torch.as_tensor(obs_input(robot, o), dtype=torch.float32)
                goal = torch.as_tensor(goal_input(robot, q, g), dtype=torch.float32)
                mean, log_std = actor(obs, goal)
                return torch.tanh(mean + scale * log_std.exp() * torch.randn_like(mean)).numpy()

        res = rollout_batch(act, robot, env, problems, scenario.horizon, seed=args.seed)
        ok = np.array([r.success for r in res])
        name = "mean" if scale == 0 else f"noise x{scale:g}"
        # a failure "stalls" when its last 20 steps moved it less than one step (0.07)
        stalled = sum(not r.success and len(r.path) > 20 and float(robot.distance(r.path[-21], r.path[-1])) < 0.07 for r in res)
        print(f"{name:12s} {100 * ok.mean():5.1f}% of {len(ok)} {args.split} problems; {stalled} of {int((~ok).sum())} failures stalled", flush=True)


if __name__ == "__main__":
    main()
