"""Fixtures shared by the test modules.

The package is imported inside the fixtures, not here: collecting the tests loads only
what the test modules themselves import.
"""

from __future__ import annotations

import os
import socket
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np
import pytest

if TYPE_CHECKING:
    from pointplan.scenes.scene import Problem

# Under pytest-xdist (the default, pyproject's addopts) each worker is one of several
# processes on the machine's cores: one thread each for PyTorch, MKL, OpenMP and numba,
# set before any of them is imported, or the workers slow each other down.
if int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1")) > 1:
    for _var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
        os.environ.setdefault(_var, "1")


@pytest.fixture(scope="session")
def narrow2d_test_problems() -> Callable[[int], list[Problem]]:
    """``narrow2d_test_problems(n)``: the first ``n`` 2D-Narrow test problems (seed 0), a
    new list of new problems at each call (a module's fixture keeps its own)."""
    from pointplan.scenes.scenarios import Narrow2DScenario

    def build(n: int) -> list[Problem]:
        return Narrow2DScenario().problems("test", n, seed=0)

    return build


@pytest.fixture(scope="module")
def one_torch_thread() -> None:
    """PyTorch on one thread in this process (small networks are faster so, and the results
    do not depend on the machine's cores). Like the tests' own calls it replaces, it is not
    undone afterwards."""
    import torch

    torch.set_num_threads(1)


@pytest.fixture(scope="session")
def same_rollout() -> Callable[[object, object], bool]:
    """``same_rollout(a, b)``: two plans of one problem (a compiled rollout and the step
    loop's) have the same outcome and the same path up to the two networks' float32
    round-off, which feeds back through each step's observation and grows along a
    rollout: up to 2.6e-5 after 20 steps of the sphere on an AMD EPYC host (the S-shape's
    under 1e-7), where the sphere's smallest step is 0.02; paths that part where round-off
    decides a step differ by a whole step."""

    def same(a: object, b: object) -> bool:
        pa, pb = a.path, b.path  # type: ignore[attr-defined]
        return bool(a.success == b.success and pa.shape == pb.shape and np.allclose(pa, pb, atol=1e-4))  # type: ignore[attr-defined]

    return same


@pytest.fixture(scope="session")
def free_port() -> Callable[[], int]:
    """``free_port()``: a TCP port on 127.0.0.1 that nothing listens on now."""

    def pick() -> int:
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            return int(s.getsockname()[1])

    return pick
