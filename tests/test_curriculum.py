"""Retrying failed problems during training (learning/curriculum.py)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pointplan.envs.core import BatchedCore, EnvConfig
from pointplan.learning.curriculum import EpisodeSource, FailurePool
from pointplan.learning.train import TrainConfig, train
from pointplan.models.actor_critic import NetConfig
from pointplan.models.encoders import EncoderConfig
from pointplan.scenes import Problem
from pointplan.scenes.scenarios import make_scenario


def _problems(n: int) -> list[Problem]:
    return make_scenario("narrow2d").problems("val", n)


def test_pool_lends_a_failure_retries_times_and_a_new_failure_renews_it() -> None:
    rng = np.random.default_rng(0)
    pool = FailurePool(capacity=10, retries=3)
    assert pool.draw(rng) is None
    p = _problems(1)[0]
    key = pool.failed(p)
    drawn = [pool.draw(rng) for _ in range(4)]
    assert [d[1] if d else None for d in drawn] == [p, p, p, None]
    assert pool.failed(p, key) == key  # failing again after its last draw brings it back
    assert len(pool) == 1 and [pool.draw(rng)[0] for _ in range(3)] == [key] * 3  # type: ignore[index]
    assert pool.draw(rng) is None


def test_pool_drops_its_oldest_problems_beyond_capacity() -> None:
    pool = FailurePool(capacity=2, retries=5)
    a, b, c = _problems(3)
    pool.failed(a)
    kb, kc = pool.failed(b), pool.failed(c)
    assert pool.keys() == [kb, kc]  # a, the oldest, went
    pool.failed(b, kb)  # b is now the newest: the next newcomer pushes out c
    ka2 = pool.failed(a)
    assert pool.keys() == [kb, ka2]
    with pytest.raises(ValueError):
        FailurePool(capacity=0)


def test_episode_source_restarts_failed_problems_exactly() -> None:
    scenario = make_scenario("narrow2d")
    core = BatchedCore(scenario, 4, EnvConfig(split="train"))
    pool = FailurePool(retries=2)
    source = EpisodeSource(core, pool, retry=1.0)
    rng = np.random.default_rng(1)
    source.reset(range(4), rng)  # the pool is empty: four fresh problems
    assert source.retry_share == 0.0 and not any(source.is_retry(i) for i in range(4))
    start, goal, scene = core.q[2].copy(), core.goal[2].copy(), core.scenes[2]
    source.ended(2, success=False)
    source.ended(1, success=True)  # successes are not kept
    assert len(pool) == 1
    source.reset([0, 1, 3], rng)  # envs 0 and 1 get the failed problem (two retries); 3 a fresh one
    assert source.is_retry(0) and source.is_retry(1) and not source.is_retry(3)
    for i in (0, 1):
        assert core.scenes[i] is scene
        np.testing.assert_array_equal(core.q[i], start)
        np.testing.assert_array_equal(core.goal[i], goal)
    assert source.retry_share == pytest.approx(2 / 7) and len(pool) == 0
    source.ended(0, success=True)
    source.reset([0], rng)  # no retries left
    assert not source.is_retry(0)
    source.ended(1, success=False)  # a retry failed: the problem is back, under the same key
    assert len(pool) == 1 and pool.keys() == [source.key[1]]
    source.reset([1], rng)
    assert source.is_retry(1) and core.scenes[1] is scene


def test_episode_source_without_retries_leaves_the_rng_alone() -> None:
    """With the option off, episodes are drawn exactly as before it existed."""
    scenario = make_scenario("narrow2d")
    b = BatchedCore(scenario, 3, EnvConfig(split="train"))
    rb = np.random.default_rng(5)
    b.reset_envs(range(3), rb)
    pool = FailurePool()
    pool.failed(_problems(1)[0])  # a pool that is only filled (mining), never drawn from
    for p in (None, pool):
        a = BatchedCore(scenario, 3, EnvConfig(split="train"))
        ra = np.random.default_rng(5)
        EpisodeSource(a, p, retry=0.0).reset(range(3), ra)
        np.testing.assert_array_equal(a.q, b.q)
        np.testing.assert_array_equal(a.goal, b.goal)
        assert ra.bit_generator.state == rb.bit_generator.state
    with pytest.raises(ValueError, match="pool"):
        EpisodeSource(b, None, retry=0.5)


@pytest.mark.slow
def test_training_with_retries_logs_the_pool(tmp_path: Path) -> None:
    small = NetConfig(
        EncoderConfig(width=32, layers=2), head_width=32, head_layers=2, critic_action="pooled", shared_encoder=True
    )
    cfg = TrainConfig(
        num_envs=8,
        total_steps=1_600,
        warmup_steps=400,
        eval_every=800,
        eval_episodes=10,
        retry_failures=0.5,
        mine_episodes=20,
        net=small,
    )
    res = train(cfg, tmp_path, progress=False)
    last = res.history[-1]
    # an untrained policy fails most problems: the pool fills and about half the episodes retry
    assert last["pool_size"] > 0 and 0.2 < last["retry_share"] <= 0.5 + 0.1
    assert 0.0 <= last["mine_success"] <= 0.5
