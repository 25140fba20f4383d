"""Output grids: the times a run reports, as the scenario's [time] table asks for them.

Must not import: solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from smdcli.scenario import TimeSpec


def time_grid(spec: TimeSpec) -> np.ndarray:
    """Output times: start + k*step up to end (as MATLAB's start:step:end), or `points` evenly. Each time is the
    decimal start + k*step as the scenario wrote them, rounded once (0.1 + 2*0.1 is 0.3, not 0.30000000000000004),
    so that the last is exactly `end` when end falls on the grid; past 2^53 the float formula."""
    if spec.points is not None:
        h = (spec.end - spec.start) / (spec.points - 1)
        grid = spec.start + h * np.arange(spec.points)
        grid[-1] = spec.end
        return grid
    exact = _decimal_grid(spec.start, spec.step, spec.end)
    if exact is not None:
        return exact
    n = int(math.floor((spec.end - spec.start) / spec.step * (1 + 1e-12))) + 1
    return spec.start + spec.step * np.arange(n)


def _decimal_grid(start: float, step: float, end: float) -> np.ndarray | None:
    """start + k*step, k = 0.. while <= end, in exact decimal arithmetic then rounded once; None where the integers
    involved pass 2^53 (a float holds them exactly below that, so one division rounds correctly)."""
    found = _decimal_terms(start, step, end)
    if found is None:
        return None
    first, stride, den, n = found
    return (first + stride * np.arange(n, dtype=np.int64)).astype(float) / den


@functools.lru_cache(maxsize=256)
def _decimal_terms(start: float, step: float, end: float) -> tuple[int, int, int, int] | None:
    """The grid's integers (first numerator, stride, common denominator, count), once per [time] table: a fit or a
    sensitivity asks for the same grid at every trial, and the decimal arithmetic is most of a small grid's cost."""
    from fractions import Fraction

    a, h, b = (Fraction(repr(float(x))) for x in (start, step, end))
    n = math.floor((b - a) / h) + 1
    den = math.lcm(a.denominator, h.denominator)
    first, stride = a.numerator * (den // a.denominator), h.numerator * (den // h.denominator)
    if max(abs(first), abs(first + stride * (n - 1)), den) >= 2**53:
        return None
    return first, stride, den, n
