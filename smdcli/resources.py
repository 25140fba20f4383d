"""What this machine has: memory, for refusing work that could not fit before anything is allocated.

Imports nothing of smd (the bottom layer)."""

from __future__ import annotations

import os

ASSUMED_MEMORY = 8 * 2**30  # where the platform does not say: what a laptop has


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
