"""Environment conformance, determinism, dynamics and rewards."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import pointplan  # noqa: F401  (registers the ids)
from pointplan.envs import PlanningEnv, PlanningVectorEnv
from pointplan.geometry.shapes import Box
from pointplan.scenes import Problem, Scene
from pointplan.scenes.scenarios import Narrow2DScenario


@pytest.mark.parametrize("observation", ["surface", "surface-normals", "interior", "image"])
def test_check_env_passes(observation: str) -> None:
    env = gym.make("pointplan/Narrow2D-v0", observation=observation)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        check_env(env.unwrapped, skip_render_check=True)
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs)


def test_settings_are_keyword_arguments() -> None:
    env = gym.make("pointplan/Narrow2D-v0", observation="surface", n_points=32, horizon=7)
    obs, _ = env.reset(seed=0)
    assert obs["observation"].shape == (32, 2)
    for _ in range(7):
        _, _, term, trunc, _ = env.step(np.zeros(2, np.float32))
    assert trunc and not term


def test_unknown_settings_fail_clearly() -> None:
    with pytest.raises(TypeError):
        gym.make("pointplan/Narrow2D-v0", obsevation="surface")
    with pytest.raises(ValueError, match="unknown observation"):
        gym.make("pointplan/Narrow2D-v0", observation="lidar")
    with pytest.raises(ValueError, match="unknown environment"):
        PlanningEnv("narrow3000")


def _rollout(seed: int, steps: int = 60) -> list[tuple]:
    env = gym.make("pointplan/Narrow2D-v0")
    obs, _ = env.reset(seed=seed)
    env.action_space.seed(seed)
    out = [tuple(np.concatenate([v.ravel() for v in obs.values()]))]
    for _ in range(steps):
        obs, r, term, trunc, info = env.step(env.action_space.sample())
        out.append((tuple(np.concatenate([v.ravel() for v in obs.values()])), r, term, trunc, info["collided"]))
        if term or trunc:
            obs, _ = env.reset()
    return out


def test_same_seed_same_episode() -> None:
    assert _rollout(3) == _rollout(3)
    assert _rollout(3) != _rollout(4)


def _open_scene() -> Scene:
    return Scene([Box(center=[0.5, 0.5], size=[0.2, 0.2])], low=np.zeros(2), high=np.ones(2))


def test_rewards_and_success() -> None:
    env = PlanningEnv("narrow2d")
    scene = _open_scene()
    # free move far from the goal: -||a|| - 0.1
    env.reset(seed=0, options={"problem": Problem(scene, [0.1, 0.1], [0.9, 0.1])})
    _, r, term, _, info = env.step(np.array([1.0, 0.0], np.float32))
    assert not info["collided"] and not term
    assert r == pytest.approx(-1.0 - 0.1)
    assert env.core.q[0] == pytest.approx([0.17, 0.1])
    # into the box: collided, -||a|| - 4, and the robot stops before the box
    env.reset(seed=0, options={"problem": Problem(scene, [0.35, 0.5], [0.1, 0.9])})
    _, r, _, _, info = env.step(np.array([1.0, 0.0], np.float32))
    assert info["collided"]
    assert r == pytest.approx(-1.0 - 4.0)
    assert env.core.q[0, 0] <= 0.4 - 0.01 + 1e-9
    # reaching the goal: +20 and the episode ends
    env.reset(seed=0, options={"problem": Problem(scene, [0.1, 0.1], [0.16, 0.1])})
    _, r, term, _, info = env.step(np.array([0.5, 0.0], np.float32))
    assert info["is_success"] and term
    assert r == pytest.approx(-0.5 - 0.1 + 20.0)


def test_the_action_cost_weighs_the_action_norm() -> None:
    env = PlanningEnv("narrow2d", action_cost=0.25)
    env.reset(seed=0, options={"problem": Problem(_open_scene(), [0.1, 0.1], [0.9, 0.1])})
    _, r, _, _, info = env.step(np.array([0.6, 0.8], np.float32))  # |a| = 1, free
    assert not info["collided"]
    assert r == pytest.approx(-0.25 * 1.0 - 0.1)


def test_tiny_moves_are_checked() -> None:
    env = PlanningEnv("narrow2d")
    scene = _open_scene()
    env.reset(seed=0, options={"problem": Problem(scene, [0.385, 0.5], [0.1, 0.9])})
    _, _, _, _, info = env.step(np.array([0.1, 0.0], np.float32))  # a 0.007 move
    assert info["collided"]
    assert info["collision_checks"] == 2  # one sub-step: its start and its end


def test_bounds_clip_a_move_without_a_collision() -> None:
    """A move that would leave the workspace is sent to its end clipped into the bounds
    (sliding along the border) and does not count as a collision; with ``bounds="stop"`` it
    ends at its last sub-step inside, on the commanded line."""
    env = PlanningEnv("narrow2d")
    env.reset(seed=0, options={"problem": Problem(_open_scene(), [0.98, 0.02], [0.1, 0.9])})
    _, reward, _, _, info = env.step(np.array([1.0, 0.5], np.float32))
    # the end (1.05, 0.055) is clipped to (1.0, 0.055)
    assert env.core.q[0] == pytest.approx([1.0, 0.055])
    assert not info["collided"] and reward == pytest.approx(-np.sqrt(1.25) - 0.1)

    env = PlanningEnv("narrow2d", bounds="stop")
    env.reset(seed=0, options={"problem": Problem(_open_scene(), [0.98, 0.02], [0.1, 0.9])})
    _, reward, _, _, info = env.step(np.array([1.0, -1.0], np.float32))
    # sub-steps of (0.007, -0.007): (0.987, 0.013), (0.994, 0.006), then (1.001, -0.001) is out
    assert env.core.q[0] == pytest.approx([0.994, 0.006])
    assert not info["collided"] and reward == pytest.approx(-np.sqrt(2) - 0.1)
    with pytest.raises(ValueError, match="bounds"):
        PlanningEnv("narrow2d", bounds="wrap")


def test_observation_is_in_robot_frame() -> None:
    env = PlanningEnv("narrow2d", observation="surface-normals", n_points=500)
    scene = _open_scene()
    obs, _ = env.reset(seed=0, options={"problem": Problem(scene, [0.1, 0.2], [0.9, 0.9])})
    pts = obs["observation"][:, :2] + np.array([0.1, 0.2])
    # every world point lies on the box boundary, and its normal points outwards
    local = pts - 0.5
    assert np.allclose(np.max(np.abs(local), axis=1), 0.1, atol=1e-6)
    normals = obs["observation"][:, 2:]
    assert np.all(np.sum(normals * local, axis=1) > 0)


def test_compute_reward_matches_env() -> None:
    env = PlanningEnv("narrow2d")
    obs, _ = env.reset(seed=5)
    rng = np.random.default_rng(0)
    for _ in range(30):
        a = rng.uniform(-1, 1, 2).astype(np.float32)
        obs, r, term, trunc, info = env.step(a)
        r2 = env.compute_reward(obs["achieved_goal"], obs["desired_goal"], info)
        assert float(r2) == pytest.approx(r, abs=1e-5)
        if term or trunc:
            obs, _ = env.reset()


def test_vector_env_matches_single_envs() -> None:
    problems = Narrow2DScenario().problems("test", 4, seed=0)
    venv = PlanningVectorEnv("narrow2d", num_envs=4)
    venv.reset(seed=0, options={"problems": problems})
    singles = [PlanningEnv("narrow2d") for _ in problems]
    for env, p in zip(singles, problems):
        env.reset(seed=0, options={"problem": p})
    rng = np.random.default_rng(1)
    for _ in range(10):
        a = rng.uniform(-1, 1, (4, 2)).astype(np.float32)
        _, r, term, trunc, info = venv.step(a)
        for i, env in enumerate(singles):
            if term[i] or trunc[i]:
                continue
            _, ri, _, _, inf = env.step(a[i])
            assert ri == pytest.approx(r[i])
            assert inf["collided"] == info["collided"][i]
            assert env.core.q[0] == pytest.approx(venv.core.q[i])


def test_vector_env_autoresets() -> None:
    venv = gym.make_vec("pointplan/Narrow2D-v0", num_envs=3, vectorization_mode="vector_entry_point", horizon=5)
    obs, _ = venv.reset(seed=0)
    assert obs["observation"].shape == (3, 64, 4)
    for _ in range(5):
        obs, r, term, trunc, info = venv.step(np.zeros((3, 2), np.float32))
    assert trunc.all()
    assert "final_obs" in info and info["_final"].all()
    assert np.all(venv.unwrapped.core.t == 0)


def test_envs_draw_from_np_random_after_seeding():
    """Gymnasium's convention: ``reset(seed=...)`` seeds ``self.np_random``, the one
    generator the env draws from; the same seed gives the same episode."""
    import gymnasium as gym

    env = gym.make("pointplan/Narrow2D-v0").unwrapped
    a, _ = env.reset(seed=7)
    state = env.np_random.bit_generator.state
    b, _ = env.reset(seed=7)
    assert env.np_random_seed == 7
    np.testing.assert_array_equal(a["desired_goal"], b["desired_goal"])
    env.np_random.bit_generator.state = state
    c, _ = env.reset()  # no seed: continues from np_random
    assert not np.array_equal(c["desired_goal"], a["desired_goal"])
    venv = PlanningVectorEnv("narrow2d", num_envs=3)
    x, _ = venv.reset(seed=4)
    y, _ = venv.reset(seed=4)
    np.testing.assert_array_equal(x["desired_goal"], y["desired_goal"])
    assert venv.np_random_seed == 4


@pytest.mark.parametrize("name", ["narrow2d", "empty2d", "boxes3d", "slot"])
def test_scenario_bounds_need_no_scene(name, monkeypatch):
    from pointplan.scenes.scenarios import make_scenario

    scenario = make_scenario(name)
    want = scenario.scene("test", 0)
    monkeypatch.setattr(type(scenario), "scene", lambda *a, **k: pytest.fail("built a scene"))
    low, high = scenario.bounds
    np.testing.assert_array_equal(low, want.low)
    np.testing.assert_array_equal(high, want.high)


def test_occupancy_image_matches_the_general_collision_check(monkeypatch: pytest.MonkeyPatch) -> None:
    """The image's compiled disc-versus-boxes grid gives, cell for cell, what the robot's
    general collision test (checked against coal in test_geometry) gives at every cell
    centre, plus the cells outside the bounds: rotated boxes, none to six per scene (so
    the stacked scenes carry padding), robots near the walls."""
    from pointplan.geometry.collision import CollisionWorld
    from pointplan.observers import image, make_observer
    from pointplan.robots import Disc2D

    kernel, calls = image._disc_boxes_grid, []
    monkeypatch.setattr(image, "_disc_boxes_grid", lambda *a: calls.append(1) or kernel(*a))
    rng = np.random.default_rng(3)
    robot = Disc2D()
    scenes = []
    for _ in range(30):
        boxes = []
        for _ in range(rng.integers(0, 7)):
            a = rng.uniform(0, np.pi)
            rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
            boxes.append(Box(rng.uniform(0, 1, 2), rng.uniform(0.02, 0.4, 2), rot))
        scenes.append(Scene(boxes, [0, 0], [1, 1]))
    q = rng.uniform(0, 1, (30, 2))
    obs = make_observer("image", robot)
    obs.bind(scenes)
    img = obs.observe(q, rng)
    assert img.shape == (30, 1, 64, 64) and set(np.unique(img)) == {0.0, 1.0}
    u = (np.arange(64) + 0.5) / 64 * 2 - 1  # cell centres, extent 1 around the robot
    x, y = q[:, 0, None] + u, q[:, 1, None] + u
    cells = np.stack(np.broadcast_arrays(x[:, :, None], y[:, None, :]), -1).reshape(30, -1, 2)
    ref = robot.collides(CollisionWorld.stack([s.world for s in scenes]), cells).reshape(30, 64, 64)
    ref |= ((x < 0) | (x > 1))[:, :, None] | ((y < 0) | (y > 1))[:, None, :]
    assert 0.2 < ref.mean() < 0.95  # both kinds of cell, plenty of each
    assert np.array_equal(img[:, 0] == 1.0, ref) and calls == [1]  # the compiled grid drew them
