"""Scenarios: a robot, a family of workspaces, and how problems are drawn in them.

An environment id names a scenario; the environment asks it for workspaces of the train or
test split and for start/goal pairs.
"""

from __future__ import annotations

import zlib
from abc import ABC, abstractmethod
from collections.abc import Sequence

import numpy as np

from ..robots import Disc2D
from ..robots.base import Robot
from . import narrow2d
from .scene import Problem, Scene


class Scenario(ABC):
    """A family of planning problems for one robot."""

    name: str
    robot: Robot
    horizon: int

    @abstractmethod
    def scene(self, split: str, index: int) -> Scene:
        """Workspace ``index`` of ``split`` (``train`` or ``test``); splits are disjoint."""

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """The workspace bounds ``(low, high)`` shared by every scene of the scenario
        (subclasses answer without building a scene)."""
        ref = self.scene("test", 0)
        return ref.low.copy(), ref.high.copy()

    def sample_problem(self, scene: Scene, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """A collision-free start and goal drawn uniformly in ``scene``."""
        q = self.robot.sample_free(scene.world, rng, 2, scene.low, scene.high)
        return q[0], q[1]

    def problem(self, split: str, index: int, seed: int = 0) -> Problem:
        """Problem ``index`` of ``split``: workspace ``index``, start and goal drawn from
        ``(split, index, seed)``."""
        scene = self.scene(split, index)
        rng = np.random.default_rng(np.random.SeedSequence([zlib.crc32(self.name.encode()), zlib.crc32(split.encode()), index, seed]))
        start, goal = self.sample_problem(scene, rng)
        return Problem(scene, start, goal, tag=f"{self.name}/{split}/{index}/seed{seed}")

    def problems(self, split: str, n: int, seed: int = 0) -> list[Problem]:
        """``n`` fixed problems, one per workspace ``0..n-1`` of ``split``."""
        return [self.problem(split, i, seed) for i in range(n)]


class Narrow2DScenario(Scenario):
    """2D-Narrow with the 2D disc; horizon 50."""

    name = "narrow2d"
    horizon = 50

    def __init__(self, robot: Robot | None = None, config: narrow2d.Narrow2DConfig | None = None) -> None:
        self.robot = robot or Disc2D()
        self.config = config or narrow2d.Narrow2DConfig()

    def scene(self, split: str, index: int) -> Scene:
        return narrow2d.workspace(split, index, self.config, radius=float(self.robot.parts.sphere_radii.max()))

    def problem(self, split: str, index: int, seed: int = 0) -> Problem:
        return narrow2d.problem(split, index, seed, self.robot)

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros(2), np.ones(2)


class FixedScenario(Scenario):
    """One scene (e.g. loaded from a file) for every split, with optional fixed problems."""

    def __init__(self, scene: Scene, robot: Robot, horizon: int = 50, fixed: Sequence[Problem] = ()) -> None:
        self.name = scene.name or "scene"
        self._scene = scene
        self.robot = robot
        self.horizon = horizon
        self.fixed = list(fixed)

    def scene(self, split: str, index: int) -> Scene:
        return self._scene

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return self._scene.low.copy(), self._scene.high.copy()

    def problem(self, split: str, index: int, seed: int = 0) -> Problem:
        if self.fixed:
            return self.fixed[index % len(self.fixed)]
        return super().problem(split, index, seed)

    def problems(self, split: str, n: int, seed: int = 0) -> list[Problem]:
        if self.fixed:
            return self.fixed[:n]
        return super().problems(split, n, seed)


class Empty2DScenario(Scenario):
    """The unit square with no obstacles, for the 2D disc: a sanity check for learning."""

    name = "empty2d"
    horizon = 50

    def __init__(self, robot: Robot | None = None) -> None:
        self.robot = robot or Disc2D()
        self._scene = Scene([], low=np.zeros(2), high=np.ones(2), name="empty2d")

    def scene(self, split: str, index: int) -> Scene:
        return self._scene

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return self._scene.low.copy(), self._scene.high.copy()


SCENARIOS: dict[str, type[Scenario]] = {"narrow2d": Narrow2DScenario, "empty2d": Empty2DScenario}
from .narrow2d_variants import VARIANT_SCENARIOS  # noqa: E402  (narrow2d-ends, -many, -narrow, -manynarrow)

SCENARIOS.update(VARIANT_SCENARIOS)


def scenario_names() -> list[str]:
    from .scenes3d import SCENARIOS_3D

    return list(SCENARIOS) + list(SCENARIOS_3D)


def scenario_key(name: str) -> str:
    """The registry key of a scenario name or Gymnasium id (``pointplan/Boxes3D-v0`` ->
    ``boxes3d``)."""
    return name.lower().split("/")[-1].removesuffix("-v0").replace("-", "").replace("_", "")


def is_3d(name: str) -> bool:
    """Whether ``name`` is one of the 3D scenarios."""
    from .scenes3d import SCENARIOS_3D

    return scenario_key(name) in SCENARIOS_3D


def make_scenario(name: str, robot: str | Robot | None = None, **kwargs: object) -> Scenario:
    """A scenario by name: ``narrow2d``, ``empty2d`` (2D disc); ``boxes3d``, ``synthetic3d``,
    ``ycb3d``, ``dynamic3d``, ``slot``, ``qureshi3d`` (``robot``: ``sphere3d`` or ``sshape``).
    Also accepts Gymnasium ids such as ``pointplan/Boxes3D-v0``."""
    from .scenes3d import SCENARIOS_3D

    key = scenario_key(name)
    if key in SCENARIOS_3D:
        return SCENARIOS_3D[key](robot=robot, **kwargs)
    if key in SCENARIOS:
        if robot is not None:
            from ..robots import make_robot

            r = make_robot(robot) if isinstance(robot, str) else robot
            if r.dim != 2:
                raise ValueError(f"{name} is a 2D scenario; robot {r.name} is {r.dim}D")
            return SCENARIOS[key](robot=r, **kwargs)  # type: ignore[call-arg]
        return SCENARIOS[key](**kwargs)
    raise ValueError(f"unknown environment {name!r}; known: {', '.join(scenario_names())}")
