"""The one decorator every kernel is compiled with, and whether compiled code is already cached.

numba writes each compiled kernel to a cache (beside the source, or in the user-wide cache when the
install is read-only) on first use; later processes load it in well under a second.

Must not import: solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import numba

# nogil: members of a batch run on threads; error_model numpy: 1/0 is inf as in numpy, not an exception.
kernel = numba.njit(cache=True, nogil=True, error_model="numpy")
# For the right-hand side's parts, called once per stage: inlined into the integrator, so the model's arrays
# are not handed over (and reference-counted) on every call.
inlined = numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
# For kernels that allocate nothing, called per stage or per step: compiled without numba's reference counting,
# which otherwise costs an atomic increment and decrement per array (the model's 19) on every call.
no_alloc = numba.njit(cache=True, nogil=True, error_model="numpy", _nrt=False)


def is_cached(dispatcher) -> bool:
    """True when a kernel has compiled code in memory or an index in numba's cache (so no compile is due)."""
    if dispatcher.signatures or numba.config.DISABLE_JIT:
        return True
    cache = getattr(dispatcher, "_cache", None)
    locator = getattr(getattr(cache, "_cache_file", None), "_index_path", None)
    if locator is None:
        return False
    import os

    return os.path.exists(locator)
