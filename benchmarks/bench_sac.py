"""SAC update rate for several network configurations, and policy latency at batch 1.

    python benchmarks/bench_sac.py            # ~5 s per configuration
    python benchmarks/bench_sac.py --quick
    python benchmarks/bench_sac.py --image    # the Table 1 CNN cell, channels-last against the default layout
    python benchmarks/bench_sac.py --image-malloc   # the same cell, keep_freed_memory() against glibc's default

Updates use batches of 256 transitions of 64 points x 4 features (2D-Narrow observations
from the environment), HER relabelling included. Run it on an otherwise idle machine:
PyTorch's worker threads slow down badly when another process competes for the cores.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from pointplan.envs.core import BatchedCore, EnvConfig
from pointplan.learning.replay import EpisodeReplay
from pointplan.learning.sac import SAC, SACConfig
from pointplan.models.actor_critic import NetConfig
from pointplan.models.encoders import EncoderConfig
from pointplan.scenes.scenarios import Narrow2DScenario

CONFIGS = {
    "paper (3x256, separate, action on points)": NetConfig(
        EncoderConfig(width=256), head_width=256, critic_action="points"
    ),
    "3x256, separate, action after pooling": NetConfig(
        EncoderConfig(width=256), head_width=256, critic_action="pooled"
    ),
    "3x256, shared": NetConfig(EncoderConfig(width=256), head_width=256, critic_action="pooled", shared_encoder=True),
    "3x128, shared": NetConfig(EncoderConfig(width=128), head_width=128, critic_action="pooled", shared_encoder=True),
    "3x64, separate, action after pooling": NetConfig(EncoderConfig(width=64), head_width=64, critic_action="pooled"),
    "3x64, shared (default)": NetConfig(
        EncoderConfig(width=64), head_width=64, critic_action="pooled", shared_encoder=True
    ),
    "3x32, shared": NetConfig(EncoderConfig(width=32), head_width=32, critic_action="pooled", shared_encoder=True),
}


def filled_buffer(rng: np.random.Generator, episodes: int = 40) -> EpisodeReplay:
    scenario = Narrow2DScenario()
    core = BatchedCore(scenario, 8, EnvConfig())
    buf = EpisodeReplay(episodes * 50 + 100, (64, 4), 2, 2)
    for _ in range(episodes // 8):
        core.reset_envs(range(8), rng)
        obs, q, qn, a, col = [], [], [], [], []
        for _ in range(50):
            obs.append(core.observe(rng)["observation"])
            q.append(core.q.copy())
            act = rng.uniform(-1, 1, (8, 2)).astype(np.float32)
            _, _, _, info = core.step(act)
            qn.append(core.q.copy())
            a.append(act)
            col.append(info["collided"])
        obs_a = np.stack(obs, 1)
        for i in range(8):
            buf.add_episode(
                obs_a[i],
                obs_a[i],
                np.stack(q, 1)[i],
                np.stack(qn, 1)[i],
                np.broadcast_to(core.goal[i], (50, 2)),
                np.stack(a, 1)[i],
                np.linalg.norm(np.stack(a, 1)[i], axis=1),
                np.stack(col, 1)[i],
            )
    return buf


def image_buffer(rng: np.random.Generator, episodes: int = 16) -> EpisodeReplay:
    """Episodes of random actions in 2D-Narrow with 64 x 64 occupancy images."""
    scenario = Narrow2DScenario()
    core = BatchedCore(scenario, 8, EnvConfig(observation="image"))
    buf = EpisodeReplay(episodes * 50 + 100, (1, 64, 64), 2, 2)
    for _ in range(episodes // 8):
        core.reset_envs(range(8), rng)
        obs, q, qn, a, col = [], [], [], [], []
        for _ in range(50):
            obs.append(core.observe(rng)["observation"])
            q.append(core.q.copy())
            act = rng.uniform(-1, 1, (8, 2)).astype(np.float32)
            _, _, _, info = core.step(act)
            qn.append(core.q.copy())
            a.append(act)
            col.append(info["collided"])
        obs_a, q_a, qn_a, a_a, col_a = (
            np.stack(obs, 1),
            np.stack(q, 1),
            np.stack(qn, 1),
            np.stack(a, 1),
            np.stack(col, 1),
        )
        for i in range(8):
            buf.add_episode(
                obs_a[i],
                obs_a[i],
                q_a[i],
                qn_a[i],
                np.broadcast_to(core.goal[i], (50, 2)),
                a_a[i],
                np.linalg.norm(a_a[i], axis=1),
                col_a[i],
            )
    return buf


def bench_image(duration: float, device: str) -> None:
    """SAC updates of the Table 1 image / CNN cell (3 x 64 heads, shared CNN, batches of
    256) with the CNN channels-last, as it ships, and converted back to the default layout."""
    rng = np.random.default_rng(0)
    buf = image_buffer(rng)
    robot = Narrow2DScenario().robot
    net = NetConfig(
        EncoderConfig("cnn", 64, 3), head_width=64, head_layers=3, critic_action="pooled", shared_encoder=True
    )
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads, device {device}")
    rates = {}
    for layout in ("channels-last (shipped)", "default layout"):
        torch.manual_seed(0)
        sac = SAC(robot, EnvConfig(observation="image"), (1, 64, 64), net, SACConfig(), device=device)
        if layout == "default layout":
            for m in (
                m
                for part in (sac.actor, sac.critic, sac.critic_target, sac.actor_avg)
                if part is not None
                for m in part.modules()
            ):
                if isinstance(m, torch.nn.Conv2d):
                    m.to(memory_format=torch.contiguous_format)  # type: ignore[call-overload]
        sac.update(buf.sample(256, rng))
        n, t0 = 0, time.perf_counter()
        while time.perf_counter() - t0 < duration:
            sac.update(buf.sample(256, rng))
            n += 1
        rates[layout] = n / (time.perf_counter() - t0)
        print(f"image / CNN, {layout:24s} {rates[layout]:6.2f} updates/s")
    print(f"channels-last: {rates['channels-last (shipped)'] / rates['default layout']:.2f}x the default layout")


def image_rate(duration: float, device: str) -> None:
    """One process's image / CNN update rate (channels-last, as shipped) and the share of
    its CPU time spent in the kernel, as one JSON line; ``keep_freed_memory()`` applies
    unless ``POINTPLAN_SYSTEM_MALLOC`` is set."""
    import json
    import resource

    from pointplan.learning.memory import keep_freed_memory

    kept = keep_freed_memory()
    rng = np.random.default_rng(0)
    buf = image_buffer(rng)
    robot = Narrow2DScenario().robot
    net = NetConfig(
        EncoderConfig("cnn", 64, 3), head_width=64, head_layers=3, critic_action="pooled", shared_encoder=True
    )
    torch.manual_seed(0)
    sac = SAC(robot, EnvConfig(observation="image"), (1, 64, 64), net, SACConfig(), device=device)
    sac.update(buf.sample(256, rng))
    r0 = resource.getrusage(resource.RUSAGE_SELF)
    n, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < duration:
        sac.update(buf.sample(256, rng))
        n += 1
    rate = n / (time.perf_counter() - t0)
    r1 = resource.getrusage(resource.RUSAGE_SELF)
    user, system = r1.ru_utime - r0.ru_utime, r1.ru_stime - r0.ru_stime
    faults = r1.ru_minflt - r0.ru_minflt
    print(json.dumps({"kept": kept, "rate": rate, "kernel_share": system / max(user + system, 1e-9), "faults": faults}))


def bench_image_malloc(duration: float, rounds: int, device: str) -> None:
    """The image / CNN cell's update rate with glibc's default ``malloc`` and with
    :func:`~pointplan.learning.memory.keep_freed_memory`, each in its own process, taking
    turns ``rounds`` times; the ratio of the median rates."""
    import json
    import os
    import subprocess
    import sys

    rates: dict[str, list[float]] = {"glibc default": [], "keep_freed_memory": []}
    for r in range(rounds):
        for name in rates:
            env = dict(os.environ)
            env.pop("POINTPLAN_SYSTEM_MALLOC", None)
            if name == "glibc default":
                env["POINTPLAN_SYSTEM_MALLOC"] = "1"
            cmd = [sys.executable, __file__, "--image-rate", str(duration), "--device", device]
            line = subprocess.run(cmd, env=env, check=True, capture_output=True, text=True).stdout.strip().splitlines()
            res = json.loads(line[-1])
            rates[name].append(res["rate"])
            print(
                f"round {r + 1}, {name:18s} {res['rate']:6.2f} updates/s, kernel {100 * res['kernel_share']:4.1f}% "
                f"of CPU time, {res['faults'] / max(duration, 1e-9):9.0f} page faults/s",
                flush=True,
            )
    med = {k: float(np.median(v)) for k, v in rates.items()}
    print(f"keep_freed_memory: {med['keep_freed_memory'] / med['glibc default']:.2f}x glibc's default (median rates)")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--image", action="store_true", help="the Table 1 image / CNN cell instead")
    ap.add_argument("--image-malloc", action="store_true", help="the image cell, keep_freed_memory() or not")
    ap.add_argument("--image-rate", type=float, default=None, help=argparse.SUPPRESS)  # (one child's run)
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    duration = 2.0 if args.quick else 5.0
    if args.image_rate is not None:
        image_rate(args.image_rate, args.device)
        return
    if args.image_malloc:
        bench_image_malloc(4 * duration, args.rounds, args.device)
        return
    if args.image:
        bench_image(4 * duration, args.device)
        return
    rng = np.random.default_rng(0)
    torch.manual_seed(0)
    buf = filled_buffer(rng)
    robot = Narrow2DScenario().robot
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads, device {args.device}")
    print(f"{'network':45s} {'updates/s':>10s} {'vs paper':>9s} {'latency b=1 (ms)':>17s}")
    base = None
    for name, net in CONFIGS.items():
        sac = SAC(robot, EnvConfig(), (64, 4), net, SACConfig(), device=args.device)
        sac.update(buf.sample(256, rng))
        n, t0 = 0, time.perf_counter()
        while time.perf_counter() - t0 < duration:
            sac.update(buf.sample(256, rng))
            n += 1
        rate = n / (time.perf_counter() - t0)
        base = base or rate
        b = buf.sample(1, rng)
        for _ in range(20):
            sac.act(b.obs, b.q, b.goal, deterministic=True)
        m, t0 = 0, time.perf_counter()
        while time.perf_counter() - t0 < duration / 4:
            sac.act(b.obs, b.q, b.goal, deterministic=True)
            m += 1
        lat = (time.perf_counter() - t0) / m * 1000
        print(f"{name:45s} {rate:10.1f} {rate / base:8.1f}x {lat:17.2f}")


if __name__ == "__main__":
    main()
