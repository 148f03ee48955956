"""Escape a stall inside one rollout: the mean action until the robot stops moving, then
actions sampled from the policy's spread for a few steps, then the mean action again.

The cloned S-shape policies fail mostly by pinning themselves against an obstacle
(``scripts/stall_contact.py``); sampled retries from the start (``--attempts``) fix many of
those failures but start over, which a scene with moving obstacles does not allow. This
measures, on validation problems, whether noise switched on only where the robot is stuck
does as well inside a single rollout:

    python scripts/stall_escape.py --robot sshape --observation global --escape 0 3 10
    python scripts/stall_escape.py --robot sshape --observation local --env dynamic3d

``--escape 0`` is the plain mean-action rollout (with the greedy goal test in static
scenes, as the planner does). Every path is re-checked by the evaluator. ``--why`` then
plans the same problems with the planner itself (``PolicyPlanner``, its default escape
for the robot unless ``--escape`` names one value) and says how its failures end: how
they stop, how many escapes they went through, how far from the goal they are left:

    python scripts/stall_escape.py --robot sshape --observation global --escape 10 --noise 2 --why
"""

from __future__ import annotations

import argparse
import json
import time
from typing import Any

import numpy as np
import torch


class StallEscapePlanner:
    """One rollout through :func:`~pointplan.planners.policy.rollout_batch`: where a step
    moved the robot less than ``still`` (geodesic distance), the next ``escape`` actions
    are ``tanh(mean + noise * std * N(0, 1))``."""

    name = "policy-escape"

    def __init__(
        self, policy: Any, robot: Any, escape: int, still: float, noise: float, seed: int = 0, grow_noise: float = 0.0, grow_steps: float = 0.0
    ) -> None:
        from pointplan.envs.core import EnvConfig

        self.policy, self.robot = policy, robot
        self.escape, self.still, self.noise, self.seed = int(escape), float(still), float(noise), int(seed)
        self.env = EnvConfig(observation=policy.observation, n_points=policy.n_points)
        self.horizon = int(policy.meta.get("horizon") or 50)
        self.escapes = 0  # how many escape phases were started, over all problems
        # the k-th escape of a problem: noise * (1 + grow_noise * (k - 1)) for escape * (1 + grow_steps * (k - 1)) steps
        self.grow_noise, self.grow_steps = float(grow_noise), float(grow_steps)

    def plan(self, problem: Any) -> Any:
        from pointplan.planners.policy import rollout_batch

        rng = np.random.default_rng(np.random.SeedSequence([self.seed, int(1e6 * float(problem.start[0])) % (2**31)]))
        dim = self.policy.actor.action_dim
        state: dict[str, Any] = {"prev": None, "left": 0, "k": 0}

        def act(obs: np.ndarray, q: np.ndarray, goal: np.ndarray) -> np.ndarray:
            if state["prev"] is not None and self.escape > 0:
                moved = float(self.robot.distance(q[0], state["prev"]))
                if moved < self.still and state["left"] == 0:
                    state["k"] += 1
                    state["left"] = int(round(self.escape * (1 + self.grow_steps * (state["k"] - 1))))
                    self.escapes += 1
            state["prev"] = q[0].copy()
            noise = None
            if state["left"] > 0:
                state["left"] -= 1
                noise = self.noise * (1 + self.grow_noise * (state["k"] - 1)) * rng.standard_normal((len(q), dim))
            return self.policy(obs, q, goal, noise=noise)

        greedy = not problem.scene.dynamic
        return rollout_batch(act, self.robot, self.env, [problem], self.horizon, self.seed, connect_goal=True, greedy_goal=greedy)[0]


def why(policy: Any, scenario: Any, problems: list, args: argparse.Namespace) -> None:
    """How the planner's failures end (``info["end"]``, escapes, distance left)."""
    from collections import Counter

    from pointplan.evaluation.evaluate import check_path
    from pointplan.planners.policy import Escape, PolicyPlanner

    escape = Escape(steps=args.escape[0], noise=args.noise, still=args.still) if len(args.escape) == 1 else None
    planner = PolicyPlanner(policy, robot=scenario.robot, escape=escape)
    ends: Counter[str] = Counter()
    escapes, left, sent = [], [], []
    for p in problems:
        r = planner.plan(p)
        if bool(check_path(scenario.robot, p, r.path)):
            continue
        ends[str(r.info.get("end"))] += 1
        escapes.append(int(r.info.get("escapes", 0)))
        left.append(float(scenario.robot.distance(r.path[-1], p.goal)))
        sent.append(float(scenario.robot.distance(p.start, p.goal)))
    print(f"planner {planner.escape}: {len(escapes)} failures of {len(problems)}; ends {dict(ends)}")
    if escapes:
        print(
            f"escapes per failure: median {np.median(escapes):.0f} (10-90%: {np.percentile(escapes, 10):.0f}-{np.percentile(escapes, 90):.0f}); "
            f"left from the goal: median {np.median(left):.2f} of {np.median(sent):.2f} at the start"
        )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("checkpoint", nargs="?", help="policy checkpoint (default: the shipped one)")
    ap.add_argument("--robot", default="sshape")
    ap.add_argument("--observation", default=None)
    ap.add_argument("--env", default=None, help="scene id (default: the one the policy was trained in)")
    ap.add_argument("--episodes", type=int, default=200)
    ap.add_argument("--split", default="val", choices=["train", "val"])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--escape", type=int, nargs="+", default=[0, 3, 10], help="sampled steps after a stall (0: none)")
    ap.add_argument("--still", type=float, default=0.01, help="a step that moves less than this is a stall")
    ap.add_argument("--noise", type=float, default=1.0, help="scale of the policy's spread while escaping")
    ap.add_argument("--json", help="write the rows here")
    ap.add_argument("--why", action="store_true", help="then: how the planner's failures end")
    ap.add_argument("--grow-noise", type=float, default=0.0, help="the k-th escape of a problem samples with noise * (1 + this * (k - 1))")
    ap.add_argument("--grow-steps", type=float, default=0.0, help="the k-th escape of a problem lasts escape * (1 + this * (k - 1)) steps")
    args = ap.parse_args()
    torch.set_num_threads(1)
    from pointplan.evaluation.evaluate import evaluate
    from pointplan.models.policy import Policy, shipped_checkpoint
    from pointplan.scenes.scenarios import make_scenario

    ckpt = args.checkpoint or str(shipped_checkpoint(args.robot, args.observation))
    policy = Policy.from_checkpoint(ckpt)
    scenario = make_scenario(args.env or policy.env, robot=policy.robot.name)
    problems = scenario.problems(args.split, args.episodes, seed=args.seed)
    rows = []
    for m in args.escape:
        planner = StallEscapePlanner(policy, scenario.robot, m, args.still, args.noise, args.seed, args.grow_noise, args.grow_steps)
        t0 = time.perf_counter()
        rep = evaluate(planner, problems, scenario.robot, progress=False)
        met = rep.metrics()
        row = {
            "escape": m,
            "success": met["success_rate"],
            "mean_steps": met["nodes_mean"],
            "escapes_per_problem": planner.escapes / len(problems),
            "claims_disagree": met["planner_claims_disagree"],
            "wall_s": time.perf_counter() - t0,
        }
        rows.append(row)
        print(
            f"escape {m:2d}: {100 * row['success']:5.1f}% of {met['episodes']} {args.split} problems in {scenario.name}, "
            f"{row['mean_steps']:.1f} steps, {row['escapes_per_problem']:.2f} escapes per problem, "
            f"{row['claims_disagree']} claims disagree, {row['wall_s']:.0f} s",
            flush=True,
        )
    if args.why:
        why(policy, scenario, problems, args)
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"checkpoint": ckpt, "split": args.split, "episodes": args.episodes, "still": args.still, "noise": args.noise, "rows": rows}, f, indent=1)


if __name__ == "__main__":
    main()
