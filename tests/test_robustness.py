"""Robustness pieces: the 2D-Narrow variants, perturbed observers, the K-draw policy."""

from __future__ import annotations

import numpy as np
import pytest

from pointplan.geometry.shapes import Box
from pointplan.observers import SurfaceNormals
from pointplan.observers.perturb import PerturbedPoints, farthest_point_subset, perturbation, visible_from
from pointplan.robots import Disc2D
from pointplan.scenes import narrow2d
from pointplan.scenes.narrow2d_variants import VARIANTS, variant_workspace
from pointplan.scenes.scenarios import make_scenario
from pointplan.scenes.scene import Scene

NAMES = ["narrow2d-ends", "narrow2d-many", "narrow2d-narrow", "narrow2d-manynarrow"]


def _gaps(scene: Scene) -> list[tuple[int, float, float]]:
    """(wall axis, start, end) of each gap: the holes between a wall's boxes."""
    out = []
    for axis in (0, 1):  # the horizontal wall's boxes share their y centre, the vertical's their x
        centres = [round(float(b.center[1 - axis]), 9) for b in scene.obstacles]
        wall = max(set(centres), key=centres.count)
        along = [b for b, c in zip(scene.obstacles, centres) if c == wall]
        ivs = sorted((b.center[axis] - b.half[axis], b.center[axis] + b.half[axis]) for b in along)
        out += [(axis, a[1], b[0]) for a, b in zip(ivs, ivs[1:]) if b[0] - a[1] > 1e-9]
    return out


@pytest.mark.parametrize("name", NAMES)
def test_variants_connected_reproducible_and_disjoint(name: str) -> None:
    sc = make_scenario(name)
    assert sc.name == name
    radius = float(sc.robot.parts.sphere_radii.max())
    for i in range(5):
        scene = sc.scene("test", i)
        assert narrow2d.free_space_labels(scene, radius)[1] == 1
        again = sc.scene("test", i)
        assert all(
            np.allclose(a.center, b.center) and np.allclose(a.size, b.size)
            for a, b in zip(scene.obstacles, again.obstacles)
        )
        # not the 2D-Narrow workspace of the same index, nor the train workspace
        for other in (narrow2d.workspace("test", i), sc.scene("train", i)):
            assert len(other.obstacles) != len(scene.obstacles) or not all(
                np.allclose(a.center, b.center) for a, b in zip(scene.obstacles, other.obstacles)
            )
    p = sc.problem("test", 0)
    assert not sc.robot.collides(p.scene.world, p.start[None]).any()


def test_variant_gaps() -> None:
    for variant, cfg in VARIANTS.items():
        counts = []
        for i in range(20):
            scene = variant_workspace(variant, "val", i)
            gaps = _gaps(scene)
            counts.append(len(gaps))
            for _, a, b in gaps:
                assert b - a == pytest.approx(cfg.gap, abs=1e-9)
                assert a >= 0.025 - 1e-9 and b <= 1 - 0.025 + 1e-9
        assert min(counts) >= cfg.n_gaps[0] - (cfg.n_gaps[0] > 3), variant  # extra gaps need room
        assert max(counts) <= cfg.n_gaps[1]
        if variant == "many":
            assert max(counts) >= 4


def test_eval_cli_runs_variant(capsys: pytest.CaptureFixture[str]) -> None:
    from pointplan.cli import main

    assert main(["eval", "--env", "narrow2d-ends", "--planner", "straight", "--episodes", "3", "--quiet"]) == 0


def test_visible_from() -> None:
    scene = Scene([Box(center=[0.5, 0.5], size=[0.2, 0.2])], low=np.zeros(2), high=np.ones(2))
    pts = np.array([[0.4, 0.5], [0.6, 0.5], [0.5, 0.4], [0.5, 0.6], [0.1, 0.9], [0.9, 0.9], [0.4, 0.4]])
    vis = visible_from(scene, pts, np.array([0.0, 0.0]))
    # the faces turned to the viewpoint, their corner and free points are seen; the far faces
    # and the point behind the box are not
    assert vis.tolist() == [True, False, True, False, True, False, True]


def test_perturbed_observer_off_is_plain() -> None:
    robot = Disc2D()
    scene = narrow2d.workspace("test", 3)
    plain, wrapped = SurfaceNormals(robot), PerturbedPoints(SurfaceNormals(robot))
    plain.bind([scene])
    wrapped.bind([scene])
    q = np.array([0.2, 0.3])
    u = np.random.default_rng(0).random(plain.draws_one())
    assert np.array_equal(plain.observe_one(q, u=u), wrapped.observe_one(q, u=u))


def test_perturbed_observer_noise_drop_view() -> None:
    robot = Disc2D()
    scene = narrow2d.workspace("test", 3)
    plain = SurfaceNormals(robot)
    plain.bind([scene])
    total = len(plain.points_one()[0])
    dropped = PerturbedPoints(SurfaceNormals(robot), drop=0.5, seed=1)
    dropped.bind([scene])
    assert len(dropped.points_one()[0]) == total - round(0.5 * total)
    noisy = PerturbedPoints(SurfaceNormals(robot), noise=0.01, seed=1)
    noisy.bind([scene])
    q = np.array([0.2, 0.3])
    u = np.random.default_rng(0).random(plain.draws_one())
    diff = noisy.observe_one(q, u=u) - plain.observe_one(q, u=u)
    assert 0.005 < diff[:, :2].std() < 0.02 and np.all(diff[:, 2:] == 0)
    start = PerturbedPoints(SurfaceNormals(robot), viewpoint="start")
    start.bind([scene])
    start.observe_one(q, u=u)
    seen = start.points_one()[0]
    assert 0 < len(seen) < total
    assert visible_from(scene, seen, q).all()


def test_farthest_point_subset_spreads() -> None:
    pts = np.random.default_rng(0).random((300, 2))
    idx = farthest_point_subset(pts, 64, 5)
    assert idx[0] == 5 and len(set(idx.tolist())) == 64
    d = np.linalg.norm(pts[idx][:, None] - pts[idx][None], axis=-1) + np.eye(64)
    rand = np.random.default_rng(1).choice(300, 64, replace=False)
    dr = np.linalg.norm(pts[rand][:, None] - pts[rand][None], axis=-1) + np.eye(64)
    assert d.min() > dr.min()
    assert farthest_point_subset(pts[:10], 64, 0).shape == (64,)


def test_policy_planner_options() -> None:
    from pointplan.planners import make_planner

    sc = make_scenario("narrow2d")
    probs = sc.problems("test", 4)
    base = [make_planner("policy", sc.robot).plan(p) for p in probs]
    k1 = [make_planner("policy", sc.robot, draws=1).plan(p) for p in probs]
    assert all(np.array_equal(a.path, b.path) for a, b in zip(base, k1))
    for kw in (
        {"draws": 3},
        {"observer_wrapper": perturbation(noise=0.002, drop=0.1, subset="fps")},
        {"observer_wrapper": perturbation(viewpoint=(0.5, -0.5))},
    ):
        planner = make_planner("policy", sc.robot, **kw)
        for p in probs:
            r = planner.plan(p)
            assert r.path.shape[1] == 2 and np.allclose(r.path[0], p.start)
        assert len(planner.plan_many(probs[:2])) == 2
