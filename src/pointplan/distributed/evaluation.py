"""Problem sets planned by Ray tasks, with the serial run's results."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, overload

from ..evaluation.evaluate import EvalReport, evaluate, set_call_number
from ..planners.base import Planner
from ..robots.base import Robot
from ..scenes.base import Scenario
from ..scenes.scene import Problem
from .tasks import RayPool

__all__ = ["ScenarioProblems", "evaluate_parallel", "set_call_number"]


class ScenarioProblems(Sequence[Problem]):
    """``scenario.problems(split, n, seed)`` built on demand: problem ``i`` is
    ``scenario.problem(split, i, seed)``. It travels to workers as its recipe (the scenario's
    name, robot, split, count and seed), not as scenes: a 3D-YCB problem set holds tens of
    megabytes of meshes, which each worker rebuilds instead of receiving."""

    def __init__(self, env: str, robot: str | None, split: str, n: int, seed: int = 0) -> None:
        self.env, self.robot, self.split, self.n, self.seed = env, robot, split, int(n), int(seed)
        self._scenario: Scenario | None = None
        self._built: dict[int, Problem] = {}

    @classmethod
    def of(cls, scenario: Scenario, split: str, n: int, seed: int = 0) -> ScenarioProblems:
        """The problems of a registered ``scenario`` (one :func:`make_scenario` builds)."""
        robot = scenario.robot.name if scenario.robot.dim == 3 else None
        return cls(scenario.name, robot, split, n, seed)

    def __getstate__(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in ("env", "robot", "split", "n", "seed")}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__init__(**state)  # type: ignore[misc]

    def __len__(self) -> int:
        return self.n

    @overload
    def __getitem__(self, i: int) -> Problem: ...
    @overload
    def __getitem__(self, i: slice) -> list[Problem]: ...
    def __getitem__(self, i: int | slice) -> Problem | list[Problem]:
        if isinstance(i, slice):
            return [self[j] for j in range(*i.indices(self.n))]
        if i < 0:
            i += self.n
        if not 0 <= i < self.n:
            raise IndexError(i)
        if i not in self._built:
            if self._scenario is None:
                from ..scenes.scenarios import make_scenario

                self._scenario = make_scenario(self.env, robot=self.robot)
            if len(self._built) > 64:  # a worker plans a chunk at a time: keep few scenes
                self._built.clear()
            self._built[i] = self._scenario.problem(self.split, i, seed=self.seed)
        return self._built[i]


def evaluate_parallel(
    planner: Planner,
    problems: Sequence[Problem],
    robot: Robot,
    progress: bool = True,
    resolution: float = 0.01,
    tolerance: float = 0.07,
    workers: int | None = None,
    address: str | None = None,
) -> EvalReport:
    """:func:`~pointplan.evaluation.evaluate` on Ray workers: the same records in the same
    order (times aside). Each worker plans with its own copy of ``planner``; afterwards
    ``planner`` here counts the calls as if it had planned them all.

    On Ctrl-C the running tasks are cancelled and the report holds the problems that
    finished (in problem order); its ``interrupted`` attribute is ``(finished, total)``."""
    return evaluate(planner, problems, robot, progress, resolution, tolerance, pool=RayPool(workers, address))
