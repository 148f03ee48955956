"""Training is the same for a fixed seed across refactors of the loop (every count
exactly; the float statistics up to what the CPU's float kernels move).

The numbers below were recorded with the training loop as it was before it was split into
functions (commit 55d42f4), on a tiny seeded run that goes through warm-up, updates, the
averaged actor, failure mining and retries, and a resume from ``last.pt``.
"""

from __future__ import annotations

import csv
from dataclasses import replace

import pytest

from pointplan.learning.train import TrainConfig, train

pytestmark = pytest.mark.slow

RECORDED = [
    {
        "env_steps": 1000.0,
        "updates": 126.0,
        "val_success": 0.05,
        "train_success": 0.058823529411764705,
        "val_nodes": 2.0,
        "val_success_current": 0.1,
        "mine_success": 0.0,
        "pool_size": 26.0,
        "retry_share": 0.20833333333333334,
        "critic_loss": 102.06297302246094,
        "actor_loss": -7.372157096862793,
        "alpha": 0.9631901979446411,
        "q_mean": 6.145164966583252,
        "entropy": 1.3449686765670776,
    },
    {
        "env_steps": 2000.0,
        "updates": 376.0,
        "val_success": 0.05,
        "train_success": 0.06896551724137931,
        "val_nodes": 2.0,
        "val_success_current": 0.15,
        "mine_success": 0.1,
        "pool_size": 46.0,
        "retry_share": 0.3181818181818182,
        "critic_loss": 81.72299194335938,
        "actor_loss": -9.419023513793945,
        "alpha": 0.8934909701347351,
        "q_mean": 8.186773300170898,
        "entropy": 1.3694477081298828,
    },
    {
        "env_steps": 3000.0,
        "updates": 577.0,
        "val_success": 0.05,
        "train_success": 0.06666666666666667,
        "val_nodes": 3.0,
        "val_success_current": 0.15,
        "mine_success": 0.0,
        "pool_size": 24.0,
        "retry_share": 0.28,
        "critic_loss": 52.649024963378906,
        "actor_loss": -10.310806274414062,
        "alpha": 0.8411878943443298,
        "q_mean": 9.418928146362305,
        "entropy": 1.4011788368225098,
    },
]


#: the metrics computed with float kernels (the rest are counts and rates of episodes)
FLOATS = ("critic_loss", "actor_loss", "alpha", "q_mean", "entropy")


def test_seeded_training_matches_the_recorded_run(tmp_path):
    cfg = TrainConfig(
        env="narrow2d",
        num_envs=4,
        total_steps=3000,
        warmup_steps=500,
        eval_every=1000,
        eval_episodes=20,
        seed=3,
        retry_failures=0.3,
        mine_episodes=10,
    )
    cfg = replace(cfg, sac=replace(cfg.sac, batch_size=64, policy_avg=1e-3))
    train(replace(cfg, total_steps=2000), tmp_path, progress=False)
    train(cfg, tmp_path, progress=False, resume=tmp_path / "last.pt")
    with (tmp_path / "metrics.csv").open(newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == len(RECORDED)
    for i, (row, want) in enumerate(zip(rows, RECORDED, strict=True)):
        got = {k: float(row[k]) for k in want}
        # Counts and success rates exactly. The losses and network statistics move in their
        # last bits with the CPU's float kernels (AVX2 or AVX-512) and between runs on a
        # loaded 2-core machine (seen: actor loss -7.3721552 and -7.3721566 against the
        # recorded -7.3721571 at 1,000 steps), and SAC compounds it (3% apart at 3,000
        # steps, with every count still equal): to a relative 1e-4 at the first row, 5%
        # after.
        exact = {k: v for k, v in want.items() if k not in FLOATS}
        assert {k: got[k] for k in exact} == exact
        for k in FLOATS:
            assert got[k] == pytest.approx(want[k], rel=1e-4 if i == 0 else 0.05), (row["env_steps"], k)
