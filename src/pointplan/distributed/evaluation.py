"""Problem sets planned by Ray tasks, with the serial run's results."""

from __future__ import annotations

import sys
from collections.abc import Sequence
from typing import Any, overload

from ..robots.base import Robot
from ..scenes.scene import Problem


class ScenarioProblems(Sequence[Problem]):
    """``scenario.problems(split, n, seed)`` built on demand: problem ``i`` is
    ``scenario.problem(split, i, seed)``. It travels to workers as its recipe (the scenario's
    name, robot, split, count and seed), not as scenes: a 3D-YCB problem set holds tens of
    megabytes of meshes, which each worker rebuilds instead of receiving."""

    def __init__(self, env: str, robot: str | None, split: str, n: int, seed: int = 0) -> None:
        self.env, self.robot, self.split, self.n, self.seed = env, robot, split, int(n), int(seed)
        self._scenario: Any = None
        self._built: dict[int, Problem] = {}

    @classmethod
    def of(cls, scenario: Any, split: str, n: int, seed: int = 0) -> ScenarioProblems:
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


def set_call_number(planner: Any, number: int) -> None:
    """Make ``planner``'s next ``plan`` call the ``number``-th one (counted from 0), for a
    planner that numbers its calls in ``calls`` (Bi-RRT seeds each call with
    ``(seed, call number)``); others are left alone."""
    if isinstance(getattr(planner, "calls", None), int):
        planner.calls = int(number)


def _plan_and_check(pos: int, planner: Any, problems: Sequence[Problem], robot: Robot, first_call: int, resolution: float, tolerance: float) -> Any:
    """One problem of an evaluation, in a worker: what the serial loop of
    :func:`~pointplan.evaluation.evaluate` does for it."""
    from ..evaluation.evaluate import plan_and_check

    set_call_number(planner, first_call + pos)
    return plan_and_check(planner, problems[pos], robot, resolution, tolerance)


def evaluate_parallel(
    planner: Any,
    problems: Sequence[Problem],
    robot: Robot,
    progress: bool = True,
    resolution: float = 0.01,
    tolerance: float = 0.07,
    workers: int | None = None,
    address: str | None = None,
) -> Any:
    """:func:`~pointplan.evaluation.evaluate` on Ray workers: the same records in the same
    order (times aside). Each worker plans with its own copy of ``planner``; afterwards
    ``planner`` here counts the calls as if it had planned them all.

    On Ctrl-C the running tasks are cancelled and the report holds the problems that
    finished (in problem order); its ``interrupted`` attribute is ``(finished, total)``."""
    from ..evaluation.evaluate import EvalReport
    from . import Interrupted, map_ordered

    report = EvalReport(planner=str(getattr(planner, "name", type(planner).__name__)))
    n = len(problems)
    first_call = int(getattr(planner, "calls", 0) or 0)
    bar = None
    solved = [0, 0]
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=n, desc=report.planner, unit="problem")

    def tick(_: int, rec: Any) -> None:
        solved[0] += bool(rec.success)
        solved[1] += 1
        if bar is not None:
            bar.update()
            bar.set_postfix(success=f"{solved[0] / solved[1]:.1%}")

    try:
        records = map_ordered(
            _plan_and_check, range(n), workers=workers, address=address, shared=(planner, problems, robot, first_call, resolution, tolerance), on_result=tick
        )
        interrupted = None
    except Interrupted as stop:
        records = [stop.results[i] for i in sorted(stop.results)]
        interrupted = (len(records), n)
        print(f"\ninterrupted: kept the {len(records)} of {n} problems that finished", file=sys.stderr)
    finally:
        if bar is not None:
            bar.close()
    report.records.extend(records)
    report.interrupted = interrupted
    set_call_number(planner, first_call + n)
    return report
