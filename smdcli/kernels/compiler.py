"""The one decorator every kernel is compiled with, and whether compiled code is already cached.

numba writes each compiled kernel to a cache (beside the source, or in the user-wide cache when the
install is read-only) on first use; later processes load it in well under a second.

Must not import: solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

import numba

# numba keys a cached kernel on its own file's time stamp only, while every integrator inlines or calls code of
# other files (rhs.py, linalg.py, the opcodes of expression.py): after one of those changed it would load stale
# machine code. The sources together stamp the cache folder; a different stamp clears our kernels from it.
_KERNELS = Path(__file__).resolve().parent
_SOURCES = (*sorted(_KERNELS.glob("*.py")), _KERNELS.parent / "expression.py")
_STAMP = "smd_kernels.stamp"


def _cache_folder() -> Path | None:
    """The folder numba caches this package's kernels in (the first locator that takes them, as numba picks)."""
    from numba.core.caching import CacheImpl

    for locator_class in CacheImpl._locator_classes:
        # a locator reads only the source file's path; any function stands for the kernel
        locator = locator_class.from_function(_cache_folder, str(_KERNELS / "rhs.py"))
        if locator is None:
            continue
        try:
            locator.ensure_cache_path()
        except OSError:
            continue
        return Path(locator.get_cache_path())
    return None


def clear_stale_cache() -> bool:
    """Remove the cached kernels when the kernels' sources differ from those they were compiled from; True if
    it removed any. Best effort: where the cache cannot be read or written numba compiles as it would anyway."""
    digest = hashlib.sha256()
    for source in _SOURCES:
        digest.update(source.name.encode() + b"\0" + source.read_bytes())
    try:
        folder = _cache_folder()
        if folder is None:
            return False
        stamp = folder / _STAMP
        if stamp.exists() and stamp.read_text() == digest.hexdigest():
            return False
        stems = tuple(f"{source.stem}." for source in _SOURCES)
        stale = [entry for entry in folder.iterdir()
                 if entry.name.startswith(stems) and entry.suffix in (".nbi", ".nbc")]
        for entry in stale:
            entry.unlink(missing_ok=True)
        partial = folder / f"{_STAMP}.{os.getpid()}"
        partial.write_text(digest.hexdigest())
        os.replace(partial, stamp)
        return bool(stale)
    except (OSError, AttributeError, ImportError):  # AttributeError/ImportError: a numba without these internals
        return False


if not numba.config.DISABLE_JIT:
    clear_stale_cache()

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
    if numba.config.DISABLE_JIT or dispatcher.signatures:  # plain Python functions have no signatures
        return True
    cache = getattr(dispatcher, "_cache", None)
    locator = getattr(getattr(cache, "_cache_file", None), "_index_path", None)
    if locator is None:
        return False
    import os

    return os.path.exists(locator)


STENCIL_MODELS = 8  # the stencil models one sensitivity run takes (more: the parameters in groups, a run each)


def model_tuple(models: list, like) -> tuple:
    """Kernel arrays as the sensitivity kernel takes them: a tuple of STENCIL_MODELS, padded with `like` (one type
    for any count, one compile). A tuple, not a numba typed list: reading a typed list's item counts a reference to
    each of its 44 arrays, and a function that indexes one cannot be compiled without reference counting."""
    if len(models) > STENCIL_MODELS:
        raise ValueError(f"{len(models)} stencil models; a sensitivity run takes at most {STENCIL_MODELS}")
    return tuple(models) + (like,) * (STENCIL_MODELS - len(models))
