"""Speed-ups of Ray workers: Bi-RRT evaluation and SAC training rollouts, in one run.

    python benchmarks/bench_ray.py                      # 400 2D-Narrow problems, 2 workers
    python benchmarks/bench_ray.py --episodes 40 --train-steps 2000   # a quick look

1. Evaluation: Bi-RRT on the test problems (2D-Narrow by default), serially and on
   ``--workers`` Ray workers; checks that the records (metrics and paths) are identical
   apart from the times, and prints the speed-up of the planning call: cold (the workers'
   first task imports pointplan), warm (a second run), and with Ray's start-up (what a
   fresh ``pointplan eval --workers`` pays once).
2. Training: the same small SAC run (empty2d by default, the settings of
   ``docs/guide/training.md``) serially and with ``--workers`` rollout workers; prints the
   validation success at each evaluation (per environment step) and the environment
   steps per second of each.

Run it on a quiet machine: the load average (``uptime``) is printed before and after, and
the numbers mean little when other jobs share the cores.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time

import numpy as np


def load() -> str:
    one, five, fifteen = os.getloadavg()
    return f"load average {one:.2f} {five:.2f} {fifteen:.2f} on {os.cpu_count() or 0} cores"


def bench_eval(
    env: str, robot_name: str | None, episodes: int, workers: int, seed: int, max_nodes: int
) -> dict[str, float]:
    from pointplan.distributed import ScenarioProblems, connect
    from pointplan.evaluation import evaluate
    from pointplan.planners import make_planner
    from pointplan.scenes.scenarios import make_scenario

    scenario = make_scenario(env, robot=robot_name)
    robot = scenario.robot
    problems = scenario.problems("test", episodes, seed=seed)
    t0 = time.perf_counter()
    serial = evaluate(make_planner("birrt", robot, seed=seed, max_nodes=max_nodes), problems, robot, progress=False)
    t_serial = time.perf_counter() - t0

    t0 = time.perf_counter()
    connect(workers)
    t_start = time.perf_counter() - t0
    times = []
    for _ in range(2):  # cold (the workers import pointplan on their first task), then warm
        t0 = time.perf_counter()
        parallel = evaluate(
            make_planner("birrt", robot, seed=seed, max_nodes=max_nodes),
            ScenarioProblems.of(scenario, "test", episodes, seed),
            robot,
            progress=False,
            workers=workers,
        )
        times.append(time.perf_counter() - t0)

    untimed = lambda m: {k: v for k, v in m.items() if not k.startswith("time")}  # noqa: E731
    same = untimed(serial.metrics()) == untimed(parallel.metrics()) and all(
        (a.tag, a.success, a.nodes, a.collision_checks) == (b.tag, b.success, b.nodes, b.collision_checks)
        and np.array_equal(a.path, b.path)
        for a, b in zip(serial.records, parallel.records, strict=True)
    )
    cold, warm = times
    busy = sum(r.time_s for r in parallel.records)
    print(
        f"eval: {episodes} {scenario.name} problems ({robot.name}), Bi-RRT: serial {t_serial:.1f} s; {workers} workers: {cold:.1f} s cold, {warm:.1f} s warm, Ray start-up {t_start:.1f} s"
    )
    print(
        f"      speed-up {t_serial / warm:.2f}x warm, {t_serial / cold:.2f}x cold, {t_serial / (cold + t_start):.2f}x with Ray's start-up (a fresh command); identical metrics and paths: {same}"
    )
    # where the time goes: scheduling overhead (workers idle) or slower planning (CPU shared)
    print(
        f"      warm run: workers planning {busy / warm:.2f} of {workers} on average; a problem took {busy / sum(r.time_s for r in serial.records):.2f}x its serial time"
    )
    return {"serial_s": t_serial, "cold_s": cold, "warm_s": warm, "ray_start_s": t_start, "identical": float(same)}


def bench_train(
    env: str,
    steps: int,
    workers: int,
    updates_per_step: float = 0.5,
    robot: str | None = None,
    observation: str | None = None,
) -> None:
    from pointplan.learning.train import TrainConfig, train
    from pointplan.models.actor_critic import NetConfig
    from pointplan.models.encoders import EncoderConfig

    net = NetConfig(
        EncoderConfig(width=32, layers=2), head_width=32, head_layers=2, critic_action="pooled", shared_encoder=True
    )
    cfg = TrainConfig(
        env=env,
        robot=robot,
        observation=observation or ("local" if robot else "surface-normals"),
        total_steps=steps,
        num_envs=8,
        eval_every=max(steps // 6, 500),
        eval_episodes=100,
        updates_per_step=updates_per_step,
        warmup_steps=500,
        net=net,
    )
    runs = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, w in (("serial", None), (f"{workers} workers", workers)):
            t0 = time.perf_counter()
            res = train(cfg, os.path.join(tmp, name.replace(" ", "_")), progress=False, workers=w)
            total = time.perf_counter() - t0
            runs[name] = res
            print(
                f"train {env} ({updates_per_step} updates per step), {name}: {res.steps} env steps in {res.wall_time_s:.1f} s = {res.steps / res.wall_time_s:.0f} steps/s ({total:.1f} s with start-up), {res.history[-1]['updates']:.0f} updates"
            )
    print("      validation success by env steps:")
    for name, res in runs.items():
        print(f"      {name:>10}: " + "  ".join(f"{int(r['env_steps'])}:{r['val_success']:.2f}" for r in res.history))
    s, p = runs["serial"], runs[f"{workers} workers"]
    print(f"      env steps/s: {p.steps / p.wall_time_s / (s.steps / s.wall_time_s):.2f}x the serial trainer's")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--env", default="narrow2d", help="evaluation scenario (default: %(default)s)")
    ap.add_argument("--robot", help="robot of a 3D scenario")
    ap.add_argument("--max-nodes", type=int, default=20000)
    ap.add_argument("--episodes", type=int, default=400, help="0 skips the evaluation part")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--train-env", default="empty2d")
    ap.add_argument(
        "--train-robot", help="robot of a 3D training scenario (sphere3d or sshape; its observation is `local`)"
    )
    ap.add_argument("--train-steps", type=int, default=6000, help="0 skips the training part")
    ap.add_argument(
        "--train-updates-per-step",
        type=float,
        default=0.5,
        help="gradient steps per env step (default: %(default)s, as in docs/guide/training.md)",
    )
    args = ap.parse_args()
    print(load())
    if args.episodes > 0:
        bench_eval(args.env, args.robot, args.episodes, args.workers, args.seed, args.max_nodes)
    if args.train_steps > 0:
        bench_train(args.train_env, args.train_steps, args.workers, args.train_updates_per_step, args.train_robot)
    print(load())


if __name__ == "__main__":
    main()
