"""How often a policy's mean action arrives when started k steps before the goal of a
demonstration path (the starts of ``pointplan ppo --start-demos``).

    python experiments/demo_start_success.py CKPT --demos runs/demos_slot_canonical.npz --env slot --back 1 4 8 16 32 40
    python experiments/demo_start_success.py CKPT --demos ... --greedy-goal   # with the planner's goal test

Without ``--greedy-goal`` a rollout succeeds as in training: within the environment's
goal tolerance. The demonstrations are the last ``--paths`` of the file.
"""

from __future__ import annotations

import argparse
import json

import numpy as np
import torch


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("checkpoint")
    ap.add_argument("--demos", required=True)
    ap.add_argument("--env", default="slotmoving")
    ap.add_argument("--back", nargs="+", type=int, default=[1, 4, 8, 16, 32])
    ap.add_argument("--paths", type=int, default=150)
    ap.add_argument("--greedy-goal", action="store_true")
    ap.add_argument("--json")
    args = ap.parse_args()
    torch.set_num_threads(1)
    from pointplan.config import from_dict
    from pointplan.envs.core import EnvConfig
    from pointplan.learning.bc import load_demos
    from pointplan.models.actor_critic import Actor, NetConfig
    from pointplan.models.checkpoint import load_checkpoint
    from pointplan.models.inputs import goal_input, obs_input
    from pointplan.planners.policy import rollout_batch
    from pointplan.scenes.scenarios import make_scenario
    from pointplan.scenes.scene import Problem

    ck = load_checkpoint(args.checkpoint)
    sc = make_scenario(args.env, robot=ck["robot"])
    robot = sc.robot
    actor = Actor(tuple(ck["obs_shape"]), robot.twist_dim, robot.twist_dim, from_dict(NetConfig, ck["net"]))
    actor.load_state_dict(ck["actor"])
    actor.eval()
    demos = load_demos(args.demos, sc)
    by_index: dict[int, Problem] = {}
    for k, _ in demos.paths:
        by_index.setdefault(k, demos.problems[len(by_index)])
    paths = [(by_index[k], p) for k, p in demos.paths][-args.paths :]
    env = EnvConfig(observation=ck["observation"], n_points=ck["n_points"], split="train")

    def act(o: np.ndarray, q: np.ndarray, g: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            m, _ = actor(torch.as_tensor(obs_input(robot, o), dtype=torch.float32), torch.as_tensor(goal_input(robot, q, g), dtype=torch.float32))
            return torch.tanh(m).numpy()

    out = {}
    for k in args.back:
        probs = [Problem(pr.scene, p[max(0, len(p) - 1 - k)].copy(), pr.goal, pr.tag) for pr, p in paths]
        res = rollout_batch(act, robot, env, probs, sc.horizon, seed=0, greedy_goal=args.greedy_goal)
        out[k] = float(np.mean([r.success for r in res]))
        print(f"{k} steps before the goal: {out[k]:.3f} of {len(probs)}", flush=True)
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"checkpoint": args.checkpoint, "demos": args.demos, "greedy_goal": args.greedy_goal, "paths": len(paths), "success": out}, f, indent=1)


if __name__ == "__main__":
    main()
