"""PPO fine-tuning: its estimators against direct computations, the direction of an update,
and a run through the command line (tiny budget), resumed."""

from __future__ import annotations

import json
import math
from dataclasses import replace
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
def run(tmp_path_factory: pytest.TempPathFactory, one_torch_thread: None) -> PPORun:
    cfg = PPOConfig(
        init_actor=str(shipped_checkpoint("disc2d")),
        num_envs=4,
        rollout_steps=10,
        minibatch=20,
        eval_episodes=5,
        value_warmup=0,
        lr=3e-4,
        target_kl=0,
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
    common = [
        "--num-envs",
        "4",
        "--rollout-steps",
        "10",
        "--eval-every",
        "40",
        "--eval-episodes",
        "4",
        "--value-warmup",
        "1",
        "--quiet",
    ]
    out = tmp_path / "s.json"
    code = main(
        [
            "ppo",
            "--init-actor",
            str(shipped_checkpoint("disc2d")),
            "--steps",
            "80",
            "--run-dir",
            str(run_dir),
            "--json",
            str(out),
            *common,
        ]
    )
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
    # resumed with the same validation the best so far stands; with another one it starts afresh
    from pointplan.config import from_dict

    state = load_checkpoint(run_dir / "last.pt")
    same = from_dict(PPOConfig, state["ppo_config"])
    assert PPORun(same, tmp_path / "again", run_dir / "last.pt").best == state["ppo"]["best"] >= 0
    other = from_dict(PPOConfig, {**state["ppo_config"], "eval_episodes": 2})
    assert PPORun(other, tmp_path / "other", run_dir / "last.pt").best == -1.0


@pytest.fixture(scope="module")
def demos_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from pointplan.learning.bc import generate_demos, save_demos
    from pointplan.scenes.scenarios import make_scenario

    scenario = make_scenario("narrow2d")
    demos = generate_demos(scenario, 6, seed=0, progress=False)
    path = tmp_path_factory.mktemp("demos") / "demos.npz"
    save_demos(path, scenario, demos, "train", 0)
    return path


def test_reverse_curriculum_starts_on_the_demonstrations_near_their_goal(demos_file: Path, tmp_path: Path) -> None:
    cfg = PPOConfig(
        init_actor=str(shipped_checkpoint("disc2d")), num_envs=8, rollout_steps=4, eval_episodes=2, start_demos=str(demos_file), start_share=1.0, start_back=2,
        start_back_step=3, start_advance=0.5, start_min_episodes=4,
    )  # fmt: skip
    run = PPORun(cfg, tmp_path, None)
    assert run.from_demo.all()
    for i in range(cfg.num_envs):  # every start is one of the last two steps before a path's end, with that path's goal
        hits = [
            len(path) - 1 - int(np.flatnonzero(np.all(np.isclose(path, run.core.q[i]), axis=1))[0])
            for prob, path in run.demo_paths
            if np.allclose(prob.goal, run.core.goal[i]) and np.all(np.isclose(path, run.core.q[i]), axis=1).any()
        ]
        assert hits and 1 <= hits[0] <= 2
    longest = max(len(p) for _, p in run.demo_paths) - 1
    run.frontier = [1.0, 1.0, 1.0]  # too few frontier episodes
    run.advance()
    assert run.back == 2
    run.frontier = [1.0, 0.0, 0.0, 1.0, 0.0, 0.0]  # too few of the last 4 succeeded
    run.advance()
    assert run.back == 2 and run.frontier == [0.0, 1.0, 0.0, 0.0]  # a sliding window
    run.frontier += [1.0, 1.0]  # the last 4: 0, 0, 1, 1
    run.advance()
    assert run.back == 5 and run.frontier == []
    for _ in range(longest):
        run.frontier = [1.0] * 4
        run.advance()
    assert run.back == longest  # at most the longest path: its starts are then the problems' own
    # half of the starts drawn at the frontier (here its last step, 2 before the goal), half anywhere in the range
    run3 = PPORun(replace(cfg, start_band=1), tmp_path / "c", None)
    assert min(len(p) for _, p in run3.demo_paths) >= 3
    fronts = []
    for _ in range(200):
        run3.reset([0])
        fronts.append(run3.at_frontier[0])
    assert 0.65 < np.mean(fronts) < 0.85  # 1/2 + 1/2 x 1/2
    # with no share, every episode is a fresh problem
    run2 = PPORun(
        PPOConfig(init_actor=cfg.init_actor, num_envs=4, eval_episodes=2, start_demos=str(demos_file), start_share=0.0),
        tmp_path / "b",
        None,
    )
    assert not run2.from_demo.any()


def test_reverse_curriculum_takes_several_paths_per_problem(demos_file: Path, tmp_path: Path) -> None:
    """A roadmap expert's file holds several paths of one problem: each keeps its own problem."""
    from pointplan.learning.bc import demos_from_paths, load_demos, save_demos
    from pointplan.scenes.scenarios import make_scenario

    scenario = make_scenario("narrow2d")
    one = load_demos(demos_file, scenario)
    twice = [(k, path) for k, path in one.paths for path in (path, path[1:])]  # a second, shorter path of each
    path = tmp_path / "twice.npz"
    save_demos(path, scenario, demos_from_paths(scenario, "train", 0, twice), "train", 0)
    cfg = PPOConfig(init_actor=str(shipped_checkpoint("disc2d")), num_envs=2, eval_episodes=2, start_demos=str(path))
    run = PPORun(cfg, tmp_path / "run", None)
    assert len(run.demo_paths) == len(twice) == 2 * len(one.problems)
    for prob, demo in run.demo_paths:
        assert np.allclose(demo[-1], prob.goal, atol=1e-6)  # every path ends at its own problem's goal


def test_ppo_command_keeps_the_curriculum_across_a_resume(demos_file: Path, tmp_path: Path) -> None:
    from pointplan.cli import main

    run_dir = tmp_path / "run"
    common = [
        "--num-envs",
        "4",
        "--rollout-steps",
        "10",
        "--eval-every",
        "40",
        "--eval-episodes",
        "2",
        "--value-warmup",
        "1",
        "--quiet",
    ]
    curriculum = [
        "--start-demos",
        str(demos_file),
        *[
            "--start-back",
            "3",
            "--start-back-step",
            "2",
            "--start-advance",
            "0.01",
            "--start-min-episodes",
            "1",
            "--start-frontier-share",
            "1",
        ],
    ]
    assert (
        main(
            [
                "ppo",
                "--init-actor",
                str(shipped_checkpoint("disc2d")),
                "--steps",
                "40",
                "--run-dir",
                str(run_dir),
                *curriculum,
                *common,
            ]
        )
        == 0
    )
    saved = load_checkpoint(run_dir / "last.pt")
    back = saved["ppo"]["back"]
    assert back > 3  # advanced (a frontier episode that succeeded passes the 1% bar)
    from pointplan.config import from_dict

    # restored, not restarted
    assert PPORun(from_dict(PPOConfig, saved["ppo_config"]), run_dir, run_dir / "last.pt").back == back
    header = (run_dir / "metrics.csv").read_text().splitlines()[0].split(",")
    assert "start_back" in header and "demo_start_success" in header
    assert main(["ppo", "--resume", str(run_dir / "last.pt"), "--steps", "80", *common]) == 0
    assert load_checkpoint(run_dir / "last.pt")["ppo"]["back"] >= back
    # demonstrations of another scenario are refused
    other = tmp_path / "other.npz"
    with np.load(demos_file) as f:
        np.savez(other, **{k: (np.array("boxes3d") if k == "env" else f[k]) for k in f.files})
    refused = [
        "ppo",
        "--init-actor",
        str(shipped_checkpoint("disc2d")),
        "--steps",
        "40",
        "--run-dir",
        str(tmp_path / "r2"),
        "--start-demos",
        str(other),
    ]
    assert main([*refused, *common]) == 2


def test_the_greedy_goal_test_ends_episodes_whose_straight_edge_to_the_goal_is_free(tmp_path: Path) -> None:
    from pointplan.planners.edges import edge_free

    cfg = PPOConfig(
        init_actor=str(shipped_checkpoint("disc2d")), num_envs=8, rollout_steps=4, eval_episodes=2, greedy_goal=True
    )
    run = PPORun(cfg, tmp_path, None)
    run.core.q[0] = run.core.goal[0]  # at the goal: free for sure
    reward, term, trunc = np.full(8, -0.1), np.zeros(8, bool), np.ones(8, bool)
    term[7] = True  # an episode that already ended is left alone
    r2, t2, tr2 = run.greedy(reward, term, trunc)
    free = [
        edge_free(run.robot, s.world, q, g, 0.01, s.low, s.high)[0]
        for s, q, g in zip(run.core.scenes, run.core.q, run.core.goal)
    ]
    assert free[0] and not all(free[:7])  # some of the random starts are blocked
    for i in range(7):
        assert t2[i] == free[i] and tr2[i] == (not free[i])
        assert r2[i] == pytest.approx(-0.1 + (20.0 if free[i] else 0.0))
    assert t2[7] and r2[7] == -0.1
    assert term.tolist() == [False] * 7 + [True] and trunc.all()  # the inputs are not changed
