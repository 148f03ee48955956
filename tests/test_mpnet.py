"""MPNet: the networks, lazy state contraction, the planners and a tiny training run."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from pointplan.evaluation import check_path
from pointplan.models.checkpoint import CheckpointError
from pointplan.models.mpnet import MPNet, MPNetModel, MPNetNetConfig, encoder_input, shipped_mpnet
from pointplan.planners import make_planner, path_length
from pointplan.planners.birrt import BiRRT
from pointplan.planners.mpnet import EdgeChecker, MPNetPlanner, contract, scene_points
from pointplan.scenes.scenarios import Narrow2DScenario

SCENARIO = Narrow2DScenario()
ROBOT = SCENARIO.robot


def _random_mpnet(seed: int = 0, zero_output: bool = False) -> MPNet:
    torch.manual_seed(seed)
    model = MPNetModel(2, 4, MPNetNetConfig(encoder_width=16, width=32, layers=2))
    if zero_output:  # proposes staying where it is: a useless network
        last = model.pnet[-1]
        assert isinstance(last, torch.nn.Linear)
        torch.nn.init.zeros_(last.weight)
        torch.nn.init.zeros_(last.bias)
    return MPNet(model.eval(), ROBOT, np.array([0.5, 0.5]), 0.07, {})


def _straight_line_fails(index: int) -> bool:
    p = SCENARIO.problem("test", index, seed=0)
    return not EdgeChecker(ROBOT, p.scene).free(p.start, p.goal)


@pytest.fixture(scope="module")
def shipped() -> MPNet:
    return MPNet.from_checkpoint(shipped_mpnet("disc2d"))


def test_numpy_network_matches_torch() -> None:
    net = _random_mpnet(3)
    fast = net.numpy()
    p = SCENARIO.problem("test", 0)
    pts, nrm = scene_points(ROBOT, p.scene)
    x = encoder_input(pts, nrm, net.center, net.step)
    with torch.inference_mode():
        z = net.model.encode(torch.as_tensor(x)[None])[0]
        q_in = torch.as_tensor(((p.start - 0.5) / 0.07).astype(np.float32))[None]
        g_in = torch.as_tensor(((p.goal - 0.5) / 0.07).astype(np.float32))[None]
        out = net.model(z[None], q_in, g_in)[0].numpy()
    z_np = fast.encode(x)
    np.testing.assert_allclose(z_np, z.numpy(), atol=1e-5)
    np.testing.assert_allclose(fast.displacement(z_np, p.start, p.goal, None), out, atol=1e-5)
    # dropout on: random draws that differ, from a seeded generator (reproducible)
    a = fast.displacement(z_np, p.start, p.goal, np.random.default_rng(1))
    b = fast.displacement(z_np, p.start, p.goal, np.random.default_rng(1))
    np.testing.assert_array_equal(a, b)


def test_shipped_checkpoint_loads_through_make_planner() -> None:
    for name, hybrid in (("mpnet-nr", False), ("mpnet-hr", True)):
        planner = make_planner(name, ROBOT)
        assert isinstance(planner, MPNetPlanner)
        assert planner.name == name and planner.hybrid is hybrid
    assert shipped_mpnet("disc2d").stat().st_size < 500_000


def test_a_policy_checkpoint_is_not_an_mpnet() -> None:
    from pointplan.models.policy import shipped_checkpoint

    with pytest.raises(CheckpointError, match="not an MPNet"):
        make_planner("mpnet-nr", ROBOT, checkpoint=str(shipped_checkpoint("disc2d")))


@pytest.mark.parametrize("hybrid", [False, True])
def test_paths_start_at_start_end_at_goal_and_are_certified(shipped: MPNet, hybrid: bool) -> None:
    planner = MPNetPlanner(shipped, ROBOT, hybrid=hybrid, seed=0)
    solved = 0
    for i in range(8):
        p = SCENARIO.problem("test", i, seed=0)
        res = planner.plan(p)
        if not res.success:
            assert not hybrid
            assert res.path.shape == (0, 2)
            continue
        solved += 1
        assert np.array_equal(res.path[0], p.start) and np.array_equal(res.path[-1], p.goal)
        assert check_path(ROBOT, p, res.path)
        assert res.nodes == res.info["neural_nodes"] + res.info["birrt_nodes"]
    assert solved >= (8 if hybrid else 4)


def test_same_seed_same_plans(shipped: MPNet) -> None:
    problems = [SCENARIO.problem("test", i) for i in (1, 2)]
    runs = []
    for _ in range(2):
        planner = MPNetPlanner(shipped, ROBOT, seed=5)
        runs.append([planner.plan(p) for p in problems])
    for a, b in zip(*runs):
        assert a.success == b.success and a.nodes == b.nodes and a.collision_checks == b.collision_checks
        np.testing.assert_array_equal(a.path, b.path)


@pytest.mark.parametrize("index", [0, 4, 9])
def test_contraction_never_lengthens_and_keeps_free_paths_free(index: int) -> None:
    p = SCENARIO.problem("test", index, seed=0)
    raw = BiRRT(ROBOT, seed=index).plan(p).raw_path  # before shortcutting: many vertices
    assert raw is not None and check_path(ROBOT, p, raw)
    edges = EdgeChecker(ROBOT, p.scene)
    out = contract(ROBOT, raw, edges)
    assert path_length(ROBOT, out) <= path_length(ROBOT, raw) + 1e-12
    assert len(out) <= len(raw)
    assert np.array_equal(out[0], p.start) and np.array_equal(out[-1], p.goal)
    assert check_path(ROBOT, p, out)
    assert edges.all_free(out).all()


def test_contraction_of_a_colliding_path_never_lengthens_it() -> None:
    p = SCENARIO.problem("test", 0, seed=0)
    rng = np.random.default_rng(0)
    for _ in range(5):
        path = np.concatenate([p.start[None], rng.uniform(0, 1, (8, 2)), p.goal[None]])
        edges = EdgeChecker(ROBOT, p.scene)
        before = edges.all_free(path)
        out = contract(ROBOT, path, edges)
        assert path_length(ROBOT, out) <= path_length(ROBOT, path) + 1e-12
        # every kept edge is an original edge or a free shortcut
        original = {(a.tobytes(), b.tobytes()) for a, b in zip(path[:-1], path[1:])}
        for a, b in zip(out[:-1], out[1:]):
            assert (a.tobytes(), b.tobytes()) in original or edges.free(a, b)
        assert edges.all_free(out).sum() >= 0 and len(before) == len(path) - 1


def test_useless_network_nr_fails_cleanly_hr_succeeds() -> None:
    index = next(i for i in range(20) if _straight_line_fails(i))
    p = SCENARIO.problem("test", index, seed=0)
    useless = _random_mpnet(zero_output=True)
    nr = MPNetPlanner(useless, ROBOT, seed=0, replan_iters=3).plan(p)
    assert not nr.success and nr.path.shape == (0, 2)
    assert nr.info["stage"] == "failed" and nr.collision_checks > 0
    hr = MPNetPlanner(useless, ROBOT, hybrid=True, seed=0, replan_iters=3).plan(p)
    assert hr.success and hr.info["stage"] == "birrt" and hr.info["birrt_nodes"] > 0
    assert np.array_equal(hr.path[0], p.start) and np.array_equal(hr.path[-1], p.goal)
    assert check_path(ROBOT, p, hr.path)


def test_waypoints_of_a_resampled_path() -> None:
    from pointplan.learning.mpnet import cut_path, path_vertices

    corners = np.array([[0.1, 0.1], [0.5, 0.1], [0.5, 0.6], [0.9, 0.9]])
    dense = cut_path(corners, 0.03)
    assert np.all(np.linalg.norm(np.diff(dense, axis=0), axis=1) <= 0.03 + 1e-12)
    np.testing.assert_allclose(path_vertices(dense), corners, atol=1e-12)
    assert np.array_equal(cut_path(corners, 0.0), corners)


def test_training_smoke(tmp_path: object) -> None:
    from pathlib import Path

    from pointplan.learning.mpnet import MPNetTrainConfig, train_mpnet

    run = Path(str(tmp_path))
    cfg = MPNetTrainConfig(
        n_problems=12,
        val_demo_problems=4,
        val_problems=3,
        test_problems=2,
        epochs=2,
        eval_every=1,
        net=MPNetNetConfig(encoder_width=8, width=16, layers=2),
    )
    res = train_mpnet(cfg, run, progress=False)
    assert (run / "best.pt").is_file() and (run / "metrics.csv").is_file() and (run / "summary.json").is_file()
    assert set(res.test) == {"mpnet-nr", "mpnet-hr"} and res.test["mpnet-hr"]["episodes"] == 2
    planner = make_planner("mpnet-hr", ROBOT, checkpoint=str(run / "best.pt"))
    assert isinstance(planner, MPNetPlanner) and planner.net.layers[0][0].shape == (8 + 4, 16)
    # validation demonstrations must come from the validation split
    from dataclasses import replace

    from pointplan.learning.bc import generate_demos, save_demos

    train_file = run / "train_demos.npz"
    save_demos(train_file, SCENARIO, generate_demos(SCENARIO, 2, progress=False), "train", 0)
    with pytest.raises(ValueError, match="not val"):
        train_mpnet(
            replace(cfg, demos_file=str(train_file), val_demos_file=str(train_file)), run / "again", progress=False
        )


def test_cli_eval_runs_the_shipped_mpnet(tmp_path: object, capsys: pytest.CaptureFixture[str]) -> None:
    import json
    from pathlib import Path

    from pointplan.cli import main

    out = Path(str(tmp_path)) / "m.json"
    assert main(["eval", "--planner", "mpnet-nr,mpnet-hr", "--episodes", "2", "--quiet", "--json", str(out)]) == 0
    metrics = json.loads(out.read_text())["planners"]
    assert metrics["mpnet-hr"]["success_rate"] == 1.0 and metrics["mpnet-nr"]["planner_claims_disagree"] == 0


def test_cli_one_checkpoint_for_policy_and_mpnet_is_an_error(capsys: pytest.CaptureFixture[str]) -> None:
    from pointplan.cli import main

    assert main(["eval", "--planner", "mpnet-nr,policy", "--checkpoint", "x.pt", "--episodes", "1", "--quiet"]) == 2
    assert "not both" in capsys.readouterr().err


# ---------------------------------------------------------------------------- 3D: the sphere
@pytest.fixture(scope="module")
def boxes3d() -> object:
    from pointplan.scenes.scenarios import make_scenario

    return make_scenario("boxes3d", robot="sphere3d")


def test_3d_scene_points_are_a_fixed_area_weighted_set_with_normals(boxes3d: object) -> None:
    from pointplan.scenes.scenarios import Scenario

    assert isinstance(boxes3d, Scenario)
    scene = boxes3d.problems("test", 1)[0].scene
    pts, nrm = scene_points(boxes3d.robot, scene, "global", 64)
    assert pts.shape[1] == 3 and nrm.shape == pts.shape and 0 < len(pts) <= 64
    np.testing.assert_allclose(np.linalg.norm(nrm, axis=1), 1.0, atol=1e-6)
    again, _ = scene_points(boxes3d.robot, scene, "global", 64)
    np.testing.assert_array_equal(pts, again)  # one point set (and encoding) per workspace


@pytest.mark.parametrize("hybrid", [False, True])
def test_3d_shipped_mpnet_found_by_robot_and_paths_certified(boxes3d: object, hybrid: bool) -> None:
    from pointplan.scenes.scenarios import Scenario

    assert isinstance(boxes3d, Scenario)
    robot = boxes3d.robot
    assert shipped_mpnet("sphere3d").stat().st_size < 500_000
    planner = make_planner("mpnet-hr" if hybrid else "mpnet-nr", robot, seed=0)
    assert isinstance(planner, MPNetPlanner)
    assert planner.mpnet.robot.name == "sphere3d" and planner.mpnet.observation == "global" and planner.net.dim == 3
    solved = 0
    for p in boxes3d.problems("test", 4, seed=0):
        res = planner.plan(p)
        if not res.success:
            assert not hybrid and res.path.shape == (0, 3)
            continue
        solved += 1
        assert np.array_equal(res.path[0], p.start) and np.array_equal(res.path[-1], p.goal)
        assert check_path(robot, p, res.path)
    assert solved >= (4 if hybrid else 2)


def test_robot_without_an_mpnet_is_a_clear_error() -> None:
    from pointplan.robots import make_robot

    sshape = make_robot("sshape")
    with pytest.raises(ValueError, match="no MPNet ships for robot 'sshape'"):
        make_planner("mpnet-nr", sshape)
    with pytest.raises(ValueError, match="translating robots only"):
        MPNetPlanner(MPNet.from_checkpoint(shipped_mpnet("sphere3d")), sshape)


def test_cli_mpnet_train_refuses_the_sshape(capsys: pytest.CaptureFixture[str]) -> None:
    from pointplan.cli import main

    assert main(["mpnet-train", "--env", "boxes3d", "--robot", "sshape", "--quiet"]) == 2
    assert "translating robots only" in capsys.readouterr().err


def test_3d_training_smoke(tmp_path: object) -> None:
    from pathlib import Path

    from pointplan.learning.mpnet import MPNetTrainConfig, train_mpnet

    run = Path(str(tmp_path))
    cfg = MPNetTrainConfig(
        env="boxes3d",
        robot="sphere3d",
        n_points=32,
        n_problems=4,
        val_demo_problems=2,
        val_problems=2,
        test_problems=0,
        epochs=1,
        net=MPNetNetConfig(encoder_width=8, width=16, layers=2),
    )
    train_mpnet(cfg, run, progress=False)
    net = MPNet.from_checkpoint(run / "best.pt")
    assert net.robot.name == "sphere3d" and net.observation == "global" and net.n_points == 32
    assert net.numpy().layers[0][0].shape == (8 + 6, 16)
