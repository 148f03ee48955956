"""Scaling out on Ray: many cores of one machine, or a Ray cluster.

Ray is an optional extra (``pip install 'pointplan[ray]'``). Without it everything runs in
one process as before, and asking for workers says how to install it.

What runs on Ray:

- planning problem sets (``pointplan eval`` / ``plan``: :func:`pointplan.evaluation.evaluate`
  with a :class:`RayPool`, or :func:`evaluate_parallel`);
- Bi-RRT demonstrations for behavioural cloning and DAgger (a :class:`RayPool` passed to
  ``learning.bc.generate_demos`` and the trainers);
- rollouts for SAC training (``pointplan.distributed.rollouts``).

This package depends on evaluation and learning, never the reverse: they take a pool or a
rollout source (:mod:`pointplan.parallel`), which the command line passes in, and calls that
give only ``workers`` / ``address`` get them from :class:`RayBackend`, the default back end
the package root installs.

Determinism: a problem set is cut into chunks of consecutive problems; each chunk is a Ray
task that plans its problems with a copy of the planner, and the results are put back in
problem order. A planner that numbers its calls (Bi-RRT draws from
``default_rng((seed, call number))``) is set to the problem's position in the set before
each problem, which is the number a serial run gives it: the paths and metrics are those
of the serial run (only the wall times differ).

Failures: Ray re-runs a task whose worker process died (``max_retries``) on a new worker.
Ctrl-C cancels the tasks still running and keeps the finished results
(:class:`Interrupted` carries them).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

from .evaluation import ScenarioProblems, evaluate_parallel
from .tasks import (
    RAY_MISSING,
    TASK_RETRIES,
    Interrupted,
    NoCluster,
    RayMissing,
    RayPool,
    cluster_cpus,
    connect,
    map_ordered,
    ray_available,
    wants_ray,
)

if TYPE_CHECKING:
    from ..learning.train import TrainConfig
    from .rollouts import RayRollouts


class RayBackend:
    """The default back end of :mod:`pointplan.parallel`: Ray."""

    def available(self) -> bool:
        return ray_available()

    def pool(self, workers: int | None, address: str | None) -> RayPool:
        return RayPool(workers, address)

    def rollouts(
        self, workers: int | None, address: str | None, sync_every: int | None
    ) -> Callable[[TrainConfig], RayRollouts]:
        from .rollouts import ray_rollouts

        return ray_rollouts(workers, address, sync_every)


__all__ = [
    "RAY_MISSING",
    "TASK_RETRIES",
    "Interrupted",
    "NoCluster",
    "RayBackend",
    "RayMissing",
    "RayPool",
    "ScenarioProblems",
    "cluster_cpus",
    "connect",
    "evaluate_parallel",
    "map_ordered",
    "ray_available",
    "wants_ray",
]
