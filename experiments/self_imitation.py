"""Self-imitation (filtered behavioural cloning) from a cloned actor (exploratory).

The spread-cloned S-shape actor solves 35% of the validation problems with its mean action
and 58% with sampled actions: its mean stalls in contact with an obstacle, pushing into it
every step, while a draw from its spread gets it off. Each round here rolls the *sampled*
policy out on fresh training problems, keeps the steps of the successful rollouts that
did not collide (a collided step moved the robot less than its action, or not at all, so
its displacement is not the action taken), adds them to the demonstrations and fits the
actor a few more passes on all of them. Conditioning on success re-weights the policy's
own actions by how often they lead to the goal (reward-weighted regression with a 0/1
reward), so the mean moves towards the actions that got the samples out of the stalls.

    python experiments/self_imitation.py checkpoints/sshape_local_bc_spread.pt \\
        --demos runs/demos_boxes3d_sshape_3k.npz --rounds 8 --rollouts 1000 --out runs/selfim_sshape

Writes ``OUT/round_K.pt`` (a policy checkpoint) and ``OUT/metrics.csv``; validation is on
the ``val`` split (mean action and sampled actions), never on test problems.
"""

from __future__ import annotations

import argparse
import csv
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

#: training problems of the rollouts start here (the demonstrations use 1,000,000 + i and
#: the RL trainer draws from 0 up)
ROLLOUT_INDEX0 = 3_000_000


def sampled_rollouts(policy, scenario, indices, seed, rng, scale=1.0, chunk=200):  # type: ignore[no-untyped-def]
    """Roll the sampled policy out on training problems ``indices``; returns, per problem,
    (success, path (T+1, d), collided (T,))."""
    from pointplan.envs.core import EnvConfig
    from pointplan.planners.policy import BatchedCore, _GivenProblems

    robot = scenario.robot
    env = replace(EnvConfig(observation=policy.observation, n_points=policy.n_points, split="train"), horizon=scenario.horizon)
    out = []
    for c0 in range(0, len(indices), chunk):
        probs = [scenario.problem("train", int(i), seed=seed) for i in indices[c0 : c0 + chunk]]
        n = len(probs)
        core = BatchedCore(_GivenProblems(robot, scenario.horizon), n, env)
        core.reset_envs(range(n), rng, probs)
        paths = [core.q.copy()]
        coll = []
        active = np.ones(n, bool)
        succ = np.zeros(n, bool)
        length = np.zeros(n, np.int64)
        for _ in range(scenario.horizon):
            obs = core.observe(rng)["observation"]
            a = policy(obs, core.q.copy(), core.goal.copy(), noise=scale * rng.standard_normal((n, robot.twist_dim)))
            a[~active] = 0.0
            _, term, _, info = core.step(a)
            paths.append(core.q.copy())
            coll.append(info["collided"].copy())
            length += active
            succ |= term & active
            active &= ~term
            if not active.any():
                break
        P = np.stack(paths)
        C = np.stack(coll)
        for i in range(n):
            k = int(length[i])
            out.append((bool(succ[i]), P[: k + 1, i], C[:k, i]))
    return out


def free_segments(path: np.ndarray, collided: np.ndarray) -> list[np.ndarray]:
    """The runs of consecutive non-collided steps of a path, each as a path of >= 2 configs."""
    segs, s = [], 0
    for t, c in enumerate(list(collided) + [True]):
        if c:
            if t > s:
                segs.append(path[s : t + 1])
            s = t + 1
    return segs


def evaluate(policy, scenario, episodes, seed):  # type: ignore[no-untyped-def]
    from pointplan.envs.core import EnvConfig
    from pointplan.planners.policy import rollout_batch

    env = EnvConfig(observation=policy.observation, n_points=policy.n_points, split="val")
    problems = scenario.problems("val", episodes, seed=seed)
    mean = rollout_batch(lambda o, q, g: policy(o, q, g), policy.robot, env, problems, scenario.horizon, seed=seed)
    rng = np.random.default_rng(seed)
    sampled = rollout_batch(
        lambda o, q, g: policy(o, q, g, noise=rng.standard_normal((len(q), policy.robot.twist_dim))), policy.robot, env, problems, scenario.horizon, seed=seed
    )
    return float(np.mean([r.success for r in mean])), float(np.mean([r.success for r in sampled]))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("checkpoint", help="a policy checkpoint to start from (a cloned actor)")
    ap.add_argument("--demos", required=True, help="the Bi-RRT demonstrations it was cloned on (kept in every fit)")
    ap.add_argument("--rounds", type=int, default=8)
    ap.add_argument("--rollouts", type=int, default=1000, help="fresh training problems per round")
    ap.add_argument("--epochs-per-round", type=float, default=2.0)
    ap.add_argument("--lr", type=float, default=3e-4)
    ap.add_argument("--spread-weight", type=float, default=1.0)
    ap.add_argument("--noise-scale", type=float, default=1.0, help="scale of the sampled actions' noise in the rollouts")
    ap.add_argument(
        "--only-mean-failures",
        action="store_true",
        help="keep a solved rollout only where the mean action fails the same problem (the samples then carry what the mean lacks)",
    )
    ap.add_argument("--self-weight", type=int, default=1, help="repeat every kept rollout step this many times in the fit")
    ap.add_argument("--drop-demos", action="store_true", help="fit on the policy's own solved rollouts only, not on the Bi-RRT demonstrations")
    ap.add_argument("--eval-episodes", type=int, default=200)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", required=True)
    args = ap.parse_args()
    torch.set_num_threads(1)
    from pointplan.envs.core import EnvConfig
    from pointplan.learning.bc import demos_from_paths, fit_actor, load_demos
    from pointplan.models.checkpoint import load_checkpoint, save_checkpoint
    from pointplan.models.policy import Policy
    from pointplan.scenes.scenarios import make_scenario

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    payload = {k: v for k, v in load_checkpoint(args.checkpoint).items() if k not in ("format", "version")}
    policy = Policy.from_checkpoint(args.checkpoint)
    scenario = make_scenario(policy.env, robot=policy.robot.name)
    robot = scenario.robot
    demos = load_demos(args.demos, scenario)
    with np.load(args.demos) as f:
        demo_seed = int(f["seed"])
    paths = list(demos.paths)
    own: list[tuple[int, np.ndarray]] = []
    env = EnvConfig(observation=policy.observation, n_points=policy.n_points)
    rng = np.random.default_rng(args.seed)
    torch.manual_seed(args.seed)
    actor = policy.actor
    opt = torch.optim.Adam(actor.parameters(), lr=args.lr)
    metrics = out / "metrics.csv"
    t0 = time.perf_counter()
    with metrics.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["round", "rollouts_solved", "self_steps_added", "demo_steps", "loss", "val_mean", "val_sampled", "wall_time_s"])
        vm, vs = evaluate(policy, scenario, args.eval_episodes, args.seed)
        w.writerow([0, "", 0, len(demos), "", vm, vs, round(time.perf_counter() - t0, 1)])
        fh.flush()
        print(f"round 0: val mean {100 * vm:.1f}%, sampled {100 * vs:.1f}%", flush=True)
        for r in range(1, args.rounds + 1):
            actor.eval()
            idx = np.arange(args.rollouts) + ROLLOUT_INDEX0 + (r - 1) * args.rollouts
            res = sampled_rollouts(policy, scenario, idx, demo_seed, rng, args.noise_scale)
            keep = np.array([x[0] for x in res])
            if args.only_mean_failures:
                det = sampled_rollouts(policy, scenario, idx, demo_seed, rng, 0.0)
                keep &= ~np.array([x[0] for x in det])
            added = 0
            for i, k, (ok, path, coll) in zip(idx, keep, res):
                if k:
                    for seg in free_segments(path, coll):
                        own.extend([(int(i), seg)] * args.self_weight)
                        added += len(seg) - 1
            demos = demos_from_paths(scenario, "train", demo_seed, (own if args.drop_demos else paths + own))
            actor.train()
            losses = fit_actor(actor, opt, demos, robot, env, args.epochs_per_round, 256, rng, 1, False, args.spread_weight)
            actor.eval()
            vm, vs = evaluate(policy, scenario, args.eval_episodes, args.seed)
            solved = float(np.mean([x[0] for x in res]))
            w.writerow([r, solved, added, len(demos), losses[-1], vm, vs, round(time.perf_counter() - t0, 1)])
            fh.flush()
            save_checkpoint(out / f"round_{r}.pt", {**payload, "actor": actor.state_dict(), "self_imitation_round": r})
            print(
                f"round {r}: rollouts solved {100 * solved:.1f}%, +{added} steps ({len(demos)} in all), loss {losses[-1]:.3f}, val mean {100 * vm:.1f}%, sampled {100 * vs:.1f}%",
                flush=True,
            )


if __name__ == "__main__":
    main()
