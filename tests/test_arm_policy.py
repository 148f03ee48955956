"""The arm's training ground (random workcells) and the learned arm policy's pipeline:
problems checked by pinocchio + coal, state features against pinocchio's joint placements,
cloning on the cells and the policy and hybrid planners on a MotionBenchMaker problem."""

from __future__ import annotations

from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
import pytest

from pointplan.models.inputs import goal_dim, goal_input
from pointplan.robots.arm import ARMS
from pointplan.scenes.armcells import KINDS, ArmCellsScenario, cell_of
from pointplan.scenes.mbm import load_problem, make_arm
from pointplan.scenes.registry import make_scenario


def _urdf(arm: str) -> tuple[str, str]:
    d = resources.files("pointplan") / "data" / "robots" / arm
    return str(d / ARMS[arm][0]), str(d)


def _collides(arm: str, obstacles: list[Any], q: np.ndarray, robot: Any) -> bool:
    """pinocchio + coal (test_arm's set-up): does the arm at ``q`` touch an obstacle or itself?"""
    from pointplan.scenes.mbm import JointSpaceScene
    from pointplan.scenes.scene import Problem
    from test_arm import _pinocchio

    problem = Problem(JointSpaceScene(obstacles, robot.lower, robot.upper), q, q)
    m, g = _pinocchio(arm, problem, robot)
    d, gd = m.createData(), pin.GeometryData(g)
    return bool(pin.computeCollisions(m, d, g, gd, q, True))


def test_arm_cells_problems_are_free_placed_and_reproducible() -> None:
    """Every kind appears; starts and goals are free by pinocchio + coal; one end's hand is
    in the cell's target region; the same index gives the same problem, splits differ."""
    sc = make_scenario("armcells", robot="panda")
    assert isinstance(sc, ArmCellsScenario)
    kinds, inside_ends = set(), 0
    for i in range(9):
        p = sc.problem("train", i)
        cell = cell_of(p.scene)
        assert cell is not None
        kinds.add(cell.kind)
        for q in (p.start, p.goal):
            assert np.all(q >= sc.robot.lower) and np.all(q <= sc.robot.upper)
            assert not _collides("panda", p.scene.obstacles, q, sc.robot)
        hands = sc.hand(np.stack([p.start, p.goal]))
        inside_ends += any(r.contains(hands).any() for r in cell.inside)
    assert kinds == set(KINDS)
    assert inside_ends >= 8  # a problem falls back to uniform ends only when the sampler fails
    again = make_scenario("armcells", robot="panda").problem("train", 3)
    assert np.array_equal(again.start, sc.problem("train", 3).start)
    assert not np.array_equal(sc.problem("val", 3).start, sc.problem("train", 3).start)
    with pytest.raises(ValueError, match="unknown arm"):
        make_scenario("armcells", robot="sphere3d")
    from pointplan.robots import make_robot

    with pytest.raises(ValueError, match="for arms"):
        make_scenario("armcells", robot=make_robot("sphere3d"))


def test_arm_state_features_match_pinocchio_placements() -> None:
    """The arm's policy input: the goal in steps, the joints scaled to [-1, 1] and the joint
    origins at ``q`` and at the goal, which equal pinocchio's joint placements."""
    robot = make_arm("panda")
    urdf, _ = _urdf("panda")
    m = pin.buildModelFromUrdf(urdf)
    d = m.createData()
    rng = np.random.default_rng(1)
    q = rng.uniform(robot.lower, robot.upper, (20, 7))
    goal = rng.uniform(robot.lower, robot.upper, (20, 7))
    x = goal_input(robot, q, goal)
    assert x.shape == (20, goal_dim(robot)) == (20, 7 + 7 + 42)
    assert np.allclose(x[:, :7], (goal - q) / robot.action_scale, atol=1e-5)
    assert np.allclose(x[:, 7:14], 2 * (q - robot.lower) / (robot.upper - robot.lower) - 1, atol=1e-6)
    scale = robot.action_scale[0]
    for k in range(20):
        for col, conf in ((14, q[k]), (35, goal[k])):
            full = np.zeros(m.nq)
            full[:7] = conf
            pin.forwardKinematics(m, d, full)
            ref = np.array([d.oMi[m.getJointId(name)].translation for name in robot.model.joint_names])
            assert np.allclose(x[k, col : col + 21].reshape(7, 3) * scale, ref, atol=1e-5)


def test_cloned_arm_policy_plans_and_the_hybrid_certifies(tmp_path: Path) -> None:
    """A policy cloned from a few arm-cell demonstrations plans for the Panda through the
    policy planner; the hybrid solves a MotionBenchMaker problem and its path passes the
    evaluator (pinocchio + coal, independent of the planners)."""
    from pointplan.evaluation import check_path
    from pointplan.learning.bc import BCConfig, generate_demos, train_bc
    from pointplan.planners import make_planner

    cfg = BCConfig(env="armcells", robot="panda", observation="global", n_points=64, n_problems=2, epochs=1)
    demos = generate_demos(make_scenario("armcells", robot="panda"), 2, max_nodes=3000, progress=False)
    assert len(demos) > 0
    summary = train_bc(cfg, run_dir=tmp_path, progress=False, demos=demos)
    ckpt = Path(summary["checkpoint"])
    robot = make_arm("panda")
    p = load_problem("panda", "box", 1)
    res = make_planner("policy", robot, checkpoint=str(ckpt), horizon=30).plan(p)
    assert len(res.path) >= 2 and np.array_equal(res.path[0], p.start)
    if res.success:
        assert check_path(robot, p, res.path, tolerance=1e-6)
    for name in ("hybrid", "hybrid-ompl"):  # (the arm's joint step reaches OMPL's fallback as its range)
        hyb = make_planner(name, robot, checkpoint=str(ckpt), horizon=30, time_limit=20.0).plan(p)
        assert hyb.success, name
        assert check_path(robot, p, hyb.path, tolerance=1e-6), name
