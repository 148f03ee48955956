"""PPO fine-tuning: its estimators against direct computations, the direction of an update,
and a run through the command line (tiny budget), resumed."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import torch

from pointplan.learning.ppo import PPOConfig, PPORun, _Batch, gae, gaussian_logp
from pointplan.models.checkpoint import load_checkpoint
from pointplan.models.policy import Policy, shipped_checkpoint


def test_gaussian_logp_matches_torch_distributions() -> None:
    torch.manual_seed(0)
    mean, log_std, u = torch.randn(7, 6), torch.randn(7, 6) * 0.5, torch.randn(7, 6)
    expected = torch.distributions.Normal(mean, log_std.exp()).log_prob(u).sum(-1)
    assert torch.allclose(gaussian_logp(u, mean, log_std), expected, atol=1e-5)


def _gae_direct(r: np.ndarray, v: np.ndarray, nv: np.ndarray, d: np.ndarray, gamma: float, lam: float) -> np.ndarray:
    """The advantage as the explicit sum over later TD errors of the same episode."""
    T, E = r.shape
    delta = r + gamma * nv - v
    adv = np.zeros_like(r)
    for e in range(E):
        for t in range(T):
            total, w = 0.0, 1.0
            for k in range(t, T):
                total += w * delta[k, e]
                if d[k, e]:
                    break
                w *= gamma * lam
            adv[t, e] = total
    return adv


def test_gae_equals_the_sum_of_discounted_td_errors_cut_at_episode_ends() -> None:
    rng = np.random.default_rng(1)
    T, E = 12, 3
    r, v, nv = rng.normal(size=(T, E)), rng.normal(size=(T, E)), rng.normal(size=(T, E))
    d = (rng.uniform(size=(T, E)) < 0.2).astype(np.float64)
    adv, ret = gae(r, v, nv, d, 0.97, 0.9)
    np.testing.assert_allclose(adv, _gae_direct(r, v, nv, d, 0.97, 0.9), atol=1e-12)
    np.testing.assert_allclose(ret, adv + v)
    # lambda = 1 with no episode end and zero values: the discounted return to the end plus its tail value
    adv1, _ = gae(r[:, :1], np.zeros((T, 1)), np.zeros((T, 1)), np.zeros((T, 1)), 0.97, 1.0)
    np.testing.assert_allclose(adv1[0, 0], sum(0.97**k * r[k, 0] for k in range(T)), atol=1e-12)


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> PPORun:
    torch.set_num_threads(1)
    cfg = PPOConfig(
        init_actor=str(shipped_checkpoint("disc2d")), num_envs=4, rollout_steps=10, minibatch=20, eval_episodes=5, value_warmup=0, lr=3e-4, target_kl=0
    )
    return PPORun(cfg, tmp_path_factory.mktemp("ppo"), None)


def test_collect_gives_consistent_batches(run: PPORun) -> None:
    steps = run.steps
    b = run.collect()
    n = run.cfg.num_envs * run.cfg.rollout_steps
    assert run.steps == steps + n
    assert b.obs.shape == (n,) + run.obs_shape and b.u.shape == (n, run.robot.twist_dim)
    with torch.no_grad():  # the stored log-probabilities are those of the acting policy
        mean, log_std = run.actor(run.tensor(b.obs), run.tensor(b.goal))
        np.testing.assert_allclose(gaussian_logp(run.tensor(b.u), mean, log_std).numpy(), b.logp, rtol=1e-4, atol=1e-4)
    assert np.isfinite(b.adv).all() and np.isfinite(b.ret).all()


def test_an_update_moves_the_policy_toward_actions_with_positive_advantage(run: PPORun) -> None:
    b = run.collect()
    obs, goal, u = run.tensor(b.obs), run.tensor(b.goal), run.tensor(b.u)
    with torch.no_grad():
        mean0, log_std0 = run.actor(obs, goal)
    # draws above the mean on the first axis are better than those below it
    adv = np.where(b.u[:, 0] > mean0[:, 0].numpy(), 1.0, -1.0).astype(np.float32)
    stats = run.update(_Batch(b.obs, b.goal, b.u, b.logp, adv, b.ret))
    with torch.no_grad():
        mean1, log_std1 = run.actor(obs, goal)
    change = (gaussian_logp(u, mean1, log_std1) - gaussian_logp(u, mean0, log_std0)).numpy()
    assert change[adv > 0].mean() > change[adv < 0].mean()
    assert float((mean1[:, 0] - mean0[:, 0]).mean()) > 0
    assert math.isfinite(stats["approx_kl"]) and stats["approx_kl"] > 0


def test_ppo_command_runs_saves_and_resumes(tmp_path: Path) -> None:
    from pointplan.cli import main

    run_dir = tmp_path / "run"
    common = ["--num-envs", "4", "--rollout-steps", "10", "--eval-every", "40", "--eval-episodes", "4", "--value-warmup", "1", "--quiet"]
    out = tmp_path / "s.json"
    code = main(["ppo", "--init-actor", str(shipped_checkpoint("disc2d")), "--steps", "80", "--run-dir", str(run_dir), "--json", str(out), *common])
    assert code == 0
    assert json.loads(out.read_text())["steps"] == 80
    last = load_checkpoint(run_dir / "last.pt")
    assert last["ppo"]["steps"] == 80 and last["ppo"]["iterations"] == 2
    # best.pt is an ordinary policy checkpoint
    policy = Policy.from_checkpoint(run_dir / "best.pt")
    assert policy.robot.name == "disc2d"
    rows = (run_dir / "metrics.csv").read_text().splitlines()
    assert len(rows) == 1 + 3  # the start, then two validations
    assert main(["ppo", "--resume", str(run_dir / "last.pt"), "--steps", "120", *common]) == 0
    assert load_checkpoint(run_dir / "last.pt")["ppo"]["steps"] == 120
    assert len((run_dir / "metrics.csv").read_text().splitlines()) == 1 + 4
    # a resume past the end, a missing initial policy, a policy checkpoint given as a trainer state: clear errors
    assert main(["ppo", "--resume", str(run_dir / "last.pt"), "--steps", "100", *common]) == 2
    assert main(["ppo", "--steps", "100", *common]) == 2
    assert main(["ppo", "--resume", str(run_dir / "best.pt"), "--steps", "400", *common]) == 2
