"""Paths read as linear translation + slerp rotation (how OMPL, MoveIt and most
controllers follow them): certified by conservative advancement, made free by splitting."""

from __future__ import annotations

import numpy as np
import pytest

from pointplan.evaluation import check_path
from pointplan.evaluation.interpolation import body_radius, check_linear_slerp, for_linear_slerp, slerp_pose
from pointplan.geometry import lie
from pointplan.planners import make_planner
from pointplan.robots import make_robot
from pointplan.scenes.scenarios import make_scenario


def test_slerp_pose_ends_and_rate() -> None:
    rng = np.random.default_rng(0)
    robot = make_robot("sshape")
    for _ in range(20):
        q0, q1 = (
            np.concatenate([rng.uniform(0, 1, 3), lie.matrix_to_quat(lie.random_rotations(rng, 1))[0]])
            for _ in range(2)
        )
        r0, r1 = robot.rotations(q0), robot.rotations(q1)
        np.testing.assert_allclose(robot.rotations(slerp_pose(q0, q1, 0.0)), r0, atol=1e-12)
        np.testing.assert_allclose(robot.rotations(slerp_pose(q0, q1, 1.0)), r1, atol=1e-9)
        np.testing.assert_allclose(slerp_pose(q0, q1, 0.3)[:3], 0.7 * q0[:3] + 0.3 * q1[:3])
        # constant rate about one axis: the rotation from the start grows linearly
        total = np.linalg.norm(lie.so3_log(r0.T @ r1))
        for s in (0.25, 0.5, 0.9):
            got = np.linalg.norm(lie.so3_log(r0.T @ robot.rotations(slerp_pose(q0, q1, s))))
            assert got == pytest.approx(s * total, abs=1e-7)


def test_body_radius_bounds_every_corner() -> None:
    robot = make_robot("sshape")
    rho = body_radius(robot)
    p = robot.parts
    corners = p.box_centers + np.einsum("pij,pj->pi", p.box_rotations, p.box_halfs)
    assert np.all(np.linalg.norm(corners, axis=-1) <= rho + 1e-12) and rho > 0.1


def test_exported_paths_are_free_under_both_readings() -> None:
    """Bi-RRT's first S-shape path of these problems cuts a box when read as linear + slerp;
    after ``for_linear_slerp`` every path is free under both readings, and a dense sampling
    of the linear + slerp motion checked by the batched collision code (not the certificate
    under test) touches nothing."""
    sc = make_scenario("boxes3d", robot="sshape")
    robot = sc.robot
    planner = make_planner("birrt", robot)
    failed_before = 0
    for p in sc.problems("test", 3, seed=2026):
        res = planner.plan(p)
        assert res.success and check_path(robot, p, res.path)
        failed_before += not check_linear_slerp(robot, p, res.path)[0]
        path = for_linear_slerp(robot, p, res.path)
        assert check_linear_slerp(robot, p, path)[0] and check_path(robot, p, path)
        assert len(path) >= len(res.path)
        dense = np.stack([slerp_pose(a, b, s) for a, b in zip(path[:-1], path[1:]) for s in np.linspace(0, 1, 200)])
        assert not robot.collides(p.scene.world, dense).any()
    assert failed_before >= 1


def test_translating_robots_are_unchanged() -> None:
    sc = make_scenario("boxes3d", robot="sphere3d")
    p = sc.problem("test", 0, seed=0)
    path = np.stack([p.start, p.goal])
    assert for_linear_slerp(sc.robot, p, path) is not None
    np.testing.assert_array_equal(for_linear_slerp(sc.robot, p, path), path)
    with pytest.raises(ValueError, match="only translates"):
        check_linear_slerp(sc.robot, p, path)


def test_plan_writes_linear_slerp_waypoints_on_request(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """``pointplan plan --waypoints linear-slerp``: the JSON names its interpolation and its
    layout, some paths gain waypoints, and every written path, sampled densely as linear +
    slerp and checked by the batched collision code, touches nothing; the default output
    says its edges are screw motions."""
    import json

    from pointplan.cli import main

    common = ["plan", "--env", "boxes3d", "--robot", "sshape", "--planner", "birrt", "--episodes", "8", "--quiet"]
    assert main([*common, "--waypoints", "linear-slerp", "--json", str(tmp_path / "ls.json")]) == 0
    assert main([*common, "--json", str(tmp_path / "screw.json")]) == 0
    ls, screw = (json.loads((tmp_path / f).read_text()) for f in ("ls.json", "screw.json"))
    assert ls["interpolation"].startswith("linear + slerp") and screw["interpolation"].startswith("screw")
    assert "qx, qy, qz, qw" in ls["configuration"]
    robot = make_robot("sshape")
    problems = make_scenario("boxes3d", robot="sshape").problems("test", 8, seed=0)
    grew = 0
    for p, a, b in zip(problems, ls["problems"], screw["problems"], strict=True):
        assert a["success"] and b["success"]
        path = np.asarray(a["path"])
        grew += len(path) > len(b["path"])
        dense = np.stack([slerp_pose(x, y, s) for x, y in zip(path[:-1], path[1:]) for s in np.linspace(0, 1, 200)])
        assert not robot.collides(p.scene.world, dense).any()
    assert grew >= 1
