"""Ray itself: connecting, ordered maps of tasks with retries and Ctrl-C, the worker pool."""

from __future__ import annotations

import contextlib
import importlib.util
import math
import os
import warnings
from collections.abc import Callable, Iterator, Sequence
from typing import Any

from ..parallel import Interrupted, wants_workers

#: whether ``workers`` / ``address`` ask for more than this process
wants_ray = wants_workers

#: printed when workers are asked for without Ray
RAY_MISSING = "running on several workers needs Ray: pip install 'pointplan[ray]' (or drop --workers/--address to run in one process)"

#: times Ray re-runs a task whose worker process died
TASK_RETRIES = 3


def ray_available() -> bool:
    """Is Ray installed?"""
    return importlib.util.find_spec("ray") is not None


class RayMissing(RuntimeError):
    """Workers were asked for but Ray is not installed."""

    def __init__(self) -> None:
        super().__init__(RAY_MISSING)


class NoCluster(RuntimeError):
    """No Ray cluster answers at the address given (a one-line message for the user)."""

    def __init__(self, address: str) -> None:
        super().__init__(f"no Ray cluster at {address}: start one with `ray start --head`, or leave out --address")
        self.address = address


def connect(workers: int | None = None, address: str | None = None) -> Any:
    """Start (or join) Ray and return the ``ray`` module.

    ``address``: an existing cluster (``auto``, ``ray://host:10001`` or ``host:6379``);
    otherwise a local Ray with ``workers`` CPUs (default: all of this machine's). An
    already running Ray in this process is reused. Raises :class:`NoCluster` when no
    cluster answers at ``address``."""
    if not ray_available():
        raise RayMissing()
    import ray

    if ray.is_initialized():
        return ray
    # No runtime_env: workers inherit this process's environment (PYTHONPATH for a source
    # checkout included) and Ray sets OMP_NUM_THREADS=1 for one-CPU tasks; a runtime_env
    # would keep Ray from using the workers it prestarts (2-3 s more before the first task).
    kwargs: dict[str, Any] = {"include_dashboard": False, "logging_level": "warning", "log_to_driver": True}
    if address:
        # the cluster's nodes must have pointplan installed (docs/guide/scaling.md)
        try:
            with warnings.catch_warnings():  # the client's own warning says what NoCluster says
                warnings.filterwarnings("ignore", message="Ray Client connection timed out")
                ray.init(address=address, **kwargs)
        except (ConnectionError, TimeoutError) as e:
            raise NoCluster(address) from e
    else:
        # Ray runs its workers at niceness 15 by default, below every other job of a shared
        # machine; the workers of a local Ray do this command's work, so they run at its
        # priority, as the serial command would (set RAY_worker_niceness to choose another).
        os.environ.setdefault("RAY_worker_niceness", "0")
        ray.init(num_cpus=int(workers) if workers else None, **kwargs)
    return ray


def cluster_cpus() -> int:
    """CPUs of the Ray instance this process is connected to."""
    import ray

    return max(1, int(ray.cluster_resources().get("CPU", 1)))


# ---------------------------------------------------------------------------- worker side
#: objects fetched by workers, by object id (a worker process runs many tasks)
_CACHE: dict[str, Any] = {}


def _shared(refs: list[Any]) -> list[Any]:
    """The values of ``refs`` (object refs wrapped in a list, so Ray does not resolve them
    per task), fetched once per worker process."""
    import ray

    out = []
    for ref in refs:
        key = ref.hex()
        if key not in _CACHE:
            if len(_CACHE) > 16:
                _CACHE.clear()
            _CACHE[key] = ray.get(ref)
        out.append(_CACHE[key])
    return out


def _run_chunk(fn: Callable[..., Any], items: list[tuple[int, Any]], shared: list[Any]) -> list[tuple[int, Any]]:
    values = _shared(shared)
    try:  # torch, if the task uses it, on the one core Ray gave this task
        import sys

        if "torch" in sys.modules:
            sys.modules["torch"].set_num_threads(1)
    except Exception:  # pragma: no cover
        pass
    return [(pos, fn(item, *values)) for pos, item in items]


# ---------------------------------------------------------------------------- driver side
def map_ordered(
    fn: Callable[..., Any],
    items: Sequence[Any],
    *,
    workers: int | None = None,
    address: str | None = None,
    shared: Sequence[Any] = (),
    chunksize: int | None = None,
    on_result: Callable[[int, Any], None] | None = None,
) -> list[Any]:
    """``[fn(item, *shared) for item in items]`` computed by Ray tasks, in item order.

    ``fn`` must be importable by the workers (a module-level function). ``shared`` values
    are stored once in Ray's object store and fetched once per worker process. Items go
    in chunks of ``chunksize`` consecutive items (default: about 8 chunks per worker, at
    most 16 items); at most two chunks per worker are in flight, so a cluster is not
    flooded and Ctrl-C stops quickly. ``on_result(position, result)`` is called as
    results arrive (in completion order). A worker process that dies has its chunk re-run
    by Ray (up to :data:`TASK_RETRIES` times); an exception raised by ``fn`` is raised
    here. Ctrl-C cancels what is running and raises :class:`Interrupted` with the finished
    results."""
    ray = connect(workers, address)
    n = len(items)
    if n == 0:
        return []
    slots = int(workers) if workers and int(workers) > 0 else cluster_cpus()
    if chunksize is None:
        chunksize = max(1, min(16, math.ceil(n / (8 * slots))))
    chunks = [[(i, items[i]) for i in range(s, min(n, s + chunksize))] for s in range(0, n, chunksize)]
    task = ray.remote(num_cpus=1, max_retries=TASK_RETRIES)(_run_chunk)
    shared_refs = [ray.put(v) for v in shared]
    fn_ref = ray.put(fn)
    pending: dict[Any, int] = {}
    results: dict[int, Any] = {}
    next_chunk = 0
    try:
        while next_chunk < len(chunks) or pending:
            while next_chunk < len(chunks) and len(pending) < 2 * slots:
                ref = task.remote(fn_ref, chunks[next_chunk], shared_refs)
                pending[ref] = next_chunk
                next_chunk += 1
            done, _ = ray.wait(list(pending), num_returns=1)
            for ref in done:
                pending.pop(ref)
                for pos, value in _get(ray, ref):
                    results[pos] = value
                    if on_result is not None:
                        on_result(pos, value)
    except KeyboardInterrupt:
        for ref in pending:
            with contextlib.suppress(Exception):  # (a task that already finished)
                ray.cancel(ref, force=True)
        raise Interrupted(results, n) from None
    return [results[i] for i in range(n)]


def _get(ray: Any, ref: Any) -> Any:
    """``ray.get`` that raises the task's own exception (not Ray's wrapper) when it can."""
    try:
        return ray.get(ref)
    except ray.exceptions.RayTaskError as e:
        cause = e.as_instanceof_cause()
        raise cause from None


class RayPool:
    """A stand-in for ``concurrent.futures``' process pool on Ray, and the
    :class:`~pointplan.parallel.WorkerPool` that evaluation and learning take: ``map``
    returns the results in input order (see :func:`map_ordered`; Ray starts on the first
    call), ``shutdown`` does nothing (Ray's workers stay up for the next call; they end with
    the process)."""

    def __init__(self, workers: int | None = None, address: str | None = None) -> None:
        self.workers, self.address = workers, address

    def map(
        self,
        fn: Callable[..., Any],
        items: Sequence[Any] | Iterator[Any],
        chunksize: int | None = None,
        on_result: Callable[[int, Any], None] | None = None,
        shared: Sequence[Any] = (),
    ) -> list[Any]:
        """``fn(item, *shared)`` of every item on the Ray workers, in order; ``on_result(i,
        result)`` as each arrives."""
        # ``chunksize`` is accepted for the process pool's signature; chunks are sized by
        # map_ordered (small enough to balance problems of very different costs)
        return map_ordered(
            fn, list(items), workers=self.workers, address=self.address, shared=shared, on_result=on_result
        )

    def shutdown(self, wait: bool = True, cancel_futures: bool = False) -> None:
        """Nothing to release (the pool holds no workers between calls); for the process pool's signature."""
        return None
