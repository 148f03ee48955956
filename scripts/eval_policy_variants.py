"""Policies on fixed problems under chosen variants: checkpoints, their weight average,
the rule at the workspace bounds, observation seeds.

    python scripts/eval_policy_variants.py                       # the shipped policy
    python scripts/eval_policy_variants.py --bounds clip stop    # both bounds rules
    python scripts/eval_policy_variants.py --checkpoints a.pt b.pt c.pt --average
    python scripts/eval_policy_variants.py --splits val --val-episodes 2000 --problem-seeds 0 1 2 3

Prints one row per (policy, bounds rule, split, problem seed, observation seed): success
(paths re-checked by the evaluator), mean nodes, failing problem indices; with several rows
per policy, a last row sums each policy's failures over them. ``--average`` adds the uniform
average of the checkpoints' actor weights (they must share one network layout).
"""

from __future__ import annotations

import argparse
import copy
import sys
from pathlib import Path

import numpy as np
import torch

from pointplan.envs.core import EnvConfig
from pointplan.evaluation.evaluate import check_path
from pointplan.models.checkpoint import load_checkpoint
from pointplan.models.policy import Policy, shipped_checkpoint
from pointplan.planners.policy import rollout_batch
from pointplan.scenes.scenarios import make_scenario


def average_policy(paths: list[str]) -> Policy:
    """A policy whose actor weights are the mean of the checkpoints' actors."""
    base = Policy.from_checkpoint(paths[0])
    states = [load_checkpoint(p, "cpu")["actor"] for p in paths]
    if any(set(s) != set(states[0]) or any(s[k].shape != states[0][k].shape for k in s) for s in states):
        sys.exit("--average needs checkpoints of one network layout")
    mean = {
        k: (sum(s[k].double() for s in states) / len(states)).to(states[0][k].dtype)
        if states[0][k].is_floating_point()
        else states[0][k]
        for k in states[0]
    }
    avg = copy.deepcopy(base)
    avg.actor.load_state_dict(mean)
    return avg


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--checkpoints", nargs="+", help="policy checkpoints (default: the shipped 2D-Narrow policy)")
    ap.add_argument("--average", action="store_true", help="also the uniform average of the checkpoints' weights")
    ap.add_argument("--bounds", nargs="+", default=["clip"], choices=["clip", "stop"])
    ap.add_argument("--splits", nargs="+", default=["val", "test"])
    ap.add_argument("--val-episodes", type=int, default=1000)
    ap.add_argument("--test-episodes", type=int, default=400)
    ap.add_argument("--obs-seeds", type=int, nargs="+", default=[0], help="seeds of the observed point subsets")
    ap.add_argument(
        "--problem-seeds",
        type=int,
        nargs="+",
        default=[0],
        help="seeds of the start/goal draws (0: the problem sets of pointplan eval)",
    )
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)

    paths = args.checkpoints or [str(shipped_checkpoint())]
    names = [Path(p).name for p in paths]
    if len(set(names)) < len(names):  # e.g. runs/a/best.pt and runs/b/best.pt
        names = [str(Path(p).parent.name + "/" + Path(p).name) for p in paths]
    policies = {n: Policy.from_checkpoint(p) for n, p in zip(names, paths)}
    if args.average:
        policies[f"average of {len(paths)}"] = average_policy(paths)
    first = next(iter(policies.values()))
    scenario = make_scenario(first.env)
    episodes = {"val": args.val_episodes, "test": args.test_episodes, "train": args.val_episodes}
    problems = {(s, ps): scenario.problems(s, episodes[s], seed=ps) for s in args.splits for ps in args.problem_seeds}
    horizon = int(first.meta.get("horizon") or scenario.horizon)

    print(f"{'policy':<28} {'bounds':<6} {'split':<5} {'prob':>4} {'obs':>4} {'success':>8} {'nodes':>6}  failing")
    for name, pol in policies.items():
        failed = total = rows = 0
        for rule in args.bounds:
            env = EnvConfig(observation=pol.observation, n_points=pol.n_points, bounds=rule)
            for (split, pseed), probs in problems.items():
                for seed in args.obs_seeds:
                    res = rollout_batch(pol, pol.robot, env, probs, horizon, seed=seed)
                    ok = np.array([r.success and check_path(pol.robot, p, r.path) for r, p in zip(res, probs)])
                    nodes = float(np.mean([r.nodes for r in res]))
                    fails = np.flatnonzero(~ok).tolist()
                    failed, total, rows = failed + len(fails), total + len(ok), rows + 1
                    shown = " ".join(map(str, fails[:12])) + (" ..." if len(fails) > 12 else "")
                    print(
                        f"{name:<28} {rule:<6} {split:<5} {pseed:>4} {seed:>4} {ok.mean():>8.2%} {nodes:>6.2f}  {shown}",
                        flush=True,
                    )
        if rows > 1:
            print(
                f"{name:<28} {'all':<6} {'all':<5} {'':>4} {'':>4} {1 - failed / total:>8.2%} {'':>6}  {failed} failures of {total}",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
