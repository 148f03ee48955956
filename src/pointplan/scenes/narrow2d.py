"""2D-Narrow: three 0.1-wide gaps in two 0.1-thick walls (after Ichter et al. 2018).

A horizontal wall (y in [gy - t, gy]) spans the unit square with one gap left and one
gap right of a vertical wall (x in [gx - t, gx]) that also spans the square with one gap,
above or below the horizontal wall. That is five boxes. The cross splits the square into
four rooms and the three gaps join all four, so every pair of free configurations is
connected; the generator checks this on a grid all the same and re-draws otherwise.

Train, validation and test workspaces come from disjoint seed streams: workspace ``i`` of split ``s``
is drawn from ``SeedSequence([SPLIT_KEYS[s], i])``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from ..geometry.shapes import Box
from ..robots.base import Robot
from .scene import Problem, Scene

SPLIT_KEYS = {"train": 0x7A11, "val": 0x7A1D, "test": 0x7E57}


@dataclass(frozen=True)
class Narrow2DConfig:
    """Parameters of the 2D-Narrow generator."""

    #: wall thickness
    thickness: float = 0.1
    #: width of each gap
    gap: float = 0.1
    #: margin kept between a gap and the crossing or the square's border
    margin: float = 0.05
    #: range of the walls' positions (upper edge of the horizontal wall, right edge of the
    #: vertical one)
    wall_range: tuple[float, float] = (0.3, 0.8)


def _boxes_from_intervals(axis: int, lo: float, hi: float, holes: list[tuple[float, float]]) -> list[Box]:
    """Boxes covering [0, 1] along ``axis`` minus the holes, and [lo, hi] across it."""
    edges = [0.0]
    for a, b in sorted(holes):
        edges += [a, b]
    edges.append(1.0)
    boxes = []
    for a, b in zip(edges[::2], edges[1::2]):
        if b - a <= 1e-9:
            continue
        if axis == 0:
            boxes.append(Box(center=np.array([(a + b) / 2, (lo + hi) / 2]), size=np.array([b - a, hi - lo])))
        else:
            boxes.append(Box(center=np.array([(lo + hi) / 2, (a + b) / 2]), size=np.array([hi - lo, b - a])))
    return boxes


def generate_scene(rng: np.random.Generator, config: Narrow2DConfig = Narrow2DConfig()) -> Scene:
    """One random 2D-Narrow workspace."""
    t, g, m = config.thickness, config.gap, config.margin
    lo, hi = config.wall_range
    gy = rng.uniform(lo, hi)  # horizontal wall occupies y in [gy - t, gy]
    gx = rng.uniform(lo, hi)  # vertical wall occupies x in [gx - t, gx]
    # gaps in the horizontal wall: one in the left room, one in the right room
    x1 = rng.uniform(m, gx - t - m - g)
    x3 = rng.uniform(gx + m, 1.0 - m - g)
    # gap in the vertical wall: below or above the horizontal wall
    y2 = rng.uniform(m, gy - t - m - g) if rng.random() < 0.5 else rng.uniform(gy + m, 1.0 - m - g)
    obstacles = _boxes_from_intervals(0, gy - t, gy, [(x1, x1 + g), (x3, x3 + g)])
    obstacles += _boxes_from_intervals(1, gx - t, gx, [(y2, y2 + g)])
    return Scene(obstacles=obstacles, low=np.zeros(2), high=np.ones(2), name="narrow2d")


def free_space_labels(scene: Scene, radius: float, resolution: int = 200) -> tuple[np.ndarray, int]:
    """Connected components of the free space of a disc on a grid (cell centres)."""
    xs = (np.arange(resolution) + 0.5) / resolution
    boxes = [b for b in scene.obstacles if isinstance(b, Box)]
    if len(boxes) == len(scene.obstacles) and all(np.allclose(b.rotation, np.eye(2)) for b in boxes):
        # axis-aligned boxes: per-axis distances, combined by broadcasting (fast)
        occupied = np.zeros((resolution, resolution), dtype=bool)
        for b in boxes:
            dx = np.maximum(np.abs(xs - b.center[0]) - b.half[0], 0.0)
            dy = np.maximum(np.abs(xs - b.center[1]) - b.half[1], 0.0)
            occupied |= dx[:, None] ** 2 + dy[None, :] ** 2 <= radius * radius
    else:
        grid = np.stack(np.meshgrid(xs, xs, indexing="ij"), -1).reshape(-1, 2)
        occupied = scene.world.spheres_collide(grid, radius).reshape(resolution, resolution)
    labels, n = ndimage.label(~occupied)
    return labels, int(n)


def workspace_rng(split: str, index: int) -> np.random.Generator:
    """The generator of workspace ``index`` of a split (``train`` or ``test``)."""
    if split not in SPLIT_KEYS:
        raise ValueError(f"unknown split {split!r}; use 'train', 'val' or 'test'")
    return np.random.default_rng(np.random.SeedSequence([SPLIT_KEYS[split], int(index)]))


def workspace(split: str, index: int, config: Narrow2DConfig = Narrow2DConfig(), radius: float = 0.01) -> Scene:
    """Workspace ``index`` of ``split``; re-drawn until its free space is one component."""
    rng = workspace_rng(split, index)
    for _ in range(100):
        scene = generate_scene(rng, config)
        if free_space_labels(scene, radius)[1] == 1:
            scene.name = f"narrow2d/{split}/{index}"
            return scene
    raise RuntimeError("2D-Narrow generator kept producing disconnected workspaces")


def sample_problem(scene: Scene, robot: Robot, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A uniformly drawn collision-free start and goal (the free space is connected)."""
    q = robot.sample_free(scene.world, rng, 2, scene.low, scene.high)
    return q[0], q[1]


def problem(split: str, index: int, seed: int = 0, robot: Robot | None = None) -> Problem:
    """Problem ``index`` of a split: workspace ``index`` with a start and goal drawn from
    ``(split, index, seed)``."""
    from ..robots import Disc2D

    robot = robot or Disc2D()
    scene = workspace(split, index, radius=float(robot.parts.sphere_radii.max()))
    rng = np.random.default_rng(np.random.SeedSequence([SPLIT_KEYS[split], int(index), int(seed), 1]))
    start, goal = sample_problem(scene, robot, rng)
    return Problem(scene=scene, start=start, goal=goal, tag=f"narrow2d/{split}/{index}/seed{seed}")


def problems(split: str, n: int, seed: int = 0, robot: Robot | None = None) -> list[Problem]:
    """``n`` problems of a split, one per workspace ``0..n-1``; fixed by ``seed``."""
    return [problem(split, i, seed, robot) for i in range(n)]
