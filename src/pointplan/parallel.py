"""What evaluation and learning need from workers in other processes, as interfaces.

:mod:`pointplan.distributed` implements them on Ray. Evaluation and learning never import
it: a worker pool or rollout source is passed in (the command line does that), and a call
that only asks for ``workers`` / ``address`` gets them from the default back end, which
the package root installs (:func:`set_backend`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, Protocol


class Interrupted(Exception):
    """Ctrl-C while tasks ran: ``results`` maps positions to the results that finished."""

    def __init__(self, results: dict[int, Any], total: int) -> None:
        super().__init__(f"interrupted: {len(results)} of {total} finished")
        self.results = results
        self.total = total


def wants_workers(workers: int | None, address: str | None) -> bool:
    """Whether ``workers`` / ``address`` ask for more than this process."""
    return bool(address) or (workers is not None and int(workers) > 1)


class WorkerPool(Protocol):
    """Runs a module-level function over items on workers, results in item order."""

    def map(
        self,
        fn: Callable[..., Any],
        items: Sequence[Any],
        *,
        shared: Sequence[Any] = (),
        on_result: Callable[[int, Any], None] | None = None,
    ) -> list[Any]:
        """``[fn(item, *shared) for item in items]``; ``on_result(position, result)`` as
        results arrive. Ctrl-C raises :class:`Interrupted` with the finished results."""
        ...

    def shutdown(self, wait: bool = True, cancel_futures: bool = False) -> None: ...


class RolloutSource(Protocol):
    """Training episodes stepped elsewhere with copies of the learner's actor."""

    #: a stop was asked for (Ctrl-C): the trainer ends the run after a last checkpoint
    interrupted: bool

    def sync(self, actor: Any, updates: int) -> None:
        """Publish ``actor``'s weights (when due after ``updates`` learner updates)."""
        ...

    def next_chunk(self, random_actions: bool) -> tuple[list[tuple[Any, ...]], list[float], int]:
        """Finished episodes, their success, and the transitions collected."""
        ...

    def close(self) -> None: ...


class Backend(Protocol):
    """Where ``workers`` / ``address`` run when no pool or rollout source is passed."""

    def available(self) -> bool:
        """Can it run anything here (its dependencies installed)?"""
        ...

    def pool(self, workers: int | None, address: str | None) -> WorkerPool: ...

    def rollouts(
        self, workers: int | None, address: str | None, sync_every: int | None
    ) -> Callable[[Any], RolloutSource]:
        """A factory of rollout sources for a training config."""
        ...


_backend: Callable[[], Backend] | None = None


def set_backend(loader: Callable[[], Backend] | None) -> None:
    """Install the default back end: ``loader()`` returns it when first needed."""
    global _backend
    _backend = loader


def backend() -> Backend:
    """The default back end (raises ``RuntimeError`` when none is installed)."""
    if _backend is None:
        raise RuntimeError(
            "no worker back end is installed: pass a pool (e.g. pointplan.distributed.RayPool) or run in one process"
        )
    return _backend()
