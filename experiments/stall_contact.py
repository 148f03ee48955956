"""Where a policy's failed rollouts end: pinned against an obstacle, or free.

Rolls a policy checkpoint out with its mean action on validation problems and, for the
failures, counts how many of the last 20 steps collided (the environment then moves the
robot to the last free configuration along the action, here none: it stays in place),
how far the robot moved in them, and the first step that collided:

    python experiments/stall_contact.py checkpoints/sshape_local_bc_spread.pt --episodes 200
"""

from __future__ import annotations

import argparse
from dataclasses import replace

import numpy as np
import torch


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("checkpoint")
    ap.add_argument("--episodes", type=int, default=200)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--last", type=int, default=20, help="the failures' last this many steps are inspected")
    args = ap.parse_args()
    torch.set_num_threads(1)
    from pointplan.envs.core import EnvConfig
    from pointplan.models.policy import Policy
    from pointplan.planners.policy import BatchedCore, _GivenProblems
    from pointplan.scenes.scenarios import make_scenario

    policy = Policy.from_checkpoint(args.checkpoint)
    scenario = make_scenario(policy.env, robot=policy.robot.name)
    robot = scenario.robot
    env = replace(EnvConfig(observation=policy.observation, n_points=policy.n_points, split="val"), horizon=scenario.horizon)
    problems = scenario.problems("val", args.episodes, seed=args.seed)
    n = len(problems)
    rng = np.random.default_rng(args.seed)
    core = BatchedCore(_GivenProblems(robot, scenario.horizon), n, env)
    core.reset_envs(range(n), rng, problems)
    active = np.ones(n, bool)
    success = np.zeros(n, bool)
    collided, moved = [], []
    for _ in range(scenario.horizon):
        a = policy(core.observe(rng)["observation"], core.q.copy(), core.goal.copy())
        a[~active] = 0.0
        q0 = core.q.copy()
        _, term, _, info = core.step(a)
        collided.append(info["collided"] & active)
        moved.append(robot.distance(q0, core.q))
        success |= term & active
        active &= ~term
    C, M = np.array(collided), np.array(moved)
    fail = ~success
    k = args.last
    pinned = C[-k:, fail].all(0)
    first = [int(np.argmax(c)) if c.any() else -1 for c in C[:, fail].T]
    print(f"{100 * success.mean():.1f}% of {n} val problems solved (mean action); {int(fail.sum())} failures")
    print(f"failures whose last {k} steps all collided (pinned against an obstacle): {int(pinned.sum())}")
    print(f"failures with no collision in their last {k} steps: {int((~C[-k:, fail].any(0)).sum())}")
    print(f"share of the failures' last {k} steps that collided: {100 * C[-k:, fail].mean():.1f}%")
    print(f"mean distance moved per step in them: {M[-k:, fail].mean():.4f} (one free step: up to {float(np.linalg.norm(robot.action_scale)):.3f})")
    print(
        f"first collision of a failure at step (median over those that collide): {np.median([f for f in first if f >= 0]):.0f}; in the first 2 steps: {sum(0 <= f < 2 for f in first)}"
    )


if __name__ == "__main__":
    main()
