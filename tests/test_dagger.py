"""Demonstrations in worker processes, their files, and DAgger rounds."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from pointplan.config import from_dict
from pointplan.learning.bc import BCConfig, generate_demos, load_demos, save_demos
from pointplan.learning.dagger import DaggerConfig, train_dagger
from pointplan.models.actor_critic import NetConfig
from pointplan.models.checkpoint import load_checkpoint
from pointplan.models.encoders import EncoderConfig
from pointplan.models.policy import Policy
from pointplan.scenes.scenarios import Narrow2DScenario, make_scenario

pytestmark = pytest.mark.slow  # behavioural cloning and DAgger train networks

SMALL = NetConfig(
    EncoderConfig(width=16, layers=2), head_width=16, head_layers=2, critic_action="pooled", shared_encoder=True
)


def test_parallel_demos_equal_serial_ones_and_survive_a_file(tmp_path: Path) -> None:
    scenario = make_scenario("boxes3d", robot="sphere3d")
    serial = generate_demos(scenario, 6, seed=3, progress=False)
    parallel = generate_demos(scenario, 6, seed=3, progress=False, workers=2)
    assert len(serial) > 6
    for a, b in ((serial.q, parallel.q), (serial.action, parallel.action), (serial.goal, parallel.goal)):
        assert np.array_equal(a, b)
    save_demos(tmp_path / "d.npz", scenario, serial, "train", 3)
    back = load_demos(tmp_path / "d.npz", scenario)
    assert (
        np.array_equal(back.q, serial.q)
        and np.array_equal(back.action, serial.action)
        and np.array_equal(back.scene, serial.scene)
    )
    # every demonstration step is one action of the robot, along a Bi-RRT path to the goal
    assert np.all(np.abs(serial.action) <= 1 + 1e-9)
    for (_, path), p in zip(serial.paths, serial.problems):
        assert np.allclose(path[0], p.start) and np.allclose(path[-1], p.goal)


def test_demos_of_another_robot_are_refused(tmp_path: Path) -> None:
    scenario = make_scenario("boxes3d", robot="sphere3d")
    save_demos(tmp_path / "d.npz", scenario, generate_demos(scenario, 2, progress=False), "train", 0)
    try:
        load_demos(tmp_path / "d.npz", make_scenario("boxes3d", robot="sshape"))
    except ValueError as e:
        assert "sphere3d" in str(e)
    else:
        raise AssertionError("loaded demonstrations of another robot")


def test_dagger_rounds_add_expert_labels_and_resume(tmp_path: Path) -> None:
    bc = BCConfig(n_problems=20, epochs=2, net=SMALL, refresh_every=0)
    cfg = DaggerConfig(bc, rounds=2, rollouts=12, labels_per_failure=2, epochs_per_round=1, eval_episodes=10)
    out = train_dagger(cfg, tmp_path, progress=False)
    rows = (tmp_path / "metrics.csv").read_text().splitlines()
    assert len(rows) == 3 and rows[0].startswith("round,")
    first = load_demos(tmp_path / "demos.npz", Narrow2DScenario())
    assert len(first) == out["demo_steps"]
    labels = [int(r.split(",")[3]) for r in rows[1:]]
    assert sum(labels) > 0  # an untrained policy fails, and Bi-RRT labels its states
    # a label starts where the policy was, not at the problem's start
    starts = {tuple(p.start) for p in first.problems}
    assert any(tuple(path[0]) not in starts for _, path in first.paths)
    state = load_checkpoint(tmp_path / "last.pt")
    assert state["dagger"]["round"] == 2
    resumed = replace(from_dict(DaggerConfig, state["dagger_config"]), rounds=3)
    train_dagger(resumed, tmp_path, progress=False, resume=tmp_path / "last.pt")
    rows = (tmp_path / "metrics.csv").read_text().splitlines()
    assert [r.split(",")[0] for r in rows[1:]] == ["1", "2", "3"]
    assert len(load_demos(tmp_path / "demos.npz", Narrow2DScenario())) >= len(first)
    assert Policy.from_checkpoint(tmp_path / "best.pt").observation == "surface-normals"


@pytest.mark.parametrize("expert", ["slot-threading", "slot-threading-copies"])
def test_dagger_with_the_slot_threading_expert_plans_its_own_demos_and_labels(tmp_path: Path, expert: str) -> None:
    """``expert="slot-threading"`` (and with the template's symmetric copies): the first
    demonstrations and the labels of failed rollouts come from the slot threading expert;
    each label starts where the policy was and is a certified path to the goal."""
    from pointplan.evaluation.evaluate import check_path
    from pointplan.scenes.scenarios import make_scenario
    from pointplan.scenes.scene import Problem

    bc = BCConfig(
        env="slotmoving",
        robot="sshape",
        observation="global",
        n_points=32,
        n_problems=3,
        epochs=1,
        net=SMALL,
        refresh_every=0,
    )
    cfg = DaggerConfig(
        bc, rounds=1, rollouts=2, labels_per_failure=2, epochs_per_round=1, eval_episodes=2, expert=expert
    )
    train_dagger(cfg, tmp_path, progress=False)
    sc = make_scenario("slotmoving", robot="sshape")
    demos = load_demos(tmp_path / "demos.npz", sc)
    rows = (tmp_path / "metrics.csv").read_text().splitlines()
    labels = int(rows[1].split(",")[3])
    assert labels > 0  # a policy cloned from a few demonstrations fails Slot
    assert len(demos.paths) >= 1 + labels
    from_starts = 0
    for k, path in demos.paths:
        p = sc.problem("train", k, seed=0)
        from_starts += bool(np.allclose(path[0], p.start))
        assert check_path(sc.robot, Problem(p.scene, path[0], p.goal), path)
    assert from_starts < len(demos.paths)  # the labels start elsewhere


def test_dagger_with_the_roadmap_expert(tmp_path: Path) -> None:
    """``expert="roadmap"``: the first demonstrations and the labels come from the roadmap
    expert; every path is certified, the labels start where the policy was, and a state's
    label is the one the roadmap of its workspace gives (``label_states``)."""
    from pointplan.evaluation.evaluate import check_path
    from pointplan.learning.roadmap import label_states
    from pointplan.scenes.scene import Problem

    bc = BCConfig(
        env="boxes3d",
        robot="sshape",
        observation="global",
        n_points=32,
        n_problems=2,
        epochs=1,
        net=SMALL,
        refresh_every=0,
    )
    cfg = DaggerConfig(
        bc,
        rounds=1,
        rollouts=3,
        labels_per_failure=2,
        epochs_per_round=1,
        eval_episodes=2,
        expert="roadmap",
        roadmap_nodes=300,
        roadmap_k=8,
    )
    train_dagger(cfg, tmp_path, progress=False)
    sc = make_scenario("boxes3d", robot="sshape")
    demos = load_demos(tmp_path / "demos.npz", sc)
    rows = (tmp_path / "metrics.csv").read_text().splitlines()
    labels = int(rows[1].split(",")[3])
    assert labels > 0  # a policy cloned from two problems fails 3D-Boxes
    first = [(k, path) for k, path in demos.paths if k < 2_000_000]
    assert len(first) > 2  # the starts' paths and paths from roadmap nodes
    relabelled = 0
    for k, path in demos.paths:
        p = sc.problem("train", k, seed=0)
        assert check_path(sc.robot, Problem(p.scene, path[0], p.goal), path)
        if k >= 2_000_000:
            again = label_states(sc, "train", 0, k, [path[0]], 300, 8, rng_seed=0)
            relabelled += len(again) == 1 and np.array_equal(again[0], path)
    assert relabelled == labels
