"""`smd fit`'s guards against a fit that stalls or settles wrong: the growing spans of the data over which a fit that
stalls over the whole record is taken again, and the judgement of what a fit leaves of the data (how much, and whether
it is noise or a misfit smooth in time); a start where the response has no derivative.

Must not import: io, plots, commands, cli.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from smdcli.analysis.fit_data import Test
from smdcli.errors import UsageError

# the fraction of the data's weighted RMS a fitted scene may leave unexplained before the fit says it does not explain
# them (a local minimum, or a model that cannot make the data), whatever its residual's shape: measurement noise
# leaves a few percent (the stick-slip belt from a kinetic force 30 % off, over the whole record at once, settled in
# pure slip and left 99 %)
UNEXPLAINED = 0.1
# What a fit leaves is no noise where its residual is smooth in time: its lag-one correlation along each channel,
# pooled, past SYSTEMATIC (white noise's is within a few 1 / sqrt(samples) of 0; a misfit's near 1). Leaving more than
# RESOLVED (the model's own accuracy) so, a fit is taken again over growing spans; more than MISFIT, it says so. A
# Coulomb and viscous free decay started 10 % off in its friction force stopped at 0.597 N for 0.452 N and c at a
# quarter of the truth, one stick-slip event short, leaving 5.4 % unexplained, lag-one correlation 1.0: "converged"
SYSTEMATIC, RESOLVED, MISFIT = 0.5, 1e-6, 0.01


# A fit over the whole record at once has stalled where its last STALL_ITERATIONS iterations took less than STALL_DROP
# off its cost while it leaves more than UNEXPLAINED of the data: the free decay's valley (its cost from 1.7e3 to
# 1.2e3 over 80 iterations, 80 % of the data unexplained), where its half of the evaluations was spent before the
# growing spans began (65 solves; 28 where it stops as it stalls). A fit stopped so that was in fact descending is
# taken over the growing spans from the start, and the lower cost of the two is written
STALL_ITERATIONS, STALL_DROP = 5, 0.2


def stalled_descent(costs: list[float], unexplained: float) -> bool:
    """Whether a fit whose costs at its accepted points are these, leaving this share of the data unexplained, has
    stalled: the last STALL_ITERATIONS took less than STALL_DROP off its cost, and it leaves more than UNEXPLAINED."""
    return len(costs) > STALL_ITERATIONS and unexplained > UNEXPLAINED and \
        costs[-1] > (1 - STALL_DROP) * costs[-1 - STALL_ITERATIONS]


class NoDerivative(Exception):
    """A fit's start where the response has no derivative: why (the sensitivities' notes), the span of the data
    before the first sample without one (from its test's start), and which samples those are."""

    def __init__(self, why: str, span: float, samples: str):
        super().__init__(why)
        self.why, self.span, self.samples = why, span, samples


def refusal(exc: NoDerivative) -> UsageError:
    """A fit that cannot go on without the derivative at its start: what to change."""
    return UsageError(f"{exc.why}; a fit needs the derivatives at its start: start elsewhere, or leave {exc.samples} "
                      "out")


ALTERNATIONS = 3  # swings of the busiest channel across its mean that the first of growing_spans holds
SPAN_TOLERANCE = 1e-6  # a span short of the whole data is a start for the next: no need to meet TOLERANCE on it


def growing_spans(tests: list[Test], count: int) -> list[float | None]:
    """The spans of the data (seconds from each test's start) over which a fit that stalls on the whole is taken
    again, each from the last one's estimate, the last the whole (None): the first holds ALTERNATIONS swings of the
    channel that swings soonest (across a band of a tenth of its RMS about its mean), at most an eighth of the
    longest test, and more samples than twice the parameters; each next twice the last. Empty where the data hold
    too few samples for a shorter span.

    A free oscillation's phase drifts with a frequency's error over the whole record (a free decay's 32 cycles with
    the stiffness 5 % off: a valley of the cost where added damping hides the drift, and the fit crawls along it);
    over a cycle and a half the drift is less than half a cycle, and each doubling starts within its own cycle. A
    mode too small to swing a channel drifts all the same (a 2-DOF's free vibration over 2 s, its slow mode swinging
    every 0.69 s: of 12 starts up to 50 % off, 8 stopped with over a third of the data unexplained; from an eighth
    of the record, all 12 found the truth)."""
    first, longest = math.inf, 0.0
    for test in tests:
        t, begin = test.measured.time, float(test.grid[0])
        longest = max(longest, float(t[-1]) - begin)
        for channel in test.channels:
            y = test.measured.channels[channel] - test.measured.channels[channel].mean()
            band = 0.1 * float(np.sqrt(np.mean(y ** 2)))
            side = np.sign(y) * (np.abs(y) > band)
            outside = np.flatnonzero(side)
            swings = outside[1:][side[outside[1:]] != side[outside[:-1]]]
            if len(swings) >= ALTERNATIONS:
                first = min(first, float(t[swings[ALTERNATIONS - 1]]) - begin)
    first = min(first, longest / 8)
    while first < longest and sum(int(np.count_nonzero(test.measured.time <= test.grid[0] + first)) *
                                  len(test.channels) for test in tests) <= 2 * count:
        first *= 2
    if not first < longest / 2:
        return []
    spans: list[float | None] = []
    while first < longest:
        spans.append(first)
        first *= 2
    return spans + [None]


def within(test: Test, span: float | None) -> Test | None:
    """The test's data no later than span after its start (None: all of them); None where that holds no sample."""
    if span is None:
        return test
    kept = int(np.searchsorted(test.measured.time, test.grid[0] + span, side="right"))
    if kept == 0:
        return None
    measured = dataclasses.replace(test.measured, time=test.measured.time[:kept],
                                   channels={c: v[:kept] for c, v in test.measured.channels.items()})
    return dataclasses.replace(test, measured=measured, grid=test.grid[:test.rows[kept - 1] + 1],
                               rows=test.rows[:kept])


def misfit(tests: list[Test], r: np.ndarray, floor: float) -> str:
    """What a fit at residuals r leaves of the data ("30 % of the data's weighted RMS unexplained"), where it leaves
    more than UNEXPLAINED, or more than floor and smooth in time (not noise: SYSTEMATIC); else empty."""
    unexplained = unexplained_share(tests, r)
    if unexplained > UNEXPLAINED:
        return f"{100 * unexplained:.0f} % of the data's weighted RMS unexplained"
    if unexplained > floor and (correlation := lag_one(tests, r)) > SYSTEMATIC:
        return (f"{100 * unexplained:.2g} % of the data's weighted RMS unexplained, and no noise: smooth in "
                f"time (its lag-one correlation {correlation:.2f})")
    return ""


def lag_one(tests: list[Test], r: np.ndarray) -> float:
    """The residual's lag-one correlation along each channel's samples, pooled (r holds each test's channels in turn,
    as the fit's residuals do)."""
    products = squares = 0.0
    first = 0
    for test in tests:
        for _ in test.channels:
            piece = r[first:first + len(test.rows)]
            first += len(test.rows)
            products += float(piece[1:] @ piece[:-1])
            squares += float(piece @ piece)
    return products / squares if squares > 0 else 0.0


def unexplained_share(tests: list[Test], r: np.ndarray) -> float:
    """|weighted residual| / |weighted data|: what the scene leaves of the data unexplained."""
    data = np.concatenate([w * test.measured.channels[c] for test in tests
                           for w, c in zip(test.weights, test.channels)])
    return float(np.linalg.norm(r) / max(float(np.linalg.norm(data)), 1e-300))
