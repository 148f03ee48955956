"""Encoders, hindsight relabelling, SAC, behavioural cloning and checkpoints."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

from pointplan.envs import PlanningEnv
from pointplan.envs.core import EnvConfig
from pointplan.learning.bc import BCConfig, generate_demos, resample_path, train_bc
from pointplan.learning.replay import EpisodeReplay
from pointplan.learning.sac import batch_rewards
from pointplan.learning.train import TrainConfig, train
from pointplan.models.actor_critic import NetConfig, build_networks
from pointplan.models.checkpoint import CheckpointError
from pointplan.models.encoders import EncoderConfig, PointNetEncoder
from pointplan.models.policy import Policy
from pointplan.planners.policy import PolicyPlanner
from pointplan.robots import Disc2D
from pointplan.scenes import Problem
from pointplan.scenes.scenarios import Narrow2DScenario

SMALL = NetConfig(
    EncoderConfig(width=32, layers=2), head_width=32, head_layers=2, critic_action="pooled", shared_encoder=True
)


def test_pointnet_is_permutation_invariant() -> None:
    torch.manual_seed(0)
    enc = PointNetEncoder(4, width=32, layers=3, extra=2)
    x = torch.randn(5, 64, 4)
    extra = torch.randn(5, 2)
    perm = torch.randperm(64)
    assert torch.allclose(enc(x, extra), enc(x[:, perm], extra), atol=1e-6)
    # and not invariant to changing a point
    y = x.clone()
    y[:, 0] += 5.0
    assert not torch.allclose(enc(x, extra), enc(y, extra))


def test_cnn_encoder_computes_the_plain_convolutions_and_their_gradients() -> None:
    """The CNN runs channels-last for speed; its features and its weights' gradients are
    those of the same convolutions written out with ``torch.nn.functional`` in the
    default layout, on a batch and on one image."""
    import torch.nn.functional as F

    from pointplan.models.encoders import CNNEncoder

    torch.manual_seed(0)
    enc = CNNEncoder(size=64, channels=8, extra=3)
    convs = [m for m in enc.net if isinstance(m, torch.nn.Conv2d)]
    assert all(c.weight.is_contiguous(memory_format=torch.channels_last) for c in convs)
    ref_w = [
        (c.weight.detach().contiguous().clone().requires_grad_(), c.bias.detach().clone().requires_grad_())  # type: ignore[union-attr]
        for c in convs
    ]

    def reference(img: torch.Tensor, extra: torch.Tensor) -> torch.Tensor:
        h = img
        for w, b in ref_w:
            h = F.elu(F.conv2d(h, w, b, stride=2, padding=1))
        return torch.cat([F.max_pool2d(h, 2).flatten(1), extra], -1)

    for batch in (32, 1):
        img, extra = torch.rand(batch, 1, 64, 64), torch.randn(batch, 3)
        got, want = enc(img, extra), reference(img, extra)
        assert got.shape == (batch, enc.features_dim)
        torch.testing.assert_close(got, want, atol=1e-5, rtol=1e-5)
    enc.zero_grad()
    img = torch.rand(16, 1, 64, 64)
    (enc(img) ** 2).sum().backward()
    (reference(img, torch.zeros(16, 0)) ** 2).sum().backward()
    for c, (w, b) in zip(convs, ref_w):
        torch.testing.assert_close(c.weight.grad, w.grad, atol=1e-4, rtol=1e-4)
        torch.testing.assert_close(c.bias.grad, b.grad, atol=1e-4, rtol=1e-4)


@pytest.mark.parametrize("action_on", ["points", "pooled"])
def test_networks_shapes(action_on: str) -> None:
    cfg = NetConfig(EncoderConfig(width=16, layers=2), head_width=16, head_layers=2, critic_action=action_on)
    actor, critic = build_networks((64, 4), 2, 2, cfg)
    obs, goal, act = torch.randn(7, 64, 4), torch.randn(7, 2), torch.rand(7, 2) * 2 - 1
    a, logp = actor.sample(obs, goal)
    assert a.shape == (7, 2) and logp.shape == (7,) and bool((a.abs() < 1).all())
    q1, q2 = critic(obs, goal, act)
    assert q1.shape == (7,) and q2.shape == (7,)


def _collect(env: PlanningEnv, buffer: EpisodeReplay, episodes: int, rng: np.random.Generator) -> list:
    """Random episodes into the buffer; returns (problem scene, per-step records)."""
    log = []
    for _ in range(episodes):
        obs, _ = env.reset(seed=int(rng.integers(1 << 30)))
        scene = env.core.scenes[0]
        recs: dict[str, list] = {
            k: [] for k in ("obs", "next_obs", "q", "q_next", "goal", "action", "action_norm", "collided")
        }
        done = False
        while not done:
            q = env.core.q[0].copy()
            a = rng.uniform(-1, 1, 2).astype(np.float32)
            nobs, _, term, trunc, info = env.step(a)
            for k, v in (
                ("obs", obs["observation"]),
                ("next_obs", nobs["observation"]),
                ("q", q),
                ("q_next", env.core.q[0].copy()),
                ("goal", env.core.goal[0].copy()),
                ("action", a),
                ("action_norm", info["action_norm"]),
                ("collided", info["collided"]),
            ):
                recs[k].append(v)
            obs, done = nobs, term or trunc
        buffer.add_episode(*(np.asarray(recs[k]) for k in recs))
        log.append(scene)
    return log


@pytest.mark.parametrize("action_cost", [1.0, 0.25])
def test_relabelled_reward_equals_env_reward(action_cost: float) -> None:
    rng = np.random.default_rng(0)
    env = PlanningEnv("narrow2d", action_cost=action_cost)
    robot = env.robot
    buf = EpisodeReplay(2000, (64, 4), 2, 2)
    scenes = _collect(env, buf, 6, rng)
    b = buf.sample(64, rng, her_ratio=1.0)
    assert b.relabelled.mean() > 0.9
    reward, success = batch_rewards(robot, EnvConfig(action_cost=action_cost), b)
    if action_cost != 1.0:  # the weight is applied, not ignored
        assert not np.allclose(reward, batch_rewards(robot, EnvConfig(), b)[0])
    assert success.any()  # some relabelled goals are reached by their own transition
    episode_of = buf.episode[: len(buf)]
    idx = [
        int(np.flatnonzero((buf.q[: len(buf)] == b.q[i]).all(1) & (buf.action[: len(buf)] == b.action[i]).all(1))[0])
        for i in range(len(b.q))
    ]
    for i in range(len(b.q)):
        # replay the stored transition in a fresh env aiming at the relabelled goal
        env.reset(seed=0, options={"problem": Problem(scenes[int(episode_of[idx[i]])], b.q[i], b.goal[i])})
        _, r, term, _, info = env.step(b.action[i])
        assert env.core.q[0] == pytest.approx(b.q_next[i])
        assert r == pytest.approx(reward[i], abs=1e-6)
        assert term == success[i]


@pytest.mark.slow
def test_sac_her_learns_empty_2d(tmp_path: Path) -> None:
    """SAC + HER reaches 90% on the obstacle-free square within a small budget."""
    cfg = TrainConfig(
        env="empty2d",
        num_envs=8,
        total_steps=12_000,
        warmup_steps=500,
        updates_per_step=0.5,
        eval_every=1_000,
        eval_episodes=100,
        target_success=0.95,
        net=SMALL,
    )
    res = train(cfg, tmp_path, progress=False)
    assert res.best_success >= 0.9, res.history
    assert (tmp_path / "best.pt").exists() and (tmp_path / "last.pt").exists() and (tmp_path / "metrics.csv").exists()


def test_resample_path_makes_unit_actions() -> None:
    robot = Disc2D()
    path = np.array([[0.1, 0.1], [0.5, 0.1], [0.52, 0.3]])
    r = resample_path(robot, path)
    steps = robot.log(r[:-1], r[1:]) / robot.action_scale
    assert np.all(np.abs(steps) <= 1 + 1e-9)
    assert r[0] == pytest.approx(path[0]) and r[-1] == pytest.approx(path[-1])


def test_bc_fits_demonstrations(tmp_path: Path) -> None:
    scenario = Narrow2DScenario()
    demos = generate_demos(scenario, 30, seed=0, progress=False)
    assert len(demos) > 100
    cfg = BCConfig(n_problems=30, epochs=60, net=SMALL, refresh_every=0)
    summary = train_bc(cfg, tmp_path, progress=False, demos=demos)
    # the expert actions have mean squared norm ~1.5; the fit must be far below that
    assert summary["final_loss"] < 0.25
    policy = Policy.from_checkpoint(tmp_path / "bc.pt")
    assert policy.observation == "surface-normals"


def test_checkpoint_round_trip_and_compatibility(tmp_path: Path) -> None:
    cfg = BCConfig(n_problems=5, epochs=1, net=SMALL)
    train_bc(cfg, tmp_path, progress=False)
    p1 = Policy.from_checkpoint(tmp_path / "bc.pt")
    p2 = Policy.from_checkpoint(tmp_path / "bc.pt")
    rng = np.random.default_rng(0)
    obs = rng.normal(size=(9, 64, 4)).astype(np.float32)
    q, g = rng.random((9, 2)), rng.random((9, 2))
    assert np.array_equal(p1(obs, q, g), p2(obs, q, g))
    # identical actions from a planner built on it, and clear refusals of mismatched envs
    problem = Narrow2DScenario().problem("test", 0)
    r1, r2 = PolicyPlanner(p1).plan(problem), PolicyPlanner(p2).plan(problem)
    assert np.array_equal(r1.path, r2.path)
    with pytest.raises(CheckpointError, match="observations"):
        p1.check_env(Disc2D(), "image", (1, 64, 64))
    with pytest.raises(ValueError, match="trained on"):
        PolicyPlanner(p1, env=EnvConfig(observation="surface"))
    bad = tmp_path / "junk.pt"
    bad.write_bytes(b"not a checkpoint")
    with pytest.raises(CheckpointError, match="junk.pt"):
        Policy.from_checkpoint(bad)


def test_actor_delay_keeps_the_actor_still() -> None:
    from pointplan.learning.sac import SAC, SACConfig

    rng = np.random.default_rng(0)
    env = PlanningEnv("narrow2d")
    buf = EpisodeReplay(500, (64, 4), 2, 2)
    _collect(env, buf, 2, rng)
    sac = SAC(env.robot, EnvConfig(), (64, 4), SMALL, SACConfig(batch_size=32, actor_delay=3))
    before = [p.detach().clone() for p in sac.actor.head.parameters()]
    for _ in range(3):
        sac.update(buf.sample(32, rng))
    assert all(torch.equal(a, b) for a, b in zip(before, sac.actor.head.parameters()))
    sac.update(buf.sample(32, rng))
    assert not all(torch.equal(a, b) for a, b in zip(before, sac.actor.head.parameters()))


def test_policy_average_is_an_exponential_average_of_the_actor(tmp_path: Path) -> None:
    """With ``policy_avg`` the averaged actor moves by ``rate`` towards the actor after every
    update, is what the run saves as its policy, and survives a resume."""
    from pointplan.learning.sac import SAC, SACConfig
    from pointplan.models.checkpoint import load_checkpoint

    rng = np.random.default_rng(0)
    env = PlanningEnv("narrow2d")
    buf = EpisodeReplay(500, (64, 4), 2, 2)
    _collect(env, buf, 2, rng)
    rate = 0.25
    sac = SAC(env.robot, EnvConfig(), (64, 4), SMALL, SACConfig(batch_size=32, policy_avg=rate))
    assert sac.policy_actor is sac.actor_avg
    for _ in range(3):
        before = {k: v.clone() for k, v in sac.actor_avg.state_dict().items()}
        sac.update(buf.sample(32, rng))
        now = sac.actor.state_dict()
        for k, v in sac.actor_avg.state_dict().items():
            torch.testing.assert_close(v, (1 - rate) * before[k] + rate * now[k])
    assert any(not torch.equal(v, sac.actor.state_dict()[k]) for k, v in sac.actor_avg.state_dict().items())
    # without averaging there is no second actor
    plain = SAC(env.robot, EnvConfig(), (64, 4), SMALL, SACConfig(batch_size=32))
    assert plain.actor_avg is None and plain.policy_actor is plain.actor

    cfg = TrainConfig(
        env="empty2d",
        num_envs=4,
        total_steps=400,
        warmup_steps=100,
        eval_every=400,
        eval_episodes=5,
        net=SMALL,
        sac=SACConfig(batch_size=32, policy_avg=0.01),
    )
    train(cfg, tmp_path / "a", progress=False)
    state = load_checkpoint(tmp_path / "a" / "last.pt")
    saved, avg = state["actor"], state["trainer"]["agent"]["actor_avg"]
    assert all(torch.equal(saved[k], avg[k]) for k in saved)  # the policy on disk is the average
    assert not all(torch.equal(saved[k], state["trainer"]["agent"]["actor"][k]) for k in saved)
    again = SAC(env.robot, EnvConfig(), (64, 4), SMALL, SACConfig(batch_size=32, policy_avg=0.01))
    again.load_state_dict(state["trainer"]["agent"])
    assert all(torch.equal(v, avg[k]) for k, v in again.actor_avg.state_dict().items())


def test_the_average_starts_from_the_initial_actor(tmp_path: Path) -> None:
    """``--init-actor`` with ``--policy-avg``: the averaged actor (what is validated and
    saved) starts from the given weights, not from the random ones the networks were built
    with (it once did, and validated a random policy for tens of thousands of updates)."""
    from dataclasses import replace

    from pointplan.learning.sac import SACConfig
    from pointplan.models.checkpoint import load_checkpoint

    own = replace(SMALL, shared_encoder=False)  # a shared encoder would learn from the critics' loss
    base = TrainConfig(
        env="empty2d",
        num_envs=4,
        total_steps=300,
        warmup_steps=100,
        eval_every=300,
        eval_episodes=5,
        net=own,
        sac=SACConfig(batch_size=32),
    )
    train(base, tmp_path / "a", progress=False)
    init = load_checkpoint(tmp_path / "a" / "last.pt")["actor"]
    # a second run from those weights, with a different seed (other random weights at
    # construction) and the actor frozen (its delay outlasts the run)
    cfg = replace(
        base,
        seed=1,
        init_actor=str(tmp_path / "a" / "last.pt"),
        sac=replace(base.sac, policy_avg=0.01, actor_delay=10_000),
    )
    train(cfg, tmp_path / "b", progress=False)
    agent = load_checkpoint(tmp_path / "b" / "last.pt")["trainer"]["agent"]
    for k, v in init.items():
        torch.testing.assert_close(agent["actor"][k], v)
        torch.testing.assert_close(agent["actor_avg"][k], v)


def test_training_resumes_from_last_checkpoint(tmp_path: Path) -> None:
    from dataclasses import replace

    from pointplan.learning.sac import SACConfig
    from pointplan.models.checkpoint import load_checkpoint

    cfg = TrainConfig(
        env="empty2d",
        num_envs=4,
        total_steps=400,
        warmup_steps=100,
        updates_per_step=0.25,
        eval_every=200,
        eval_episodes=5,
        net=SMALL,
        sac=SACConfig(batch_size=32),
    )
    first = train(cfg, tmp_path / "a", progress=False)
    state = load_checkpoint(tmp_path / "a" / "last.pt")
    assert state["trainer"]["steps"] == first.steps == 400
    resumed = train(replace(cfg, total_steps=600), tmp_path / "b", progress=False, resume=tmp_path / "a" / "last.pt")
    assert resumed.steps == 600
    after = load_checkpoint(tmp_path / "b" / "last.pt")["trainer"]
    assert after["agent"]["updates"] > state["trainer"]["agent"]["updates"]
    assert after["wall_time_s"] >= state["trainer"]["wall_time_s"]


def test_shipped_policy_loads_and_solves_fixed_problems() -> None:
    """The 2D-Narrow policy inside the package plans unseen test problems; its paths pass the
    evaluator's independent check and it refuses a robot it was not trained for."""
    from pointplan.evaluation.evaluate import check_path
    from pointplan.models.policy import Policy, shipped_checkpoint
    from pointplan.planners import make_planner
    from pointplan.scenes.scenarios import make_scenario

    path = shipped_checkpoint("disc2d")
    assert path.stat().st_size < 2_000_000
    policy = Policy.from_checkpoint(path)
    assert policy.observation == "surface-normals" and policy.robot.name == "disc2d"
    scenario = make_scenario("narrow2d")
    planner = make_planner("policy", scenario.robot)  # no checkpoint: the shipped one
    problems = scenario.problems("test", 12, seed=0)
    results = planner.plan_many(problems)
    solved = [bool(check_path(scenario.robot, p, r.path)) for p, r in zip(problems, results)]
    assert sum(solved) >= 10, solved
    assert all(r.success == ok for r, ok in zip(results, solved))
    with pytest.raises(ValueError, match="no policy ships"):  # none ships for the nearest-hits observation
        make_planner("policy", make_scenario("boxes3d", robot="sshape").robot, observation="local-near")


def test_metrics_csv_keeps_columns_aligned_when_new_ones_appear(tmp_path: Path) -> None:
    """A run resumed into its own folder with an option that logs more columns."""
    import csv

    from pointplan.learning.train import _Logger

    _Logger(tmp_path).log({"env_steps": 1.0, "val_success": 0.5, "critic_loss": 3.0})
    log = _Logger(tmp_path)
    log.log({"env_steps": 2.0, "val_success": 0.6, "pool_size": 7.0, "critic_loss": 2.0})
    log.log({"env_steps": 3.0, "critic_loss": 1.0, "val_success": 0.7, "pool_size": 5.0})
    with (tmp_path / "metrics.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert [r["critic_loss"] for r in rows] == ["3.0", "2.0", "1.0"]
    assert [r["val_success"] for r in rows] == ["0.5", "0.6", "0.7"]
    assert [r["pool_size"] for r in rows] == ["", "7.0", "5.0"]


def test_cloning_term_pulls_the_actor_to_the_demonstrations() -> None:
    """``bc_weight``: the actor's mean action moves towards the expert's on the
    demonstration batch (and without demonstrations no cloning loss is reported)."""
    from dataclasses import replace

    from pointplan.learning.sac import SAC, DemoBatch, SACConfig

    rng = np.random.default_rng(0)
    torch.manual_seed(0)
    env = PlanningEnv("narrow2d")
    buf = EpisodeReplay(500, (64, 4), 2, 2)
    _collect(env, buf, 2, rng)
    own = replace(SMALL, shared_encoder=False, critic_action="points")
    sac = SAC(env.robot, EnvConfig(), (64, 4), own, SACConfig(batch_size=32, bc_weight=10.0, lr=1e-3))
    demo_obs = torch.as_tensor(rng.normal(size=(32, 64, 4)), dtype=torch.float32)
    demo = DemoBatch(demo_obs, torch.as_tensor(rng.normal(size=(32, 2)), dtype=torch.float32), torch.full((32, 2), 0.7))

    def gap() -> float:
        with torch.no_grad():
            return float(((sac.actor.act(demo.obs, demo.goal) - demo.action) ** 2).sum(-1).mean())

    before = gap()
    losses = [sac.update(buf.sample(32, rng), demo)["bc_loss"] for _ in range(60)]
    assert losses[0] == pytest.approx(before, rel=1e-4)
    assert gap() < 0.2 * before
    assert "bc_loss" not in sac.update(buf.sample(32, rng))


def test_q_filter_keeps_only_steps_where_the_expert_is_rated_higher() -> None:
    from dataclasses import replace

    from pointplan.learning.sac import SAC, DemoBatch, SACConfig

    torch.manual_seed(0)
    own = replace(SMALL, shared_encoder=False, critic_action="points")
    sac = SAC(Disc2D(), EnvConfig(), (64, 4), own, SACConfig(bc_weight=1.0, bc_q_filter=True))

    class Rates(torch.nn.Module):  # Q = -|a|^2: small actions are rated higher
        def forward(self, obs, goal, action, features=None):  # type: ignore[no-untyped-def]
            q = -(action**2).sum(-1)
            return q, q

    sac.critic = Rates()
    rng = np.random.default_rng(1)
    obs = torch.as_tensor(rng.normal(size=(8, 64, 4)), dtype=torch.float32)
    goal = torch.as_tensor(rng.normal(size=(8, 2)), dtype=torch.float32)
    expert = torch.zeros(8, 2)
    expert[4:] = 0.99  # rated below any actor action of smaller norm
    with torch.no_grad():
        mean = sac.actor.act(obs, goal)
    assert float(mean.abs().max()) < 0.9  # (so the split below is the filter's)
    err = ((mean - expert) ** 2).sum(-1)
    loss = sac._cloning_loss(DemoBatch(obs, goal, expert))
    torch.testing.assert_close(loss, err[:4].mean())
    sac.cfg = replace(sac.cfg, bc_q_filter=False)
    torch.testing.assert_close(sac._cloning_loss(DemoBatch(obs, goal, expert)), err.mean())


def test_training_with_a_cloning_term(tmp_path: Path) -> None:
    """``--demos`` + ``--bc-weight`` through the training loop; a clear error without them."""
    from pointplan.learning.bc import save_demos
    from pointplan.learning.sac import SACConfig
    from pointplan.scenes.scenarios import make_scenario

    scenario = make_scenario("empty2d")
    demos = generate_demos(scenario, 10, seed=0, progress=False)
    save_demos(tmp_path / "demos.npz", scenario, demos, "train", 0)
    sac = SACConfig(batch_size=32, bc_weight=1.0)
    cfg = TrainConfig(
        env="empty2d",
        num_envs=4,
        total_steps=300,
        warmup_steps=100,
        eval_every=300,
        eval_episodes=5,
        net=SMALL,
        sac=sac,
    )
    with pytest.raises(ValueError, match="--demos"):
        train(cfg, tmp_path / "a", progress=False)
    from dataclasses import replace

    res = train(replace(cfg, demos=str(tmp_path / "demos.npz")), tmp_path / "b", progress=False)
    assert "bc_loss" in res.history[-1] and np.isfinite(res.history[-1]["bc_loss"])


def test_cloning_can_fit_the_spread_to_the_residuals(tmp_path: Path) -> None:
    """``spread_weight``: the fitted spread matches the residuals of the mean action (the
    likelihood's optimum is std = RMS residual before the tanh), and the mean's fit is
    about as good as without it."""
    from pointplan.learning.bc import _ATANH_CLIP, fit_actor, observe_demos
    from pointplan.models.actor_critic import Actor
    from pointplan.models.inputs import goal_input, obs_input

    scenario = Narrow2DScenario()
    demos = generate_demos(scenario, 30, seed=0, progress=False)
    robot, env = scenario.robot, EnvConfig(observation="surface-normals", n_points=64)
    fits = {}
    for w in (0.0, 1.0):
        torch.manual_seed(0)
        actor = Actor((64, 4), 2, 2, SMALL)
        opt = torch.optim.Adam(actor.parameters(), lr=1e-3)
        rng = np.random.default_rng(0)
        losses = fit_actor(actor, opt, demos, robot, env, 40, 256, rng, 0, False, w)
        obs = torch.as_tensor(obs_input(robot, observe_demos(demos, robot, env, np.random.default_rng(1))))
        with torch.no_grad():
            mean, log_std = actor(obs, torch.as_tensor(goal_input(robot, demos.q, demos.goal), dtype=torch.float32))
        u = torch.atanh(torch.as_tensor(demos.action).clamp(-_ATANH_CLIP, _ATANH_CLIP))
        rms = float(((u - mean) ** 2).mean().sqrt())
        fits[w] = (losses[-1], rms, float(log_std.exp().mean()))
    loss_plain, rms_plain, std_plain = fits[0.0]
    loss_spread, rms, std = fits[1.0]
    assert abs(np.log(std / rms)) < 0.25  # (measured: 0.58 against 0.64)
    assert abs(np.log(std / rms)) < 0.5 * abs(np.log(std_plain / rms_plain))  # unfitted: 0.95 against 0.63
    assert loss_spread < 1.5 * loss_plain + 0.02


def test_demonstrations_replay_as_the_environment_would_give_them() -> None:
    """``demo_episodes``: stepping a fresh environment from each demonstration's start with
    its actions gives the same configurations, no collision, the same rewards and success
    exactly at the episode's last step."""
    from pointplan.envs.core import BatchedCore, step_reward
    from pointplan.learning.bc import demo_episodes

    scenario = Narrow2DScenario()
    demos = generate_demos(scenario, 12, seed=3, progress=False)
    env = EnvConfig(observation="surface-normals", n_points=32, split="train")
    episodes = demo_episodes(demos, scenario.robot, env, np.random.default_rng(0), horizon=scenario.horizon)
    assert len(episodes) == len(demos.paths)
    core = BatchedCore(scenario, 1, env)
    rng = np.random.default_rng(1)
    row = 0
    for (_, path), (obs, next_obs, q, q_next, goal, action, norm, collided) in zip(demos.paths, episodes):
        problem = demos.problems[int(demos.scene[row])]
        row += len(path) - 1
        assert obs.shape == (len(q), 32, 4) and next_obs.shape == obs.shape
        core.reset_envs([0], rng, [problem])
        np.testing.assert_allclose(core.q[0], q[0])
        for t in range(len(q)):
            _, term, trunc, info = core.step(action[t : t + 1])
            np.testing.assert_allclose(core.q[0], q_next[t], atol=1e-9)
            assert not info["collided"][0] and not collided[t]
            if abs(float(scenario.robot.distance(q_next[t], goal[t])) - env.goal_tolerance) < 1e-9:
                break  # on the tolerance to rounding: either answer is right
            reward = step_reward(env, norm[t : t + 1], collided[t : t + 1], np.array([t == len(q) - 1]))
            np.testing.assert_allclose(reward, step_reward(env, info["action_norm"], info["collided"], term))
            assert bool(term[0]) == (t == len(q) - 1)
            if term[0] or trunc[0]:
                break
        else:
            raise AssertionError("the episode did not end")


def test_training_with_demonstrations_in_the_batches(tmp_path: Path) -> None:
    """``demo_share``: a quarter of every batch comes from the demonstrations' own buffer."""
    from dataclasses import replace

    from pointplan.learning import train as train_mod
    from pointplan.learning.bc import save_demos
    from pointplan.learning.sac import SACConfig
    from pointplan.scenes.scenarios import make_scenario

    scenario = make_scenario("empty2d")
    demos = generate_demos(scenario, 10, seed=0, progress=False)
    save_demos(tmp_path / "demos.npz", scenario, demos, "train", 0)
    cfg = TrainConfig(
        env="empty2d",
        num_envs=4,
        total_steps=300,
        warmup_steps=100,
        eval_every=300,
        eval_episodes=5,
        net=SMALL,
        sac=SACConfig(batch_size=32),
        demo_share=0.25,
    )
    with pytest.raises(ValueError, match="--demos"):
        train(cfg, tmp_path / "a", progress=False)
    cfg = replace(cfg, demos=str(tmp_path / "demos.npz"))
    seen = []
    real = train_mod._sample

    def spy(run):  # type: ignore[no-untyped-def]
        b = real(run)
        seen.append((len(b.q), run.demo_buffer.size, b.q[-8:].copy()))
        return b

    train_mod._sample = spy
    try:
        res = train(cfg, tmp_path / "b", progress=False)
    finally:
        train_mod._sample = real
    assert seen and np.isfinite(res.history[-1]["critic_loss"])
    n, demo_size, tail = seen[-1]
    assert n == 32 and 0.5 * len(demos) < demo_size <= len(demos)  # (cut where each arrives)
    # the batch's last 8 rows are demonstration steps: configurations of the expert paths
    expert = np.concatenate([p[:-1] for _, p in demos.paths])
    assert all(np.min(np.abs(expert - q).sum(-1)) < 1e-12 for q in tail)
    with pytest.raises(ValueError, match="demo_share"):
        train(replace(cfg, demo_share=1.0), tmp_path / "c", progress=False)


def test_occupancy_images_are_stored_as_bytes_without_loss(monkeypatch: pytest.MonkeyPatch) -> None:
    """Demonstration images are kept as bytes (0 or 1, as the observer draws them in
    float32), and cloning from the bytes fits exactly as cloning from float32 images."""
    from pointplan.learning import bc as bc_mod
    from pointplan.learning.bc import fit_actor, observe_demos, stored_obs_tensor
    from pointplan.models.actor_critic import Actor
    from pointplan.observers import make_observer

    scenario = Narrow2DScenario()
    demos = generate_demos(scenario, 6, seed=0, progress=False)
    robot, env = scenario.robot, EnvConfig(observation="image")
    stored = observe_demos(demos, robot, env, np.random.default_rng(0))
    assert stored.dtype == np.uint8 and stored.shape == (len(demos), 1, 64, 64)
    plain = make_observer("image", robot)
    plain.bind([demos.problems[j].scene for j in demos.scene])
    drawn = plain.observe(demos.q, np.random.default_rng(0))
    assert drawn.dtype == np.float32 and set(np.unique(drawn)) == {0.0, 1.0}
    assert np.array_equal(stored.astype(np.float32), drawn)
    t = stored_obs_tensor(robot, stored, "cpu")
    assert t.dtype == torch.uint8 and torch.equal(t[:5].float(), torch.as_tensor(drawn[:5]))

    net = replace(SMALL, encoder=EncoderConfig("cnn", 16, 2))
    real = bc_mod.observe_demos
    losses = []
    for as_float in (False, True):
        if as_float:
            monkeypatch.setattr(bc_mod, "observe_demos", lambda *a, **k: real(*a, **k).astype(np.float32))
        torch.manual_seed(0)
        actor = Actor((1, 64, 64), 2, 2, net)
        opt = torch.optim.Adam(actor.parameters(), lr=1e-3)
        losses.append(fit_actor(actor, opt, demos, robot, env, 2, 64, np.random.default_rng(0), 0, False))
    assert losses[0] == losses[1] and losses[0][-1] < losses[0][0]


def test_images_are_observed_once_for_every_epoch(monkeypatch: pytest.MonkeyPatch) -> None:
    """The occupancy image draws nothing at random (``stochastic`` False: the same images,
    the generator untouched), so cloning rasterises the demonstrations once however often
    it refreshes, and a caller's stored images give exactly the same fit; the point
    observers do draw, and do refresh."""
    from pointplan.learning import bc as bc_mod
    from pointplan.learning.bc import (
        fit_actor,
        observation_shape,
        observations_vary,
        observe_demos,
        stored_obs_tensor,
    )
    from pointplan.models.actor_critic import Actor
    from pointplan.observers import OBSERVERS, make_observer

    scenario = Narrow2DScenario()
    demos = generate_demos(scenario, 6, seed=0, progress=False)
    robot = scenario.robot
    scenes = [demos.problems[j].scene for j in demos.scene]
    for name in ("image", "surface", "surface-normals", "interior"):
        observer = make_observer(name, robot)
        observer.bind(scenes)
        rng = np.random.default_rng(0)
        before = rng.bit_generator.state
        first, again = observer.observe(demos.q, rng), observer.observe(demos.q, rng)
        untouched = rng.bit_generator.state == before
        assert OBSERVERS[name].stochastic == (not untouched) == (not np.array_equal(first, again)), name
        assert observations_vary(robot, EnvConfig(observation=name)) == OBSERVERS[name].stochastic

    real = bc_mod.observe_demos
    calls: list[str] = []

    def counted(demos, robot, env, rng, *a, **k):  # type: ignore[no-untyped-def]
        calls.append(env.observation)
        return real(demos, robot, env, rng, *a, **k)

    monkeypatch.setattr(bc_mod, "observe_demos", counted)
    net = replace(SMALL, encoder=EncoderConfig("cnn", 16, 2))
    env = EnvConfig(observation="image")
    fits = []
    for stored in (None, stored_obs_tensor(robot, observe_demos(demos, robot, env, np.random.default_rng(0)), "cpu")):
        calls.clear()
        torch.manual_seed(0)
        actor = Actor((1, 64, 64), 2, 2, net)
        opt = torch.optim.Adam(actor.parameters(), lr=1e-3)
        losses = fit_actor(actor, opt, demos, robot, env, 3, 64, np.random.default_rng(0), 1, False, stored=stored)
        assert calls == ([] if stored is not None else ["image"])  # refresh_every=1: three passes, one rasterising
        fits.append((losses, actor.state_dict()))
    assert fits[0][0] == fits[1][0]
    assert all(torch.equal(fits[0][1][k], fits[1][1][k]) for k in fits[0][1])

    calls.clear()
    points = EnvConfig(observation="surface", n_points=16)
    actor = Actor(observation_shape(robot, points), 2, 2, SMALL)
    opt = torch.optim.Adam(actor.parameters(), lr=1e-3)
    fit_actor(actor, opt, demos, robot, points, 3, 64, np.random.default_rng(0), 1, False)
    assert calls == ["surface"] * 3
    with pytest.raises(ValueError, match="do not vary"):
        fit_actor(actor, opt, demos, robot, points, 1, 64, np.random.default_rng(0), 1, False, stored=torch.zeros(1))


def test_image_training_keeps_bytes_in_its_buffers(tmp_path: Path) -> None:
    """SAC + HER on occupancy images: the replay buffer and the demonstrations' buffer hold
    bytes, the batches reach the networks as the images the observer drew."""
    from pointplan.learning import train as train_mod
    from pointplan.learning.bc import save_demos
    from pointplan.learning.sac import SACConfig
    from pointplan.scenes.scenarios import make_scenario

    scenario = make_scenario("narrow2d")
    demos = generate_demos(scenario, 6, seed=0, progress=False)
    save_demos(tmp_path / "demos.npz", scenario, demos, "train", 0)
    cfg = TrainConfig(
        env="narrow2d",
        observation="image",
        num_envs=4,
        total_steps=240,
        warmup_steps=100,
        eval_every=240,
        eval_episodes=4,
        net=replace(SMALL, encoder=EncoderConfig("cnn", 16, 2)),
        sac=SACConfig(batch_size=32, bc_weight=1.0),
        demo_share=0.25,
        demos=str(tmp_path / "demos.npz"),
    )
    seen = []
    real = train_mod._sample

    def spy(run):  # type: ignore[no-untyped-def]
        b = real(run)
        seen.append((run.buffer.obs.dtype, run.demo_buffer.obs.dtype, b.obs.dtype, np.unique(b.obs)))
        return b

    train_mod._sample = spy
    try:
        res = train(cfg, tmp_path / "run", progress=False)
    finally:
        train_mod._sample = real
    assert seen and np.isfinite(res.history[-1]["critic_loss"]) and np.isfinite(res.history[-1]["bc_loss"])
    own, demo, batch, values = seen[-1]
    assert own == demo == batch == np.uint8 and set(values) == {0, 1}


_FAULTS = """
import resource, sys
import numpy as np
from pointplan.learning.memory import keep_freed_memory
kept = keep_freed_memory()
big = np.zeros((1_000_000, 1, 64, 64), np.uint8)  # a replay buffer's images: still not in memory
rss = int(open("/proc/self/statm").read().split()[1]) * 4096
r0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(40):  # a CNN activation's size, freed and taken again
    a = np.ones(256 * 32 * 32 * 32 + 64, np.float32)
    del a
print(kept, rss, (resource.getrusage(resource.RUSAGE_SELF).ru_minflt - r0) / 40)
"""


@pytest.mark.skipif(not Path("/proc/self/statm").exists(), reason="Linux only")
def test_keeping_freed_memory_stops_the_page_faults_of_large_blocks() -> None:
    """``keep_freed_memory``: a 32 MiB block freed and taken again costs the kernel's
    page faults each time with glibc's default and almost none once freed memory is
    kept; a large zeroed array still takes no memory until it is written."""
    import os
    import subprocess
    import sys

    runs = {}
    for system in (True, False):
        env = {k: v for k, v in os.environ.items() if k != "POINTPLAN_SYSTEM_MALLOC"}
        if system:
            env["POINTPLAN_SYSTEM_MALLOC"] = "1"
        out = subprocess.run([sys.executable, "-c", _FAULTS], env=env, check=True, capture_output=True, text=True)
        kept, rss, faults = out.stdout.split()
        runs[system] = (kept == "True", int(rss), float(faults))
    (kept_sys, _, faults_sys), (kept, rss, faults) = runs[True], runs[False]
    assert not kept_sys and kept
    assert faults_sys >= 10 and faults < 0.1 * faults_sys  # (measured: 528 and 10.5 faults per block)
    assert rss < 1e9  # the 4 GB of zeros are not resident


def test_q_normalisation_makes_the_actor_update_independent_of_the_value_scale() -> None:
    """``bc_q_normalise``: with the SAC term divided by mean |Q|, critics that rate actions
    the same way at scales 1 and 100 move the actor identically (temperature ~0); without
    it they do not."""
    from dataclasses import replace

    from pointplan.learning.sac import SAC, DemoBatch, SACConfig

    own = replace(SMALL, shared_encoder=False, critic_action="points")
    rng = np.random.default_rng(2)
    env = PlanningEnv("narrow2d")
    buf = EpisodeReplay(500, (64, 4), 2, 2)
    _collect(env, buf, 2, rng)
    batch = buf.sample(32, np.random.default_rng(3))
    demo = DemoBatch(
        torch.as_tensor(rng.normal(size=(32, 64, 4)), dtype=torch.float32),
        torch.as_tensor(rng.normal(size=(32, 2)), dtype=torch.float32),
        torch.full((32, 2), 0.5),
    )

    class Scaled(torch.nn.Module):
        def __init__(self, c: float) -> None:
            super().__init__()
            self.c = c
            self.shared = None  # (no encoder shared with the actor)
            self.w = torch.nn.Parameter(torch.zeros(1))  # (an optimiser needs a parameter)

        def forward(self, obs, goal, action, features=None):  # type: ignore[no-untyped-def]
            q = -self.c * (1.0 + ((action - 0.3) ** 2).sum(-1)) + 0 * self.w
            return q, q

    def actor_after(c: float, normalise: bool) -> list[torch.Tensor]:
        torch.manual_seed(0)
        sac = SAC(
            Disc2D(),
            EnvConfig(),
            (64, 4),
            own,
            SACConfig(batch_size=32, bc_weight=1.0, bc_q_normalise=normalise, init_alpha=1e-12),
        )
        sac.critic = Scaled(c)
        sac.critic_target = Scaled(c)
        sac.critic_opt = torch.optim.Adam(sac.critic.parameters(), lr=1e-3)
        torch.manual_seed(1)
        sac.update(batch, demo)
        return [p.detach().clone() for p in sac.actor.parameters()]

    def same(a: list[torch.Tensor], b: list[torch.Tensor]) -> bool:
        return all(torch.allclose(x, y, atol=1e-6) for x, y in zip(a, b))

    assert same(actor_after(1.0, True), actor_after(100.0, True))
    assert not same(actor_after(1.0, False), actor_after(100.0, False))


def test_expert_attempts_keep_the_shortest_solution() -> None:
    """``attempts``: each demonstration is the shortest of that many Bi-RRT solutions,
    planned here again independently with the same seeds; the first attempt is the
    single-attempt run's, so no demonstration gets longer and some get shorter."""
    from pointplan.learning.bc import _ATTEMPT_SEED_STRIDE, _demo_index
    from pointplan.planners.base import path_length
    from pointplan.planners.birrt import BiRRT

    scenario = Narrow2DScenario()
    robot = scenario.robot
    one = dict(generate_demos(scenario, 12, seed=0, progress=False).paths)
    three = dict(generate_demos(scenario, 12, seed=0, progress=False, attempts=3).paths)
    assert one.keys() == three.keys() and len(one) == 12
    shorter = 0
    for i in range(12):
        k = _demo_index(0, 12, i)
        p = scenario.problem("train", k, seed=0)
        lengths = []
        for a in range(3):
            res = BiRRT(robot, max_nodes=20000, seed=k + a * _ATTEMPT_SEED_STRIDE).plan(p)
            if res.success:
                lengths.append(path_length(robot, res.path))
        assert path_length(robot, three[k]) == pytest.approx(min(lengths), abs=1e-9)
        assert path_length(robot, one[k]) == pytest.approx(lengths[0], abs=1e-9)
        shorter += path_length(robot, three[k]) < path_length(robot, one[k]) - 1e-6
    assert shorter >= 3
    with pytest.raises(ValueError, match="attempts"):
        generate_demos(scenario, 2, seed=0, progress=False, attempts=0)


def test_ctrl_c_while_planning_demonstrations_in_turn_keeps_those_that_finished(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Planned in this process (no workers), a Ctrl-C during the fourth problem keeps the
    three solved before it, exactly as an uninterrupted run solved them."""
    import pointplan.learning.bc as bc

    scenario = Narrow2DScenario()
    full = dict(generate_demos(scenario, 6, seed=0, progress=False).paths)
    plan = bc._plan_demo
    calls = []

    def stopped_at_fourth(job: bc.DemoJob) -> tuple[int, np.ndarray | None]:
        calls.append(job)
        if len(calls) == 4:
            raise KeyboardInterrupt
        return plan(job)

    monkeypatch.setattr(bc, "_plan_demo", stopped_at_fourth)
    kept = generate_demos(scenario, 6, seed=0, progress=False).paths
    assert len(kept) == 3 and len(calls) == 4
    for k, path in kept:
        np.testing.assert_array_equal(path, full[k])
    assert "keeping the 3 of 6 demonstrations" in capsys.readouterr().err


@pytest.mark.parametrize("robot_name", ["sphere3d", "sshape"])
def test_padded_robot_collides_exactly_within_the_margin(robot_name: str) -> None:
    """``Robot.padded(m)`` collides wherever the body's exact clearance (coal) is below ``m``;
    a ball grows exactly, a box by ``m`` along its axes, so near its edges and corners the
    padded box also covers clearances up to ``m * sqrt(3)``."""
    from pointplan.evaluation.clearance import Clearance
    from pointplan.robots import make_robot
    from pointplan.scenes.scenarios import make_scenario

    robot = make_robot(robot_name)
    scene = make_scenario("boxes3d", robot=robot_name).problem("val", 3).scene
    clearance = Clearance(robot, scene.obstacles)
    pad = robot.padded(0.03)
    assert robot.parts.box_halfs.shape == pad.parts.box_halfs.shape and pad.parts is not robot.parts
    rng = np.random.default_rng(0)
    q = robot.sample_uniform(rng, 400, scene.low, scene.high)
    d = np.array([clearance(x) for x in q])
    hit = pad.collides(scene.world, q)
    band = np.abs(d - 0.03) > 1e-6  # away from the boundary, where round-off could go either way
    assert hit[band & (d < 0.03)].all()
    exact = robot_name == "sphere3d"
    assert (~hit[band & (d > (0.03 if exact else 0.03 * np.sqrt(3)))]).all()
    if exact:
        assert (hit[band] == (d[band] < 0.03)).all()
    assert ((d > 0) & (d < 0.03)).sum() >= 5  # some configurations are free but within the margin
    assert (robot.collides(scene.world, q) == (d < 0)).all()  # the robot itself is unchanged
    with pytest.raises(ValueError, match="margin"):
        robot.padded(-0.01)


def test_expert_margin_keeps_the_demonstrations_away_from_obstacles() -> None:
    """With ``margin`` the expert's paths keep that clearance (checked with coal along the
    densified path) wherever the padded body found a path; elsewhere they fall back to the
    body itself, so no problem is lost."""
    from pointplan.evaluation.clearance import Clearance
    from pointplan.evaluation.evaluate import densify
    from pointplan.scenes.scenarios import make_scenario

    scenario = make_scenario("boxes3d", robot="sphere3d")
    robot = scenario.robot
    plain = dict(generate_demos(scenario, 8, seed=0, progress=False).paths)
    padded = dict(generate_demos(scenario, 8, seed=0, progress=False, margin=0.04).paths)
    assert plain.keys() == padded.keys()
    kept, fell_back = 0, 0
    for k, path in padded.items():
        p = scenario.problem("train", k, seed=0)
        c = Clearance(robot, p.scene.obstacles)
        d = min(c(x) for x in densify(robot, path, 0.005))
        assert d > 0
        if min(c(p.start), c(p.goal)) > 0.04:  # the padded body could start and end there
            kept += d > 0.04 - 1e-3
        else:
            fell_back += 1
        np.testing.assert_allclose(path[0], p.start, atol=1e-9)
    assert kept >= 3
    dmin_plain = [
        min(Clearance(robot, scenario.problem("train", k, seed=0).scene.obstacles)(x) for x in densify(robot, q, 0.005))
        for k, q in plain.items()
    ]
    assert min(dmin_plain) < 0.04  # without the margin some path grazes closer than that


def test_bc_uses_every_demonstration_of_an_existing_file_and_says_so(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``--demos FILE`` that exists is used whole, whatever ``--problems`` says, and the run
    says so when the two differ; the checkpoint records the steps it learnt from."""
    from pointplan.learning.bc import load_demos, save_demos

    scenario = Narrow2DScenario()
    demos = generate_demos(scenario, 5, seed=0, progress=False)
    path = tmp_path / "demos.npz"
    save_demos(path, scenario, demos, "train", 0)
    n, steps = len(load_demos(path, scenario).problems), len(load_demos(path, scenario))
    assert n >= 3
    out = train_bc(BCConfig(n_problems=2, epochs=1, net=SMALL, demos_file=str(path)), tmp_path / "run", progress=True)
    assert out["demo_steps"] == steps and out["demo_problems"] == n
    assert f"all its {n} demonstrations are used (--problems 2" in capsys.readouterr().out
    train_bc(BCConfig(n_problems=n, epochs=1, net=SMALL, demos_file=str(path)), tmp_path / "run2", progress=True)
    assert "demonstrations are used" not in capsys.readouterr().out


def test_bc_init_actor_fine_tunes_the_given_actor(tmp_path: Path) -> None:
    """``init_actor`` (``pointplan bc --init-actor``) starts cloning from that actor: with a
    vanishing step size the result acts as it does, where a fresh start (another seed)
    does not; a network that does not fit is refused with a clear error."""
    demos = generate_demos(Narrow2DScenario(), 5, seed=0, progress=False)
    train_bc(BCConfig(n_problems=5, epochs=2, net=SMALL, refresh_every=0), tmp_path / "a", progress=False, demos=demos)
    start = str(tmp_path / "a" / "bc.pt")
    tuned = BCConfig(n_problems=5, epochs=1, lr=1e-12, net=SMALL, seed=1, refresh_every=0, init_actor=start)
    train_bc(tuned, tmp_path / "b", progress=False, demos=demos)
    train_bc(replace(tuned, init_actor=None), tmp_path / "c", progress=False, demos=demos)
    rng = np.random.default_rng(0)
    obs = rng.normal(size=(9, 64, 4)).astype(np.float32)
    q, g = rng.random((9, 2)), rng.random((9, 2))
    a, b, c = (Policy.from_checkpoint(tmp_path / k / "bc.pt")(obs, q, g) for k in "abc")
    np.testing.assert_allclose(b, a, atol=1e-6)
    assert not np.allclose(c, a, atol=1e-3)
    wider = replace(tuned, net=replace(SMALL, head_width=SMALL.head_width * 2))
    with pytest.raises(ValueError, match="--init-actor .* its network is not this run's"):
        train_bc(wider, tmp_path / "d", progress=False, demos=demos)
