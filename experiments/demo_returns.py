"""Is reaching the goal worth it? Discounted returns of Bi-RRT's demonstrations under the
environment's reward, against the return of standing still for a whole episode.

The reward is ``-action_cost |a| - 0.1`` per free step and ``+20`` on arrival (docs/reference/design.md,
`EnvConfig`). Each demonstration is replayed as the actions that take one configuration to
the next (``log(q_t^-1 q_t+1)`` over the robot's action scale, as ``pointplan bc`` clones
them); its return is compared with ``sum_t -0.1 gamma^t`` over the horizon, what a policy
that never moves (and never collides) earns. Where a demonstration earns less, the reward
itself tells the learner not to go.

    python experiments/demo_returns.py runs/demos_boxes3d_sshape_3k.npz --costs 1 0.5 0.25
"""

from __future__ import annotations

import argparse

import numpy as np

from pointplan.envs.core import EnvConfig, step_reward
from pointplan.robots import make_robot
from pointplan.scenes.scenarios import make_scenario


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("demos", help="a demonstrations file written by `pointplan bc --demos`")
    ap.add_argument("--costs", type=float, nargs="+", default=[1.0, 0.5, 0.25], help="action cost weights to compare")
    ap.add_argument("--gamma", type=float, default=0.99)
    args = ap.parse_args()

    data = np.load(args.demos, allow_pickle=False)
    robot = make_robot(str(data["robot"]))
    horizon = make_scenario(str(data["env"]), robot=str(data["robot"])).horizon
    configs, lengths = data["configs"], data["lengths"]
    starts = np.concatenate([[0], np.cumsum(lengths)[:-1]])
    norms = []
    for s, n in zip(starts, lengths, strict=True):
        q = configs[s : s + n]
        norms.append(np.linalg.norm(robot.log(q[:-1], q[1:]) / robot.action_scale, axis=-1))
    steps = np.array([len(a) for a in norms])
    print(f"{len(norms)} demonstrations ({data['env']}, {robot.name}): {steps.mean():.1f} steps on average, |a| {np.concatenate(norms).mean():.2f} per step")
    for cost in args.costs:
        env = EnvConfig(action_cost=cost)
        still = float(np.sum(step_reward(env, np.zeros(horizon), np.zeros(horizon, bool), np.zeros(horizon, bool)) * args.gamma ** np.arange(horizon)))
        returns = []
        for a in norms:
            arrived = np.zeros(len(a), bool)
            arrived[-1] = True
            returns.append(float(np.sum(step_reward(env, a, np.zeros(len(a), bool), arrived) * args.gamma ** np.arange(len(a)))))
        r = np.array(returns)
        print(
            f"action cost {cost:g}: demonstration return mean {r.mean():.2f} (median {np.median(r):.2f}); standing still {still:.2f}; "
            f"{(r < still).mean():.1%} of the demonstrations earn less than standing still"
        )


if __name__ == "__main__":
    main()
