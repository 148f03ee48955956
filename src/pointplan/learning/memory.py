"""How a training process gets its memory on Linux.

glibc's ``malloc`` serves every block of 32 MiB or more with a fresh ``mmap`` and gives it
back to the kernel when it is freed. A CNN update on a batch of 256 occupancy images
allocates and frees several activations of just that size (256 x 32 channels x 32 x 32
float32) each step, so the kernel spends its time mapping and zeroing fresh pages: on
this project's machine about a third of such a process's CPU time went to the kernel.
:func:`keep_freed_memory` has ``malloc`` take large blocks from its heap and keep what is
freed there for the next request (``mallopt``: no ``mmap``, no trimming), which the image
trainers call; ``benchmarks/bench_sac.py --image-malloc`` measures the gain. The process
then keeps its peak memory until it exits. Set ``POINTPLAN_SYSTEM_MALLOC=1`` to leave
``malloc`` as it is.
"""

from __future__ import annotations

import ctypes
import os
import sys

_M_TRIM_THRESHOLD = -1
_M_MMAP_MAX = -4
_applied = False


def keep_freed_memory() -> bool:
    """Ask glibc's ``malloc`` to serve every block from its heap and never give freed
    memory back to the kernel, for the rest of the process. Returns whether that is in
    force (``False`` off Linux, without glibc, or with ``POINTPLAN_SYSTEM_MALLOC`` set)."""
    global _applied
    if _applied:
        return True
    if sys.platform != "linux" or os.environ.get("POINTPLAN_SYSTEM_MALLOC", "") not in ("", "0"):
        return False
    try:
        mallopt = ctypes.CDLL("libc.so.6").mallopt
    except (OSError, AttributeError):  # not glibc
        return False
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    mallopt.restype = ctypes.c_int
    # mallopt returns 1 on success
    _applied = mallopt(_M_MMAP_MAX, 0) == 1 and mallopt(_M_TRIM_THRESHOLD, 2**31 - 1) == 1
    return _applied
