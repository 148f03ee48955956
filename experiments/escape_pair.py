"""A second policy's draws in the escape: Slot's thin openings (under 3 bar thicknesses) of
the first 500 validation problems, the oriented S-shape's shipped `local` policy stepping
with its mean action; where it is stuck, the screened escape's draws come half from it and
half from another policy (``--other``: a PPO state or policy file of the same robot and
observation), judged by the same lookahead (the shipped policy's mean action). Policies
trained on other demonstrations fail on other thin openings; if their failures differ,
the pair's draws may thread what neither does alone. ``--share`` is the other policy's
share of the draws (0: the planner as it is).

    python experiments/escape_pair.py --other runs/slotthin/ppo_thin202/chunk_2252800.pt --share 0 0.5
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--other", required=True)
    ap.add_argument("--share", type=float, nargs="+", default=[0.0, 0.5])
    ap.add_argument("--episodes", type=int, default=500)
    ap.add_argument("--max-bars", type=float, default=3.0)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    import torch

    torch.set_num_threads(1)
    from pointplan.evaluation.evaluate import evaluate
    from pointplan.models.policy import Policy
    from pointplan.planners import rollout as R
    from pointplan.planners.policy import PolicyPlanner
    from pointplan.robots.sshape import BAR_THICKNESS
    from pointplan.scenes.scenarios import make_scenario

    policy = Policy.from_checkpoint("src/pointplan/data/slot_sshape_oriented_local_policy.pt")
    other = Policy.from_checkpoint(args.other)
    sc = make_scenario("slot", robot=policy.robot.name)
    robot = sc.robot
    problems = sc.problems("val", args.episodes, seed=args.seed)
    chosen = [p for p in problems if p.scene.__dict__["slot"]["width"] / BAR_THICKNESS < args.max_bars]
    share = 0.0
    stats = {"escapes": 0, "other": 0}

    def furthest(self, obs, q, target):  # type: ignore[no-untyped-def]
        eng = self.engine
        k_other = int(round(share * eng.escape.tries))
        best, far, from_other = None, -np.inf, False
        for k in range(eng.escape.tries):
            noise = self._noise(True)
            if k < k_other:
                a = other(obs[None], q[None], target[None], noise[None])[0]
            else:
                a = eng._act(obs, q, target, noise)
            d = self._score(a, q, target)
            if d > far:
                best, far, from_other = a, d, k < k_other
        stats["escapes"] += 1
        stats["other"] += from_other
        return best

    R._OneRobot._furthest = furthest  # type: ignore[method-assign]
    for s in args.share:
        share = s
        stats.update(escapes=0, other=0)
        planner = PolicyPlanner(policy, robot=robot, compiled=False)
        t0 = time.perf_counter()
        report = evaluate(planner, chosen, robot, progress=False)
        ok = [bool(r.success) for r in report.records]
        steps = np.mean([len(r.path) - 1 for r in report.records])
        print(
            f"share {s}: {sum(ok)}/{len(chosen)} solved (openings < {args.max_bars} bars, val seed {args.seed}), "
            f"{steps:.1f} steps, escape steps {stats['escapes']} taken from the other {stats['other']}, "
            f"{time.perf_counter() - t0:.0f} s; failed: {[i for i, v in enumerate(ok) if not v]}",
            flush=True,
        )


if __name__ == "__main__":
    main()
