"""Collision classification (paper section 4.2): exact labels, balanced data, a classifier
that learns."""

from __future__ import annotations

import numpy as np
import pytest

from pointplan.cli import main
from pointplan.geometry.shapes import Box
from pointplan.learning.collision import (
    CollisionConfig,
    draw_samples,
    end_configuration,
    make_data,
    point_clearance,
    segment_clearance,
    train_classifier,
)
from pointplan.scenes.scenarios import make_scenario
from pointplan.scenes.scene import Scene

RADIUS = 0.01


@pytest.fixture(scope="module")
def scenario():  # type: ignore[no-untyped-def]
    return make_scenario("narrow2d")


def test_end_labels_agree_with_the_collision_kernel(scenario) -> None:  # type: ignore[no-untyped-def]
    """The exact clearance says "collides" exactly where the package's sphere-vs-box kernel
    (a separate implementation) does, near the boundary included."""
    rng = np.random.default_rng(0)
    for i in range(3):
        scene = scenario.scene("test", i)
        p = rng.uniform(0, 1, (4000, 2))
        c = point_clearance(scene, p, RADIUS)
        hit = scenario.robot.collides(scene.world, p)
        # skip the few points within rounding of the boundary
        sure = np.abs(c) > 1e-9
        assert np.array_equal(c[sure] <= 0, hit[sure])
        assert (np.abs(c) < 0.02).sum() > 100  # the boundary band was exercised


def test_clearance_of_a_rotated_box_against_brute_force() -> None:
    """Signed distances to a rotated box match a dense sampling of its boundary."""
    rot = np.array([[np.cos(0.5), -np.sin(0.5)], [np.sin(0.5), np.cos(0.5)]])
    box = Box(center=np.array([0.5, 0.5]), size=np.array([0.3, 0.1]), rotation=rot)
    scene = Scene([box], np.zeros(2), np.ones(2))
    t = np.linspace(0, 1, 4001)[:, None]
    h = box.half
    edges = [np.array([-h[0], -h[1]]) + t * [2 * h[0], 0], np.array([-h[0], h[1]]) + t * [2 * h[0], 0]]
    edges += [np.array([-h[0], -h[1]]) + t * [0, 2 * h[1]], np.array([h[0], -h[1]]) + t * [0, 2 * h[1]]]
    boundary = np.concatenate(edges) @ rot.T + box.center
    p = np.random.default_rng(1).uniform(0.2, 0.8, (300, 2))
    d = np.min(np.linalg.norm(p[:, None] - boundary[None], axis=-1), axis=1)
    inside = np.all(np.abs((p - box.center) @ rot) <= h, axis=1)
    expect = np.where(inside, -d, d) - RADIUS
    assert np.allclose(point_clearance(scene, p, RADIUS), expect, atol=2e-4)


def test_swept_clearance_against_dense_points_on_the_move(scenario) -> None:  # type: ignore[no-untyped-def]
    """The segment clearance is the least point clearance along the move (sampled densely:
    never below the exact value, and above it by at most half a sample's spacing)."""
    rng = np.random.default_rng(2)
    scene = scenario.scene("train", 3)
    a = rng.uniform(0, 1, (500, 2))
    b = a + rng.uniform(-0.1, 0.1, (500, 2))
    exact = segment_clearance(scene, a, b, RADIUS)
    s = np.linspace(0, 1, 1001)
    pts = a[:, None] + s[None, :, None] * (b - a)[:, None]
    dense = point_clearance(scene, pts.reshape(-1, 2), RADIUS).reshape(500, -1)
    inside = dense < -RADIUS  # the centre inside a box: the segment meets it
    sampled = np.where(inside.any(axis=1), -RADIUS, np.maximum(dense, -RADIUS).min(axis=1))
    spacing = np.linalg.norm(b - a, axis=1) / 1000
    assert np.all(sampled >= exact - 1e-9)
    assert np.all(sampled <= exact + spacing / 2 + 1e-9)
    assert np.any(exact <= 0) and np.any(exact > 0)


def test_samples_are_balanced_free_starts_with_half_near_the_boundary(scenario) -> None:  # type: ignore[no-untyped-def]
    s = draw_samples(scenario, "train", 5, 40, np.random.default_rng(3), band=0.02)
    assert len(s) == 200
    assert s.labels("end").mean() == 0.5
    assert s.near("end", 0.02).mean() == 0.5
    for j, scene in enumerate(s.scenes):
        m = s.scene == j
        assert np.all(point_clearance(scene, s.q[m], RADIUS) > 0)  # starts are free
        # labels recomputed from the stored start and action
        e = end_configuration(scenario.robot, s.q[m], s.action[m].astype(np.float64), scene.low, scene.high)
        assert np.allclose(e, s.end[m])
        assert np.array_equal(scenario.robot.collides(scene.world, e), s.labels("end")[m])
    assert np.all(np.abs(s.action) <= 1.0)
    # stratifying by the swept label balances that one instead
    sw = draw_samples(scenario, "train", 2, 40, np.random.default_rng(3), label="swept")
    assert sw.labels("swept").mean() == 0.5


def test_uniform_samples_keep_the_natural_collision_share(scenario) -> None:  # type: ignore[no-untyped-def]
    """``sampling="uniform"`` keeps samples as drawn: its collision share matches an
    independent Monte Carlo estimate over the same workspaces (free starts, uniform
    actions, labels from the package's collision kernel), far from the strata's 0.5."""
    s = draw_samples(scenario, "train", 20, 200, np.random.default_rng(4), sampling="uniform")
    assert len(s) == 4000
    rng = np.random.default_rng(5)
    hits, n = 0, 0
    for scene in s.scenes:
        q = rng.uniform(scene.low, scene.high, (4000, 2))
        q = q[~scenario.robot.collides(scene.world, q)][:400]
        e = end_configuration(scenario.robot, q, rng.uniform(-1, 1, q.shape), scene.low, scene.high)
        hits += int(scenario.robot.collides(scene.world, e).sum())
        n += len(q)
    share, expect = s.labels("end").mean(), hits / n
    assert abs(share - expect) < 4 * np.sqrt(expect * (1 - expect) / 4000) + 0.005, (share, expect)
    assert share < 0.35 and s.near("end", 0.02).mean() < 0.4
    with pytest.raises(ValueError, match="sampling"):
        CollisionConfig(sampling="grid")


@pytest.mark.usefixtures("one_torch_thread")
def test_patience_stops_and_the_test_reports_both_samplings(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """With patience 1 and a step size too large to learn, training stops two epochs after
    its best; the test carries the stratified accuracy and ``accuracy_uniform``."""
    cfg = CollisionConfig(
        n_points=16,
        train_scenes=4,
        val_scenes=2,
        test_scenes=2,
        per_scene=16,
        epochs=30,
        patience=1,
        width=8,
        lr=5.0,
        lr_end=1.0,
    )
    res = train_classifier(cfg, tmp_path, progress=False)
    assert not res.interrupted
    assert len(res.history) == res.best_epoch + 1 < 30
    assert res.test["n"] == 32 and res.test["uniform"]["n"] == 32
    assert 0.0 <= res.test["accuracy_uniform"] <= 1.0


def test_splits_use_disjoint_workspaces() -> None:
    data = make_data(CollisionConfig(train_scenes=3, val_scenes=2, test_scenes=2, per_scene=8))
    walls = {
        k: {tuple(np.round(np.concatenate([o.center for o in sc.obstacles]), 9)) for sc in v.scenes}
        for k, v in data.items()
    }
    assert (
        not (walls["train"] & walls["test"])
        and not (walls["train"] & walls["val"])
        and not (walls["val"] & walls["test"])
    )


@pytest.mark.usefixtures("one_torch_thread")
def test_a_small_classifier_beats_chance(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """A few seconds of training: clearly above chance (0.5 on balanced classes; 0.6 on 320
    test samples is 3.5 standard deviations above it), and well above it away from the
    boundary, the easy half."""
    cfg = CollisionConfig(
        observation="surface-normals",
        n_points=64,
        train_scenes=40,
        val_scenes=5,
        test_scenes=10,
        per_scene=32,
        epochs=15,
        width=32,
        lr=3e-3,
    )
    res = train_classifier(cfg, tmp_path, progress=False)
    assert res.test["n"] == 320 and res.test["n_near"] == 160
    assert res.test["accuracy"] > 0.6, res.test
    assert res.test["accuracy_far"] > 0.75, res.test
    assert (tmp_path / "surface-normals.pt").exists() and (tmp_path / "surface-normals_test.npz").exists()


def test_cli_rejects_an_unknown_observation(capsys) -> None:  # type: ignore[no-untyped-def]
    assert main(["collision-classify", "--observation", "global", "--quiet"]) == 2
    assert "--observation" in capsys.readouterr().err
