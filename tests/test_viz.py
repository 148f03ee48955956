"""2D drawings: every renderer writes a readable, non-blank image of the expected size."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import matplotlib.image as mpimg
import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import PathCollection
from matplotlib.figure import Figure

from pointplan.geometry.shapes import Box, Capsule, PointCloud, Sphere
from pointplan.robots import Disc2D
from pointplan.scenes import Problem, Scene
from pointplan.viz import (
    draw_problem,
    grid_figsize,
    plot2d,
    render_grid,
    render_problem,
    render_rgb,
)


@dataclass
class FakeResult:
    """Stands in for a planner's ``PlanResult`` (same fields)."""

    path: np.ndarray
    success: bool = True
    nodes: int = 0
    collision_checks: int = 0
    time_s: float = 0.01
    trees: list = field(default_factory=list)
    raw_path: np.ndarray | None = None


def _result(problem: Problem, rng: np.random.Generator) -> FakeResult:
    """A made-up result: two random trees rooted at start and goal and a 3-node path."""
    trees = []
    for root in (problem.start, problem.goal):
        nodes = np.concatenate([root[None], rng.uniform(0, 1, (30, 2))])
        parents = np.concatenate([[-1], [int(rng.integers(0, i + 1)) for i in range(30)]])
        trees.append((nodes, parents))
    mid = (problem.start + problem.goal) / 2 + 0.05
    path = np.stack([problem.start, mid, problem.goal])
    raw = np.stack([problem.start, mid - 0.05, mid, problem.goal])
    return FakeResult(path=path, nodes=62, collision_checks=123, trees=trees, raw_path=raw)


@pytest.fixture(scope="module")
def problems(narrow2d_test_problems: Callable[[int], list[Problem]]) -> list[Problem]:
    return narrow2d_test_problems(3)


def _check_png(path: Path, figsize: tuple[float, float], dpi: float) -> np.ndarray:
    assert path.is_file() and path.stat().st_size > 0
    img = mpimg.imread(path)
    assert img.shape[:2] == (round(figsize[1] * dpi), round(figsize[0] * dpi))
    _check_not_blank(img)
    _check_nothing_clipped(img)
    return img


def _check_nothing_clipped(img: np.ndarray) -> None:
    """The outermost pixel rows and columns are plain background (labels fit the figure)."""
    rgb = np.asarray(img)[..., :3].astype(np.float64)
    border = np.concatenate(
        [rgb[:2].reshape(-1, 3), rgb[-2:].reshape(-1, 3), rgb[:, :2].reshape(-1, 3), rgb[:, -2:].reshape(-1, 3)]
    )
    assert np.all(np.abs(border - rgb[0, 0]) < 0.05), "something is drawn on the figure's edge"


def _check_not_blank(img: np.ndarray) -> None:
    rgb = np.asarray(img)[..., :3].astype(np.float64)
    background = rgb[0, 0]
    differs = np.any(np.abs(rgb - background) > 0.05 * rgb.max(), axis=-1)
    assert differs.mean() > 0.01, "the image is (nearly) blank"


@pytest.mark.parametrize("observer_name", ["surface-normals", "surface", "interior"])
def test_render_problem_point_observers(tmp_path: Path, problems: list[Problem], observer_name: str) -> None:
    p = problems[0]
    out = render_problem(
        p,
        tmp_path / "p.png",
        Disc2D(),
        observer_name=observer_name,
        n_points=32,
        result=_result(p, np.random.default_rng(0)),
        dpi=60,
    )
    assert out == tmp_path / "p.png"
    _check_png(out, plot2d.PROBLEM_FIGSIZE, 60)


def test_render_problem_image_observer(tmp_path: Path, problems: list[Problem]) -> None:
    out = render_problem(
        problems[1], tmp_path / "sub" / "img.png", Disc2D(), observer_name="image", title="occupancy", dpi=60
    )
    _check_png(out, plot2d.IMAGE_FIGSIZE, 60)


def test_render_grid(tmp_path: Path, problems: list[Problem]) -> None:
    rng = np.random.default_rng(1)
    results = [_result(problems[0], rng), None, FakeResult(path=np.zeros((0, 2)), success=False, nodes=5)]
    out = render_grid(problems, results, tmp_path / "grid.png", Disc2D(), ncols=2, dpi=50)
    _check_png(out, grid_figsize(3, 2), 50)
    out = render_grid(problems[:2], None, tmp_path / "grid2.png", Disc2D(), titles=["a", "b"], dpi=50)
    _check_png(out, grid_figsize(2, 4), 50)


def test_render_rgb(problems: list[Problem]) -> None:
    p = problems[2]
    img = render_rgb(p, Disc2D(), p.start)
    w, h = plot2d.RGB_FIGSIZE
    assert img.dtype == np.uint8
    assert img.shape == (round(h * plot2d.RGB_DPI), round(w * plot2d.RGB_DPI), 3)
    _check_not_blank(img)
    # the robot moves: so does the picture
    assert not np.array_equal(img, render_rgb(p, Disc2D(), p.goal))


def test_env_render_rgb_array() -> None:
    from pointplan.envs import PlanningEnv

    env = PlanningEnv("narrow2d", render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    assert frame is not None and frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3


def test_draw_problem_all_shapes(tmp_path: Path) -> None:
    rot = np.array([[np.cos(0.4), -np.sin(0.4)], [np.sin(0.4), np.cos(0.4)]])
    scene = Scene(
        [
            Box([0.3, 0.6], [0.2, 0.1], rotation=rot),
            Sphere([0.7, 0.3], 0.1),
            Capsule([0.2, 0.2], [0.45, 0.3], 0.04),
            PointCloud(np.random.default_rng(0).uniform(0.6, 0.9, (40, 2)), np.ones((40, 2))),
        ],
        low=np.zeros(2),
        high=np.ones(2),
    )
    problem = Problem(scene, [0.1, 0.9], [0.9, 0.95])
    obs = np.array([[0.1, -0.2, 1.0, 0.0], [0.2, -0.3, 0.0, 1.0]])
    fig = Figure(figsize=(4, 4), dpi=50)
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    draw_problem(ax, problem, Disc2D(), observation=obs, legend=True)
    assert ax.get_xlim() == (0.0, 1.0) and ax.get_ylim() == (0.0, 1.0)
    labels = ax.get_legend_handles_labels()[1]
    assert "obstacles" in labels and "start" in labels
    # observation points come back in the world frame
    observed = [c for c in ax.collections if isinstance(c, PathCollection) and c.get_label().startswith("observed")]
    assert len(observed) == 1
    assert np.allclose(observed[0].get_offsets(), [[0.2, 0.7], [0.3, 0.6]])
    fig.savefig(tmp_path / "shapes.png")
    _check_png(tmp_path / "shapes.png", (4, 4), 50)


def test_rejects_3d_scenes(tmp_path: Path) -> None:
    scene = Scene([Box([0.5, 0.5, 0.5], [0.1, 0.1, 0.1])], low=np.zeros(3), high=np.ones(3))
    with pytest.raises(ValueError, match="2D"):
        render_rgb(Problem(scene, [0.1] * 3, [0.9] * 3), Disc2D(), np.array([0.1] * 3))
