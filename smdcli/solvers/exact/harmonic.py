"""Harmonic forces superposed in closed form: the steady-state response to each harmonic, plus the free response
from what is left of the initial state.

A force c sin(w t + p) on a linear scene has the periodic response x_p = c Im(X e^(i (w t + p))) with
Z(w) X = b, Z(w) = K - w^2 M + i w C (b the force's column of B). The whole response is x_p plus the solution of
the scene without that force from the initial state less x_p(t0): linear superposition, exact. A Fourier series
of thousands of terms (the book's periodic pulse, a square ground motion) costs a complex solve per term and a
product per output point, where augmenting the state with every harmonic (linear.py) would exponentiate a matrix
of twice as many rows as terms. Used where the harmonics' generators would pass SPLIT_STATES states, and only
where no harmonic sits on an undamped resonance (Z singular): there the augmented exponential stays exact.

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from smdcli.model import Model

SPLIT_STATES = 64  # generator states of harmonic forces from which they are superposed instead of augmented
MAX_CONDITION = 1e10  # of Z(w): beyond, a harmonic is too near an undamped resonance to be solved for alone
BLOCK_VALUES = 2**22  # output times x harmonics evaluated at once (64 MB of complex exponentials)
EPS = float(np.finfo(float).eps)


class Particular:
    """The steady-state displacement and velocity of the superposed harmonics at any times."""

    def __init__(self, w: np.ndarray, p: np.ndarray, X: np.ndarray, condition: float):
        self.w, self.p, self.X = w, p, X  # X: (K, n) complex, amplitude included
        self.condition = condition

    def at(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """x_p and v_p at the times, (N, n) each."""
        times = np.asarray(times, dtype=float)
        n = self.X.shape[1]
        x = np.empty((len(times), n))
        v = np.empty((len(times), n))
        block = max(1, BLOCK_VALUES // max(len(self.w), 1))
        for lo in range(0, len(times), block):
            phase = np.exp(1j * (np.multiply.outer(times[lo:lo + block], self.w) + self.p))  # (b, K)
            x[lo:lo + block] = (phase @ self.X).imag
            v[lo:lo + block] = (phase @ (1j * self.w[:, None] * self.X)).imag
        return x, v

    def accuracy(self, times: np.ndarray) -> float:
        """Relative error of x_p: the solves' (c n eps cond Z) and the phases' (eps w t), summed over terms."""
        largest_phase = float(np.max(np.abs(self.w), initial=0.0)) * float(np.max(np.abs(times), initial=0.0))
        return 8 * EPS * (self.X.shape[1] * self.condition + largest_phase + len(self.w))


def split(model: Model) -> tuple[Model, Particular] | None:
    """The model without its harmonic forces and their steady-state response, where that is cheaper than the
    augmented exponential; None where it is not, or a harmonic is on an undamped resonance."""
    chosen, rows = [], []
    for j, signal in enumerate(model.signals):
        terms = signal.harmonic_terms()
        if terms is not None:
            chosen.append(j)
            rows.append(terms)
    if sum(2 * len(w) for w, _, _ in rows) <= SPLIT_STATES:
        return None
    w = np.concatenate([r[0] for r in rows])
    c = np.concatenate([r[1] for r in rows])
    p = np.concatenate([r[2] for r in rows])
    columns = np.concatenate([np.repeat(model.B[:, [j]].T, len(r[0]), axis=0) for j, r in zip(chosen, rows)])
    Z = model.K[None] - (w**2)[:, None, None] * model.M[None] + 1j * w[:, None, None] * model.C[None]
    with np.errstate(all="ignore"):
        condition = np.linalg.cond(Z)
    worst = float(np.max(condition, initial=1.0))
    if not worst < MAX_CONDITION:
        return None
    X = np.linalg.solve(Z, (columns * c[:, None]).astype(complex)[..., None])[..., 0]
    particular = Particular(w, p, X, worst)
    keep = [j for j in range(len(model.signals)) if j not in chosen]
    reduced = dataclasses.replace(
        model, signals=tuple(model.signals[j] for j in keep), force_dofs=tuple(model.force_dofs[j] for j in keep),
        force_paths=tuple(model.force_paths[j] for j in keep), force_types=tuple(model.force_types[j] for j in keep),
        inputs=None if model.inputs is None else model.inputs[:, keep],
        ground_inputs=None if model.ground_inputs is None else model.ground_inputs[:, keep])
    return reduced, particular


def from_rest_less(model: Model, particular: Particular, t0: float) -> Model:
    """The reduced model started from its initial state less the particular response there."""
    x, v = particular.at(np.array([t0]))
    return dataclasses.replace(model, x0=model.x0 - x[0], v0=model.v0 - v[0])
