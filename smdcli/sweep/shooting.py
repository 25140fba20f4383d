"""A periodic steady state by shooting: Newton on the one-period map with the monodromy matrix, accepted
only when its Floquet multipliers are inside the unit circle; one sweep direction per task.

Must not import: io, plots, commands, cli."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from smdcli.model import Model, build
from smdcli.scenario import Scenario
from smdcli.sweep.pool import _tick

PERIOD_SAMPLES = 256
MAX_PERIODS = 600
STEADY_RTOL = 1e-8
MEASURED_ACCURACY = 10 * STEADY_RTOL  # a measured amplitude or phase: the steady state's tolerance, with margin
NEWTON_ITERATIONS = 8
WARMUP = 20  # periods integrated between Newton attempts


def _one_period(model: Model, y: np.ndarray, period: float, variational: bool):
    """Integrate one forcing period from state y at t = 0 (compiled DOP853, rtol 1e-10), with the monodromy
    matrix if asked: (final state, monodromy or None, the state at PERIOD_SAMPLES even times over the period)."""
    from smdcli.kernels.tableaus import DOP853
    from smdcli.solvers.integrators.compiled import run_kernel, warm

    warm()
    m = len(y)
    start = np.concatenate([y, np.eye(m).ravel()]) if variational else y
    scale = max(np.abs(y).max(), 1e-6)
    atol = np.full(len(start), 1e-13 * scale)
    if variational:
        atol[m:] = 1e-12
    grid = period * np.arange(PERIOD_SAMPLES + 1) / PERIOD_SAMPLES
    _, out, _, _ = run_kernel(model, DOP853, grid, start, 1e-10, atol, 10**7, np.inf)
    end = out[-1]
    return end[:m], (end[m:].reshape(m, m) if variational else None), out[:-1, :m]


def _steady_state(model: Model, y: np.ndarray, period: float) -> tuple[np.ndarray, bool, np.ndarray]:
    """A stable periodic state of the forced scene near y, and the states sampled over its last period.

    Newton's method on the period map (shooting, with the monodromy matrix from the variational
    equation) reaches a periodic orbit in a few periods; it is kept only if its Floquet multipliers
    lie inside the unit circle, or on it for an undamped scene (an unstable orbit, the middle branch
    of a jump, is not what a test rig would show). Otherwise the scene is integrated for WARMUP
    periods, as a rig would settle, and Newton tries again from there; at most MAX_PERIODS in all.
    """
    scale = lambda v: max(np.abs(v).max(), 1e-12)  # noqa: E731
    spent = 0
    while spent < MAX_PERIODS:
        guess = y.copy()
        for _ in range(NEWTON_ITERATIONS):
            end, monodromy, samples = _one_period(model, guess, period, variational=True)
            spent += 1
            residual = end - guess
            if np.abs(residual).max() <= STEADY_RTOL * scale(end):
                if np.abs(np.linalg.eigvals(monodromy)).max() < 1.0 + 1e-6:
                    return end, True, samples
                break
            try:
                step = np.linalg.solve(monodromy - np.eye(len(guess)), residual)
            except np.linalg.LinAlgError:
                break
            # A Newton step larger than the motion itself leaves the basin; on a stiffening spring it can
            # also make one period cost millions of steps. Settle by integration instead.
            if not np.all(np.isfinite(step)) or np.abs(step).max() > 2 * max(scale(y), scale(end)):
                break
            guess = guess - step
        for _ in range(WARMUP):
            previous = y
            y, _, samples = _one_period(model, y, period, variational=False)
            spent += 1
            if np.abs(y - previous).max() <= STEADY_RTOL * scale(y):
                return y, True, samples
    return y, False, samples


def _measure_direction(args: tuple[Scenario, np.ndarray, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Worker: step a sine force through the frequencies in the order given, each from the last one's final state.

    At each frequency the steady state is found (see _steady_state); amplitude is (max - min) / 2
    of x over that whole period per unit force amplitude, and the phase lag is the fundamental's.
    """
    from smdcli.shapes import build_signal

    sc, omega, force_index = args
    base = build(sc).dense()
    amplitude = np.full((len(omega), len(sc.dof_names)), np.nan)
    lag = np.full_like(amplitude, np.nan)
    steady = np.zeros(len(omega), bool)
    y = None
    for f, w in enumerate(omega):
        if w <= 0:
            _tick()
            continue
        signals = list(base.signals)
        signals[force_index] = build_signal(replace(sc.forces[force_index], omega=float(w)))
        model = replace(base, signals=tuple(signals))
        n = model.n
        if y is None:
            y = np.concatenate([model.x0, model.v0])
        period = 2 * math.pi / w
        f0 = abs(sc.forces[force_index].amplitude) or 1.0
        y, steady[f], samples = _steady_state(model, y, period)
        ts = period * np.arange(PERIOD_SAMPLES) / PERIOD_SAMPLES
        xs = samples[:, :n]
        amplitude[f] = (_refined_extreme(xs, +1) - _refined_extreme(xs, -1)) / 2 / f0
        rotation = np.exp(-1j * w * ts)
        x1 = xs.T @ rotation
        u1 = model.signals[force_index].value(ts) @ rotation
        lag[f] = np.mod(np.angle(u1) - np.angle(x1) + np.pi / 2, 2 * np.pi) - np.pi / 2
        _tick()
    return amplitude, lag, steady


def _refined_extreme(samples: np.ndarray, sign: int) -> np.ndarray:
    """Max (sign +1) or min (-1) per column of periodic samples, refined by a parabola through the top three."""
    values = sign * samples
    i = np.argmax(values, axis=0)
    cols = np.arange(values.shape[1])
    a, b, c = values[i - 1, cols], values[i, cols], values[(i + 1) % len(values), cols]
    denom = a - 2 * b + c
    with np.errstate(divide="ignore", invalid="ignore"):
        top = np.where(denom < 0, b - (a - c) ** 2 / (8 * denom), b)
    return sign * top
