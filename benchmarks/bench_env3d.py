"""Environment steps and observations per second in every 3D scene, for each observer and
robot, with 1 and 16 workspaces stepping together.

    python benchmarks/bench_env3d.py                 # every scene, ~2 s per row
    python benchmarks/bench_env3d.py --scenes boxes3d slot --seconds 1

"Env steps/s" counts environment transitions (a batch of E counts E) of the batched vector
env with random actions, observation included; "obs/s" times the observer alone on the
current configurations. Episodes reset as they end, so new workspaces are built along the
way (as in training). Run it on an otherwise idle machine.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from pointplan.envs import PlanningVectorEnv
from pointplan.envs.core import BatchedCore
from pointplan.scenes.scenes3d import SCENARIOS_3D


def rate(fn, seconds: float) -> float:  # type: ignore[no-untyped-def]
    """Calls per second of ``fn`` over about ``seconds`` (after one warm-up call)."""
    fn()
    n, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        fn()
        n += 1
    return n / (time.perf_counter() - t0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenes", nargs="*", default=list(SCENARIOS_3D))
    parser.add_argument("--robots", nargs="*", default=["sphere3d", "sshape"])
    parser.add_argument("--observations", nargs="*", default=["global", "local"])
    parser.add_argument("--envs", nargs="*", type=int, default=[1, 16])
    parser.add_argument("--seconds", type=float, default=2.0)
    args = parser.parse_args()
    print(f"{'scene':12s} {'robot':9s} {'observation':11s} {'E':>3s} {'env steps/s':>12s} {'obs/s':>10s}")
    for scene in args.scenes:
        for robot in args.robots:
            for observation in args.observations:
                for e in args.envs:
                    env = PlanningVectorEnv(scene, num_envs=e, robot=robot, observation=observation)
                    env.reset(seed=0)
                    rng = np.random.default_rng(0)

                    def step(env: PlanningVectorEnv = env, rng: np.random.Generator = rng, e: int = e) -> None:
                        env.step(rng.uniform(-1, 1, (e, env.robot.twist_dim)).astype(np.float32))

                    steps = rate(step, args.seconds) * e

                    def observe(core: BatchedCore = env.core, rng: np.random.Generator = rng) -> None:
                        core.observer.observe(core.q, rng, core.t)

                    obs = rate(observe, args.seconds / 2) * e
                    print(f"{scene:12s} {robot:9s} {observation:11s} {e:3d} {steps:12,.0f} {obs:10,.0f}", flush=True)


if __name__ == "__main__":
    main()
