"""Learned sampling (Ichter et al. 2018): Bi-RRT's sampler hook, the CVAE, the shipped
network, the planner's paths and the training command."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
import torch

from pointplan.evaluation import check_path
from pointplan.models.checkpoint import CheckpointError
from pointplan.models.cvae import ConditionalVAE, pad_cloud, scene_cloud
from pointplan.planners import BiRRT, make_planner
from pointplan.planners.learned_sampling import LearnedSampler, LearnedSamplingPlanner, shipped_sampler
from pointplan.robots import Disc2D
from pointplan.scenes.scenarios import Narrow2DScenario
from pointplan.scenes.scene import Problem


@pytest.fixture(scope="module")
def problems(narrow2d_test_problems: Callable[[int], list[Problem]]) -> list:
    return narrow2d_test_problems(6)


def test_lambda_zero_is_plain_birrt(problems: list) -> None:
    """With lam = 0 the planner takes nothing from the network or the generator beyond
    Bi-RRT's own draws: the same paths, trees, nodes and checks for the same seed."""
    robot = Disc2D()
    plain = BiRRT(robot, seed=3)
    learned = make_planner("learned-sampling", robot, lam=0.0, seed=3)
    for p in problems:
        a, b = plain.plan(p), learned.plan(p)
        assert a.success and b.success
        np.testing.assert_array_equal(a.path, b.path)
        assert (a.nodes, a.collision_checks) == (b.nodes, b.collision_checks)
        for (na, pa), (nb, pb) in zip(a.trees, b.trees):
            np.testing.assert_array_equal(na, nb)
            np.testing.assert_array_equal(pa, pb)
        assert b.info["learned_samples"] == 0


def test_birrt_sampler_hook(problems: list) -> None:
    """A sampler is asked once per query, with the problem; its draws are the extend
    targets (the first extension of the start tree heads for the first one)."""
    robot = Disc2D()
    asked: list[object] = []
    sizes: list[int] = []
    target = np.array([0.5, 0.02])

    def sampler(problem: object) -> object:
        asked.append(problem)

        def draw(rng: np.random.Generator, n: int) -> np.ndarray:
            sizes.append(n)
            out = rng.uniform(0.0, 1.0, (n, 2))
            out[0] = target  # the first target of each block
            return out

        return draw

    p = problems[0]
    res = BiRRT(robot, seed=0, sampler=sampler, max_nodes=2000).plan(p)  # type: ignore[arg-type]
    assert asked == [p] and sizes and all(n == 256 for n in sizes)
    first = res.trees[0][0][1]
    d = target - p.start
    np.testing.assert_allclose(first, p.start + 0.07 * d / np.linalg.norm(d), atol=1e-9)


def test_cvae_fits_a_narrow_distribution() -> None:
    """Fitted on two narrow Gaussians (one per condition), the decoder's samples from the
    prior land where the training configurations were: the right mean, the wide axis's
    spread, the narrow axis no wider than the data, and nothing near the other cluster."""
    torch.manual_seed(0)
    rng = np.random.default_rng(0)
    means = {-1.0: np.array([-0.5, 0.4]), 1.0: np.array([0.5, -0.2])}
    sd = np.array([0.1, 0.02])
    net = ConditionalVAE(2, 1, latent=2, width=64, layers=2)
    opt = torch.optim.Adam(net.parameters(), lr=3e-3)
    for _ in range(700):
        c = rng.choice([-1.0, 1.0], 256)
        x = np.stack([means[k] for k in c]) + rng.standard_normal((256, 2)) * sd
        loss, _, _ = net.loss(torch.tensor(x, dtype=torch.float32), torch.tensor(c[:, None], dtype=torch.float32), 1e-3)
        opt.zero_grad()
        loss.backward()
        opt.step()
    for k, m in means.items():
        s = net.sample(torch.tensor([[k]]), torch.randn(4000, 2)).numpy()
        assert np.all(np.abs(s.mean(0) - m) < 0.03), (k, s.mean(0))
        assert 0.7 * sd[0] < s[:, 0].std() < 1.3 * sd[0]
        assert s[:, 1].std() < 1.3 * sd[1]
        inside = np.mean(np.all(np.abs(s - m) < 3 * sd + 0.02, axis=1))
        assert inside > 0.97
        other = means[-k]
        assert np.min(np.linalg.norm(s - other, axis=1)) > 0.3


def test_shipped_network_loads_through_make_planner(problems: list) -> None:
    robot = Disc2D()
    for name, lam in (("lsample-0.5", 0.5), ("lsample-0.9", 0.9)):
        planner = make_planner(name, robot, seed=0)
        assert isinstance(planner, LearnedSamplingPlanner)
        assert planner.lam == lam and planner.name == name
        assert planner.learned.checkpoint == str(shipped_sampler("disc2d"))
    assert make_planner("learned-sampling", robot, lam=0.7).lam == 0.7
    with pytest.raises(ValueError):
        make_planner("learned-sampling", robot, lam=1.5)
    assert shipped_sampler().stat().st_size < 500_000


def test_shipped_samples_concentrate_on_solutions(problems: list) -> None:
    """The shipped network's samples lie near Bi-RRT's solutions far more often than
    uniform samples do (a trained network, not a uniform one)."""
    robot = Disc2D()
    sampler = LearnedSampler(shipped_sampler(), robot, lam=1.0)
    near_learned, near_uniform = [], []
    rng = np.random.default_rng(0)
    for p in problems:
        path = BiRRT(robot, seed=0).plan(p).path
        dense = np.concatenate([np.linspace(a, b, 20) for a, b in zip(path[:-1], path[1:])])
        s = sampler(p)(rng, 500)
        assert np.all((s >= 0.0) & (s <= 1.0))
        u = rng.uniform(0.0, 1.0, (500, 2))
        for xs, out in ((s, near_learned), (u, near_uniform)):
            d = np.min(np.linalg.norm(xs[:, None] - dense[None], axis=-1), axis=1)
            out.append(np.mean(d < 0.1))
    assert np.mean(near_learned) > 2.0 * np.mean(near_uniform)


def test_paths_are_certified(problems: list) -> None:
    robot = Disc2D()
    for name in ("lsample-0.5", "lsample-0.9"):
        planner = make_planner(name, robot, seed=0)
        for p in problems:
            res = planner.plan(p)
            assert res.success
            assert res.info["learned_samples"] > 0
            check = check_path(robot, p, res.path)
            assert check, check


def test_refuses_other_checkpoints(tmp_path: object) -> None:
    from pointplan.models.policy import shipped_checkpoint

    with pytest.raises(CheckpointError, match="not a learned-sampling network"):
        LearnedSampler(shipped_checkpoint("disc2d"), Disc2D(), 0.5)


def test_pad_cloud_keeps_the_max_pool(problems: list) -> None:
    cloud = scene_cloud(problems[0].scene)
    padded = pad_cloud(cloud, len(cloud) + 37)
    assert padded.shape == (len(cloud) + 37, 4)
    assert {tuple(r) for r in padded} == {tuple(r) for r in cloud}


def test_lsample_train_command(tmp_path: object) -> None:
    """The training command end to end on a tiny budget; its checkpoint plans."""
    from pathlib import Path

    from pointplan.cli import main

    run = Path(str(tmp_path)) / "run"
    code = main(
        [
            "lsample-train",
            "--problems",
            "6",
            "--val-problems",
            "3",
            "--plan-problems",
            "2",
            "--epochs",
            "2",
            "--eval-every",
            "1",
            "--run-dir",
            str(run),
            "--quiet",
        ]
    )
    assert code == 0
    assert (run / "best.pt").is_file() and (run / "last.pt").is_file() and (run / "metrics.csv").is_file()
    robot = Disc2D()
    planner = make_planner("lsample-0.9", robot, checkpoint=str(run / "best.pt"))
    p = Narrow2DScenario().problem("test", 0)
    res = planner.plan(p)
    assert res.success and check_path(robot, p, res.path)


def test_eval_cli_runs_lsample() -> None:
    from pointplan.cli import main

    assert (
        main(["eval", "--env", "narrow2d", "--planner", "lsample-0.5,lsample-0.9,birrt", "--episodes", "2", "--quiet"])
        == 0
    )
