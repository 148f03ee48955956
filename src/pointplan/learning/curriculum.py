"""Retrying failed problems: a pool of start/goal pairs the policy did not solve.

Once a policy solves 99% of random problems, 99 of 100 training episodes teach it what it
already does; the rare problems it fails (long detours through a far gap, in 2D-Narrow)
are where the remaining errors are. The pool keeps such problems (the workspace object,
start and goal) and hands them back for new training episodes, so that a fraction of the
collected experience comes from them.

A problem enters the pool when an episode on it fails (training episodes, or deterministic
rollouts of the policy on fresh training problems). Each is lent out at most ``retries``
times after its last failure: failing again resets the count, so problems the policy keeps
failing stay until it learns them, and solved ones run out of retries. The pool is bounded;
the oldest entries go first.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from ..scenes.scene import Problem

if TYPE_CHECKING:
    from ..envs.core import BatchedCore


class FailurePool:
    """Problems to retry; :meth:`draw` lends them out, :meth:`failed` puts them back."""

    def __init__(self, capacity: int = 2000, retries: int = 4) -> None:
        if capacity < 1 or retries < 1:
            raise ValueError("capacity and retries must be positive")
        self.capacity = int(capacity)
        self.retries = int(retries)
        self._entries: OrderedDict[int, tuple[Problem, int]] = OrderedDict()  # key -> (problem, draws left)
        self._next_key = 0

    def __len__(self) -> int:
        return len(self._entries)

    def keys(self) -> list[int]:
        """Keys of the problems that can be drawn, oldest first."""
        return list(self._entries)

    def failed(self, problem: Problem, key: int | None = None) -> int:
        """Record a failure on ``problem`` (``key`` if it was drawn from the pool); returns
        its key. It may now be drawn ``retries`` more times."""
        if key is None:
            key = self._next_key
            self._next_key += 1
        self._entries[key] = (problem, self.retries)
        self._entries.move_to_end(key)
        while len(self._entries) > self.capacity:
            self._entries.popitem(last=False)
        return key

    def draw(self, rng: np.random.Generator) -> tuple[int, Problem] | None:
        """A problem of the pool (uniformly) and its key, or None if the pool is empty."""
        if not self._entries:
            return None
        keys = list(self._entries)
        key = keys[int(rng.integers(len(keys)))]
        problem, left = self._entries[key]
        if left <= 1:
            del self._entries[key]  # a later failure brings it back under the same key
        else:
            self._entries[key] = (problem, left - 1)
        return key, problem


class EpisodeSource:
    """Starts the episodes of a batched core: fresh problems, or with probability
    ``retry`` a problem of ``pool``; :meth:`ended` reports how an episode went."""

    def __init__(self, core: BatchedCore, pool: FailurePool | None, retry: float = 0.0) -> None:
        if not 0.0 <= retry <= 1.0:
            raise ValueError(f"the retry share must be in [0, 1], not {retry}")
        if retry > 0 and pool is None:
            raise ValueError("retrying failures needs a pool")
        self.core, self.pool, self.retry = core, pool, float(retry)
        n = core.num_envs
        self.key = np.full(n, -1, np.int64)  # pool key of each environment's problem (-1: fresh)
        self.problem: list[Problem | None] = [None] * n
        self.retried = self.fresh = 0

    def reset(self, idx: Sequence[int], rng: np.random.Generator) -> None:
        idx = [int(i) for i in idx]
        given: list[Problem | None] = [None] * len(idx)
        keys = [-1] * len(idx)
        if self.pool is not None and self.retry > 0:  # (no draws from rng otherwise)
            for j in range(len(idx)):
                if rng.random() < self.retry and (drawn := self.pool.draw(rng)) is not None:
                    keys[j], given[j] = drawn
        core = self.core
        core.reset_envs(idx, rng, given if any(g is not None for g in given) else None)
        for j, i in enumerate(idx):
            self.key[i] = keys[j]
            if self.pool is not None:
                scene = core.scenes[i]
                assert scene is not None
                self.problem[i] = given[j] or Problem(scene, core.q[i].copy(), core.goal[i].copy())
        self.retried += sum(k >= 0 for k in keys)
        self.fresh += sum(k < 0 for k in keys)

    def is_retry(self, i: int) -> bool:
        return bool(self.key[i] >= 0)

    def ended(self, i: int, success: bool) -> None:
        """Environment ``i``'s episode is over; a failure enters (or re-enters) the pool."""
        if self.pool is not None and not success:
            problem = self.problem[i]
            assert problem is not None
            self.pool.failed(problem, int(self.key[i]) if self.key[i] >= 0 else None)

    @property
    def retry_share(self) -> float:
        return self.retried / max(self.retried + self.fresh, 1)
