"""Environment throughput: steps per second of the vector and the single env.

    python benchmarks/bench_env.py            # ~4 s per configuration
    python benchmarks/bench_env.py --quick    # ~1 s per configuration

Actions are uniform in [-1, 1] (drawn beforehand, so sampling is not timed). Rates count
every environment step, and the resets triggered by ended episodes (autoreset in the
vector env, an explicit ``reset()`` for the single env) are included in the time.
``q_free`` is also timed alone, on the stacked world of a reset vector env.
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np

import pointplan  # noqa: F401  (registers the ids)
from pointplan.envs import PlanningVectorEnv, q_free


def bench_vector(num_envs: int, observation: str, duration: float, seed: int = 0) -> tuple[float, float]:
    """(env steps/s, episodes ended per 1000 env steps)."""
    env = PlanningVectorEnv("narrow2d", num_envs=num_envs, observation=observation)
    env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    actions = rng.uniform(-1, 1, (256, num_envs, 2)).astype(np.float32)
    for a in actions[:5]:  # warm-up
        env.step(a)
    steps = ended = 0
    t0 = time.perf_counter()
    while True:
        for a in actions:
            _, _, term, trunc, _ = env.step(a)
            ended += int(np.sum(term | trunc))
            steps += 1
            if steps % 8 == 0 and time.perf_counter() - t0 >= duration:
                break
        else:
            continue
        break
    dt = time.perf_counter() - t0
    env.close()
    return steps * num_envs / dt, 1000.0 * ended / (steps * num_envs)


def bench_single(observation: str, duration: float, seed: int = 0) -> tuple[float, float]:
    env = gym.make("pointplan/Narrow2D-v0", observation=observation)
    env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    actions = rng.uniform(-1, 1, (256, 2)).astype(np.float32)
    steps = ended = 0
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < duration:
        for a in actions:
            _, _, term, trunc, _ = env.step(a)
            steps += 1
            if term or trunc:
                ended += 1
                env.reset()
    dt = time.perf_counter() - t0
    env.close()
    return steps / dt, 1000.0 * ended / steps


def bench_q_free(num_envs: int, duration: float, seed: int = 0) -> float:
    """Seconds per ``q_free`` call on ``num_envs`` environments."""
    env = PlanningVectorEnv("narrow2d", num_envs=num_envs)
    env.reset(seed=seed)
    core = env.core
    world = core.world
    rng = np.random.default_rng(seed)
    twists = rng.uniform(-1, 1, (64, num_envs, 2)) * core.robot.action_scale
    q_free(core.robot, world, core.q, twists[0], core.low, core.high, core.config.substep)
    calls = 0
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < duration:
        for tw in twists:
            q_free(core.robot, world, core.q, tw, core.low, core.high, core.config.substep)
        calls += len(twists)
    return (time.perf_counter() - t0) / calls


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="about 1 s per configuration")
    args = parser.parse_args()
    duration = 1.0 if args.quick else 4.0

    rows = [("vector", e, "surface-normals") for e in (1, 16, 64)] + [("vector", e, "image") for e in (1, 16)]
    rows += [("gym.make", 1, "surface-normals"), ("gym.make", 1, "image")]
    header = f"{'env':<9} {'E':>3} {'observation':<16} {'env steps/s':>12} {'vs E=1':>7} {'episodes/1k steps':>18}"
    print(header)
    print("-" * len(header))
    base: dict[tuple[str, str], float] = {}
    for kind, e, obs in rows:
        if kind == "vector":
            r, eps = bench_vector(e, obs, duration)
        else:
            r, eps = bench_single(obs, duration)
        base.setdefault((kind, obs), r)
        print(f"{kind:<9} {e:>3} {obs:<16} {r:>12,.0f} {r / base[(kind, obs)]:>6.1f}x {eps:>18.1f}")

    print()
    header = f"{'q_free':<9} {'E':>3} {'us/call':>10} {'us/env':>9}"
    print(header)
    print("-" * len(header))
    for e in (1, 16, 64):
        t = bench_q_free(e, duration / 2)
        print(f"{'':<9} {e:>3} {1e6 * t:>10.1f} {1e6 * t / e:>9.2f}")


if __name__ == "__main__":
    main()
