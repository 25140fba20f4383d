"""What this machine has: memory, for refusing work that could not fit before anything is allocated.

Imports nothing of smd (the bottom layer)."""

from __future__ import annotations

import os
from contextlib import contextmanager

ASSUMED_MEMORY = 8 * 2**30  # where the platform does not say: what a laptop has
# glibc's mallopt parameters and what keep_freed_memory sets them to: arrays up to 32 MiB (the largest it takes) from
# the heap, and up to 256 MiB of freed heap kept
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
HEAP_ARRAYS, HEAP_KEPT = 32 * 2**20, 256 * 2**20
_kept = False


def physical_memory() -> int:
    """Bytes of physical memory."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return ASSUMED_MEMORY


def fits(needed: float) -> bool:
    """Whether an allocation of `needed` bytes fits in half of physical memory (the rest is for the system,
    the interpreter and working copies)."""
    return needed <= physical_memory() / 2


def keep_freed_memory() -> None:
    """Have glibc's malloc keep what a process frees for its next arrays, where it would hand it back to the system
    (arrays of over 128 KiB mapped on their own, the heap's free top trimmed): sensitivities repeated in one process
    (a fit's) then take their arrays' pages as they were, not fresh from the system a fault a page (a 300-mass
    chain's: 10,700 faults a run, 67 ms a run, 48 ms without them). Both settings: either alone faulted more. Set
    once a process; elsewhere (another C library) nothing."""
    global _kept
    if _kept:
        return
    _kept = True
    try:
        import ctypes

        mallopt = ctypes.CDLL(None).mallopt
        mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    except (OSError, AttributeError, TypeError):  # not glibc (macOS, musl keeps no such setting; Windows)
        return
    mallopt(_M_MMAP_THRESHOLD, HEAP_ARRAYS)
    mallopt(_M_TRIM_THRESHOLD, HEAP_KEPT)


def fault_in(nbytes: int) -> None:
    """Have the heap hold nbytes of pages already touched, for the arrays that follow: written and freed in pieces the
    heap takes (each below HEAP_ARRAYS), which keep_freed_memory keeps. A clock started after pays no page's first
    touch, as a process's later runs do not (a 5-storey frame's first sensitivity in a process: 6,000 faults and
    1.3 times the time of the next)."""
    import numpy as np

    keep_freed_memory()
    pieces = [np.ones(min(HEAP_ARRAYS // 2, nbytes - done) // 8) for done in range(0, nbytes, HEAP_ARRAYS // 2)]
    del pieces


# Above this many state variables BLAS threads pay for themselves; below, a product's work is microseconds and the
# threads' wake-ups cost more: worse, numpy and scipy each carry an OpenBLAS with its own pool, and on two cores the
# two pools' spinning workers take turns at scheduler slices (a 3-storey frame's fit: 0.37 s, 0.15 s single-threaded)
SMALL_BLAS = 256
_blas = None  # threadpoolctl's controllers of the BLAS libraries loaded (numpy's and scipy's), found once a process


@contextmanager
def small_blas(size: int):
    """Run the block with BLAS on one thread where the problem has at most SMALL_BLAS state variables (threads as
    they were otherwise); the previous limits are restored on leaving."""
    if size > SMALL_BLAS:
        yield
        return
    global _blas
    if _blas is None:
        import scipy.linalg  # noqa: F401  scipy's own BLAS is loaded before the controller looks for libraries
        from threadpoolctl import ThreadpoolController

        _blas = [library for library in ThreadpoolController().lib_controllers if library.user_api == "blas"]
    # each library's own getter and setter (what threadpoolctl's limit() calls, without its bookkeeping: 4 us a
    # call instead of 9, on a 1-DOF sensitivity of 0.4 ms)
    before = [library.num_threads for library in _blas]
    try:
        for library in _blas:
            library.set_num_threads(1)
        yield
    finally:
        for library, threads in zip(_blas, before):
            library.set_num_threads(threads)
