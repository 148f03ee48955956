"""Arms from a URDF: forward kinematics and collision against pinocchio and coal (an
independent implementation), the speed bound behind certified joint-space motions, the
MotionBenchMaker problems."""

from __future__ import annotations

from importlib import resources
from pathlib import Path
from typing import Any

import coal
import numpy as np
import pinocchio as pin
import pytest

from pointplan.geometry.shapes import Box, Cylinder
from pointplan.robots.arm import ArmRobot, load_arm
from pointplan.robots.motion import check_motions, intervals
from pointplan.scenes.mbm import ARMS, SCENARIOS, load_problem, load_problems, make_arm
from pointplan.scenes.scene import Problem

ARM_NAMES = tuple(ARMS)


def _urdf(arm: str) -> tuple[str, str]:
    d = resources.files("pointplan") / "data" / "robots" / arm
    return str(d / ARMS[arm][0]), str(d)


def _pinocchio(arm: str, problem: Problem | None = None, robot: ArmRobot | None = None) -> tuple[Any, Any]:
    """pinocchio's model and collision geometry of ``arm``; with ``problem``, its obstacles
    as coal shapes and every robot-obstacle pair plus ``robot``'s self-collision pairs."""
    urdf, folder = _urdf(arm)
    m = pin.buildModelFromUrdf(urdf)
    g = pin.buildGeomFromUrdf(m, urdf, pin.GeometryType.COLLISION, package_dirs=[folder])
    if problem is None:
        return m, g
    assert robot is not None
    n_robot = len(g.geometryObjects)
    for k, s in enumerate(problem.scene.obstacles):
        assert isinstance(s, Box | Cylinder)
        geom = coal.Box(*s.size) if isinstance(s, Box) else coal.Cylinder(s.radius, s.length)
        g.addGeometryObject(pin.GeometryObject(f"obstacle{k}", 0, 0, pin.SE3(s.rotation, s.center), geom))
        for i in range(n_robot):
            g.addCollisionPair(pin.CollisionPair(i, n_robot + k))
    for a, b in robot.model.self_pairs:
        g.addCollisionPair(pin.CollisionPair(int(a), int(b)))
    return m, g


@pytest.mark.parametrize("arm", ARM_NAMES)
def test_forward_kinematics_matches_pinocchio(arm: str) -> None:
    """Every sphere centre at 10,000 random configurations, against pinocchio's placements."""
    robot = make_arm(arm)
    m, g = _pinocchio(arm)
    d, gd = m.createData(), pin.GeometryData(g)
    q = np.random.default_rng(0).uniform(robot.lower, robot.upper, (10_000, robot.config_dim))
    ours = robot.sphere_centers(q)
    ref = np.empty_like(ours)
    for k, qk in enumerate(q):
        pin.forwardKinematics(m, d, qk)
        pin.updateGeometryPlacements(m, d, g, gd)
        ref[k] = [gd.oMg[i].translation for i in range(len(g.geometryObjects))]
    assert np.abs(ours - ref).max() < 1e-12
    assert np.allclose(robot.model.sphere_radius, [o.geometry.radius for o in g.geometryObjects])


@pytest.mark.parametrize("arm", ARM_NAMES)
def test_collision_matches_pinocchio_and_coal(arm: str) -> None:
    """Collision with the obstacles of each scenario and with itself, at 10,000 random
    configurations per arm (1,430 per scenario), against pinocchio + coal on the same spheres
    and pairs; both verdicts occur often."""
    robot = make_arm(arm)
    rng = np.random.default_rng(1)
    hits = total = 0
    for k, scenario in enumerate(SCENARIOS):
        problem = load_problem(arm, scenario, 1 + 7 * k)
        m, g = _pinocchio(arm, problem, robot)
        d, gd = m.createData(), pin.GeometryData(g)
        q = rng.uniform(robot.lower, robot.upper, (1430, robot.config_dim))
        ref = np.array([pin.computeCollisions(m, d, g, gd, qk, True) for qk in q])
        ours = robot.collides(problem.scene.world, q)
        assert np.array_equal(ours, ref), (scenario, int((ours != ref).sum()))
        hits, total = hits + int(ref.sum()), total + len(q)
    assert total >= 10_000 and 0.1 < hits / total < 0.9


@pytest.mark.parametrize("arm", ARM_NAMES)
def test_self_collision_alone_matches_pinocchio(arm: str) -> None:
    """With no obstacles: the self-collision verdict alone, pair by pair."""
    robot = make_arm(arm)
    m, g = _pinocchio(arm)
    for a, b in robot.model.self_pairs:
        g.addCollisionPair(pin.CollisionPair(int(a), int(b)))
    d, gd = m.createData(), pin.GeometryData(g)
    q = np.random.default_rng(2).uniform(robot.lower, robot.upper, (3000, robot.config_dim))
    ref = np.array([pin.computeCollisions(m, d, g, gd, qk, True) for qk in q])
    c = robot.sphere_centers(q)
    ours = robot.self_collides(c, np.broadcast_to(robot.model.sphere_radius, c.shape[:-1]))
    assert np.array_equal(ours, ref)
    assert 0.05 < ref.mean() < 0.95


@pytest.mark.parametrize("arm", ARM_NAMES)
def test_speed_bound_holds_and_is_not_vacuous(arm: str) -> None:
    """Finite differences: no sphere centre moves faster than ``W |dq|``, and the bound is
    within a small factor of the true speed for some configurations."""
    robot = make_arm(arm)
    rng = np.random.default_rng(3)
    q = rng.uniform(robot.lower, robot.upper, (2000, robot.config_dim))
    dq = rng.normal(size=q.shape)
    h = 1e-6
    speed = np.linalg.norm(robot.sphere_centers(q + h * dq) - robot.sphere_centers(q - h * dq), axis=-1) / (2 * h)
    bound = np.abs(dq) @ robot.model.speed_bound.T
    assert np.all(speed <= bound * (1 + 1e-6) + 1e-9)
    moving = bound > 0  # (spheres on the base never move)
    assert np.all(speed[~moving] == 0) and np.max(speed[moving] / bound[moving]) > 0.7
    # the distance between the spheres of a self-collision pair, by the joints between them
    a, b = robot.model.self_pairs.T
    c0, c1 = robot.sphere_centers(q - h * dq), robot.sphere_centers(q + h * dq)
    rate = np.abs(np.linalg.norm(c1[:, a] - c1[:, b], axis=-1) - np.linalg.norm(c0[:, a] - c0[:, b], axis=-1)) / (2 * h)
    pair_bound = np.abs(dq) @ robot.model.pair_speed_bound.T
    assert np.all(rate <= pair_bound * (1 + 1e-6) + 1e-9)
    assert np.max(rate / np.maximum(pair_bound, 1e-12)) > 0.5
    assert np.mean(pair_bound) < 0.5 * np.mean(bound[:, a] + bound[:, b])  # far below the two spheres' own


@pytest.mark.parametrize("arm", ARM_NAMES)
@pytest.mark.parametrize("how", ["advancement", "grid"])
def test_certified_segments_are_free_when_sampled_densely(arm: str, how: str) -> None:
    """Joint-space segments certified by the arm's motion check (conservative advancement,
    or the generic grid of grown spheres) are free at 200 samples each by pinocchio + coal
    (an independent check); some segments are rejected, and advancement certifies at least
    what the grid does."""
    robot = make_arm(arm)
    problem = load_problem(arm, "bookshelf_small", 3)
    world = problem.scene.world
    rng = np.random.default_rng(4)
    a = robot.sample_free(world, rng, 150, robot.lower, robot.upper)
    b = np.clip(a + rng.normal(scale=0.4, size=a.shape), robot.lower, robot.upper)
    n = intervals(np.linalg.norm(b - a, axis=1), 0.05)
    grid = check_motions(robot, world, a, b - a, n, robot.lower, robot.upper)
    chk = robot.check_motions(world, a, b - a, n, robot.lower, robot.upper) if how == "advancement" else grid
    ok = chk.free == n
    assert 10 < ok.sum() < 145
    assert np.all(ok[grid.free == n])
    m, g = _pinocchio(arm, problem, robot)
    d, gd = m.createData(), pin.GeometryData(g)
    s = np.linspace(0, 1, 200)
    for e in np.flatnonzero(ok):
        for qk in a[e] + s[:, None] * (b[e] - a[e]):
            assert not pin.computeCollisions(m, d, g, gd, qk, True)


def test_compiled_and_numpy_collision_agree_with_grown_sizes() -> None:
    """The compiled test and the numpy one (CollisionWorld), plain and grown sizes."""
    from pointplan.robots import arm as arm_module

    robot = make_arm("panda")
    world = load_problem("panda", "bookshelf_thin", 2).scene.world
    rng = np.random.default_rng(5)
    q = rng.uniform(robot.lower, robot.upper, (3000, 7))
    grown, _ = robot.grown_parts(rng.normal(scale=0.02, size=q.shape), 0.5)
    compiled = robot.collides(world, q), robot.collides(world, q, radii=grown)
    original = arm_module._primitives_only
    try:
        arm_module._primitives_only = lambda w: False  # type: ignore[assignment]
        plain = robot.collides(world, q), robot.collides(world, q, radii=grown)
    finally:
        arm_module._primitives_only = original
    assert np.array_equal(compiled[0], plain[0]) and np.array_equal(compiled[1], plain[1])
    assert compiled[1].sum() > compiled[0].sum() > 100


def test_planners_solve_arm_problems_and_the_evaluator_agrees() -> None:
    """Bi-RRT and OMPL's RRTConnect on MotionBenchMaker problems; every path passes the
    evaluator (pinocchio + coal advancement). A straight line that pinocchio + coal find
    colliding at a dense sampling is rejected by the evaluator."""
    from pointplan.evaluation import check_path
    from pointplan.planners import make_planner

    robot = make_arm("panda")
    problems = [load_problem("panda", sc, 1) for sc in ("box", "bookshelf_small", "table_pick")]
    for name in ("birrt", "ompl:RRTConnect"):
        planner = make_planner(name, robot, time_limit=20)
        for p in problems:
            res = planner.plan(p)
            assert res.success, (name, p.tag)
            assert check_path(robot, p, res.path, tolerance=1e-6), (name, p.tag)
    p = problems[1]
    m, g = _pinocchio("panda", p, robot)
    d, gd = m.createData(), pin.GeometryData(g)
    line = p.start + np.linspace(0, 1, 400)[:, None] * (p.goal - p.start)
    assert any(pin.computeCollisions(m, d, g, gd, qk, True) for qk in line)
    verdict = check_path(robot, p, np.stack([p.start, p.goal]), tolerance=1e-6)
    assert not verdict and "touches" in verdict.reason


def test_motionbenchmaker_problems_load() -> None:
    """7 scenarios x 100 problems per arm; the values of a request come through in the
    arm's joint order."""
    robot = make_arm("panda")
    for scenario in ("box", "cage"):
        ps = load_problems("panda", scenario)
        assert len(ps) == 100 and all(len(p.scene.obstacles) > 3 for p in ps)
    p = load_problem("panda", "bookshelf_small", 1)
    assert np.allclose(p.start, [0, -0.785, 0, -2.356, 0, 1.571, 0.785])
    assert np.isclose(p.goal[0], 1.48904932702624) and np.isclose(p.goal[6], 1.06196398075046)
    assert np.array_equal(p.scene.low, robot.lower) and p.scene.dim == 3
    assert sum(isinstance(s, Cylinder) for s in p.scene.obstacles) == 3
    with pytest.raises(ValueError, match="no problem 101"):
        load_problem("panda", "box", 101)
    with pytest.raises(ValueError, match="unknown MotionBenchMaker scenario"):
        load_problem("panda", "kitchen", 1)


def test_bad_robot_files_give_one_line(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="no such URDF"):
        load_arm(tmp_path / "missing.urdf")
    bad = tmp_path / "bad.urdf"
    bad.write_text("<robot name='x'><link name='a'>")
    with pytest.raises(ValueError, match="pinocchio could not read it"):
        load_arm(bad)
    box = tmp_path / "box.urdf"
    box.write_text(
        "<robot name='b'><link name='l0'><collision><geometry><box size='1 1 1'/></geometry></collision></link>"
        "<link name='l1'/><joint name='j' type='revolute'><parent link='l0'/><child link='l1'/>"
        "<axis xyz='0 0 1'/><limit lower='-1' upper='1' effort='1' velocity='1'/></joint></robot>"
    )
    with pytest.raises(ValueError, match="link l0 has a Box collision element"):
        load_arm(box)


def test_command_line_plans_evaluates_and_draws_an_arm(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``pointplan eval`` and ``render`` on a MotionBenchMaker scenario; a robot without
    problems there gets one line."""
    import json

    from pointplan.cli import main

    out = tmp_path / "eval.json"
    assert (
        main(
            [
                "eval",
                "--env",
                "mbm-box",
                "--robot",
                "panda",
                "--planner",
                "birrt",
                "--episodes",
                "2",
                "--json",
                str(out),
                "--quiet",
            ]
        )
        == 0
    )
    res = json.loads(out.read_text())
    assert res["env"] == "mbm-box" and res["episodes"] == 2 and res["success_rate"] == 1.0
    png, gif = tmp_path / "arm.png", tmp_path / "arm.gif"
    assert (
        main(
            [
                "render",
                "--env",
                "mbm-box",
                "--robot",
                "ur5",
                "--planner",
                "ompl:RRTConnect",
                "-o",
                str(png),
                "--gif",
                str(gif),
            ]
        )
        == 0
    )
    assert png.stat().st_size > 10_000 and gif.stat().st_size > 10_000
    assert main(["eval", "--env", "mbm-box", "--robot", "sshape", "--episodes", "1"]) == 2
    assert "ship for the arms panda, ur5" in capsys.readouterr().err


def test_eval_takes_all_of_a_motionbenchmaker_scenario_by_default() -> None:
    """Without ``--episodes``, ``eval`` runs 400 problems, or all of a fixed set that has
    fewer (each MotionBenchMaker scenario has 100): asking for 400 of those is an error."""
    import argparse

    from pointplan.cli import _eval_episodes
    from pointplan.scenes.scenarios import make_scenario

    mbm = make_scenario("mbm-box", robot="ur5")
    assert mbm.count == 100 and len(mbm.problems("test", mbm.count)) == 100
    with pytest.raises(ValueError, match="has 100 problems"):
        mbm.problems("test", 400)
    default = argparse.Namespace(episodes=None)
    assert _eval_episodes(default, mbm) == 100
    assert _eval_episodes(default, make_scenario("narrow2d")) == 400
    assert _eval_episodes(argparse.Namespace(episodes=7), mbm) == 7


def test_shortcut_probes_keep_the_paths() -> None:
    """Bi-RRT probes a shortcut's stretch with a few plain configurations before its
    certified check: the same paths as without (a certified stretch has no colliding
    configuration), with fewer configurations checked where shortcuts hit obstacles."""
    from pointplan.planners.birrt import BiRRT

    robot = make_arm("panda")
    fewer = 0
    for i in (3, 4):
        p = load_problem("panda", "bookshelf_tall", i)
        a = BiRRT(robot, step=0.5, resolution=0.05).plan(p)
        b = BiRRT(robot, step=0.5, resolution=0.05, shortcut_probes=0).plan(p)
        assert a.success and np.array_equal(a.path, b.path)
        fewer += a.collision_checks < b.collision_checks
    assert fewer > 0


def _cloud_hits_brute(robot: ArmRobot, cloud: Any, q: np.ndarray, radii: np.ndarray | None = None) -> np.ndarray:
    """Does a sphere of the arm reach a cloud point (k-d tree, numpy kinematics)?"""
    from scipy.spatial import cKDTree

    c = robot.sphere_centers(q)
    r = robot.model.sphere_radius if radii is None else radii[..., : c.shape[-2]]
    reach = r + cloud.point_radius()
    # nearest points farther than any sphere can reach are not needed: the search stops
    # there (distance inf), which the comparison reads as no contact
    d, _ = cKDTree(cloud.points).query(c.reshape(-1, 3), distance_upper_bound=1.01 * float(np.max(reach)))
    return (d.reshape(c.shape[:-1]) <= reach).any(-1)  # type: ignore[no-any-return]


def test_the_compiled_arm_test_takes_a_depth_camera_cloud() -> None:
    """A MotionBenchMaker scene with its obstacles and what two simulated depth cameras see
    of it: the compiled test (primitives and the cloud's grid) is the primitives' answer or
    the k-d tree's on the cloud; segments that conservative advancement certifies keep every
    sphere off the cloud at 200 samples each (k-d tree)."""
    import dataclasses

    from pointplan.scenes.cameras import CameraModel, camera_ring, seen_by_cameras

    robot = make_arm("panda")
    p = load_problem("panda", "bookshelf_thin", 2)
    seen = seen_by_cameras(p.scene, camera_ring(p.scene, 2, distance=1.5), CameraModel(160, 120, 140.0))
    cloud = seen.obstacles[0]
    both = dataclasses.replace(p.scene, obstacles=[*p.scene.obstacles, cloud])
    rng = np.random.default_rng(6)
    q = rng.uniform(robot.lower, robot.upper, (2000, 7))
    expect = robot.collides(p.scene.world, q) | _cloud_hits_brute(robot, cloud, q)
    got = robot.collides(both.world, q)
    assert np.array_equal(got, expect)
    assert (got & ~robot.collides(p.scene.world, q)).sum() > 5  # the cloud decides some
    a = rng.uniform(robot.lower, robot.upper, (150, 7))
    b = np.clip(a + rng.normal(scale=0.4, size=a.shape), robot.lower, robot.upper)
    n = intervals(np.linalg.norm(b - a, axis=1), 0.05)
    chk = robot.check_motions(seen.world, a, b - a, n, robot.lower, robot.upper)
    ok = chk.free == n
    assert 10 < ok.sum() < 145
    s = np.linspace(0, 1, 200)
    dense = a[ok][:, None] + s[None, :, None] * (b - a)[ok][:, None]
    assert not _cloud_hits_brute(robot, cloud, dense.reshape(-1, 7)).any()
