"""The exact flow of a linear mode with constant forcing, z' = A z + b: z(t) = E(t) z + Phi(t) b from one matrix
exponential of [[A, I], [0, 0]] t, cached by step, and Gauss-Legendre nodes on it for the energy integrals. Steps of
their own length (to an event, to a target) and event location take the flow's Taylor polynomial instead where it is
good to rounding (omega h <= 2): a few microseconds a value where an exponential takes tens, a record's modes having
no eigenvectors to step with (its generators' block is nilpotent).

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

GAUSS_POINTS = 8
# A guard's value along a step as a polynomial in tau (the flow's Taylor series), for event location: so many terms
# that where the step's omega h is at most SERIES_REACH the dropped ones are far below rounding (2^31 / 31!)
SERIES_TERMS = 30
SERIES_REACH = 2.0
SPECTRAL_CONDITION = 1e4  # eigenvector condition up to which arbitrary steps are taken from the eigenvectors
_LEGENDRE = np.polynomial.legendre.leggauss(GAUSS_POINTS)
NODES, WEIGHTS = (_LEGENDRE[0] + 1) / 2, _LEGENDRE[1] / 2  # Gauss-Legendre on [0, 1]


class Flow:
    """exp([[A, I], [0, 0]] t) of a mode's A: z(t) = E z + Phi b, cached by step; shared by the modes with one A."""

    def __init__(self, A: np.ndarray):
        s = len(A)
        self.s = s
        self.big = np.zeros((2 * s, 2 * s))
        self.big[:s, :s] = A
        self.big[:s, s:] = np.eye(s)
        self.cache: dict[float, tuple[np.ndarray, np.ndarray]] = {}
        self._series_powers = None
        self.nodes: dict[float, tuple[np.ndarray, np.ndarray]] = {}
        self.doublings: dict[float, list[np.ndarray]] = {}
        values, vectors = np.linalg.eig(A) if s else (np.zeros(0), np.zeros((0, 0)))
        self.omega = float(np.abs(values).max(initial=0.0))
        # The eigenvectors serve the arbitrary steps of event location (a few microseconds each, not an
        # exponential's hundred): where they are well conditioned, to within SPECTRAL_CONDITION eps
        self.spectral = None
        if s and np.linalg.cond(vectors) < SPECTRAL_CONDITION:
            self.spectral = (values, vectors, np.linalg.inv(vectors))

    def operators(self, h: float, keep: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """(E(h), Phi(h)): cached steps by the exponential, the rest from the eigenvectors where they serve."""
        if h in self.cache:
            return self.cache[h]
        if not keep and self.spectral is not None:
            values, vectors, inverse = self.spectral
            growth = np.exp(values * h)
            small = np.abs(values * h) < 1e-8  # (e^(l h) - 1) / l, to rounding where l h is tiny
            integral = np.where(small, h * (1 + 0.5 * values * h), (growth - 1) / np.where(small, 1.0, values))
            return ((vectors * growth) @ inverse).real, ((vectors * integral) @ inverse).real
        from scipy.linalg import expm

        s = self.s
        full = expm(self.big * h)
        pair = (full[:s, :s], full[:s, s:])
        if keep:
            self.cache[h] = pair
        return pair

    def doubling(self, h: float, count: int) -> list[np.ndarray]:
        """E(h)^(2^j) for 2^j < count (E(h) a kept step): the step's powers that take a batch of steps by doubling."""
        powers = self.doublings.setdefault(h, [self.operators(h, keep=True)[0]])
        while 2 ** len(powers) < count:
            powers.append(powers[-1] @ powers[-1])
        return powers

    def stepped(self, z: np.ndarray, b: np.ndarray, h: float, count: int) -> np.ndarray:
        """z after 0, 1, .., count steps of h, (count + 1, s), by doubling (doubled's)."""
        Z = np.empty((count + 1, len(z)))
        Z[0] = z
        for _ in self.doubled(Z, b, h):
            pass
        return Z

    def doubled(self, Z: np.ndarray, b: np.ndarray, h: float) -> Iterator[int]:
        """Z[1:] filled with the steps of h from Z[0] by doubling: steps d+1 .. 2d are E^d times steps 1 .. d plus
        the forcing's sum over d steps (a product a doubling, not a Python step a sample); yields how many steps are
        done after each product (so that a caller may check them and stop early)."""
        count = len(Z) - 1
        if count < 1:
            return
        E, Phi = self.operators(h, keep=True)
        forced = Phi @ b  # the sum of E^i (Phi b) over i < done
        Z[1] = E @ Z[0] + forced
        done = 1
        yield done
        for power in self.doubling(h, count):
            if done >= count:
                return
            stop = min(2 * done, count)
            Z[done + 1:stop + 1] = Z[1:stop - done + 1] @ power.T + forced
            forced = power @ forced + forced
            done = stop
            yield done

    def at(self, z: np.ndarray, b: np.ndarray, h: float, keep: bool = False) -> np.ndarray:
        """z after h."""
        if h == 0:
            return z.copy()
        if not keep and h not in self.cache:  # a step of its own length (to an event, a target): its series
            series = self.state_series(z, b, h)
            if series is not None:
                return h ** np.arange(SERIES_TERMS + 1) @ series
        E, Phi = self.operators(h, keep)
        return E @ z + Phi @ b

    def gauss_states(self, Z0: np.ndarray, b: np.ndarray, h: float, keep: bool) -> np.ndarray:
        """The flow from each row of Z0 (m, s) at the Gauss-Legendre nodes of [0, h]: (m, GAUSS_POINTS, s); a single
        state's on a step not kept from its Taylor polynomial where that is good to rounding (eight exponentials
        otherwise: a step cut short by an event)."""
        if len(Z0) == 1 and not keep:
            series = self.state_series(Z0[0], b, h)
            if series is not None:
                return (np.vander(NODES * h, SERIES_TERMS + 1, increasing=True) @ series)[None]
        by_state, Phi = self.gauss_operators(h, keep)
        return (Z0 @ by_state).reshape(len(Z0), GAUSS_POINTS, self.s) + (Phi @ b)[None]

    def gauss_operators(self, h: float, keep: bool) -> tuple[np.ndarray, np.ndarray]:
        """The flow's operators at the Gauss-Legendre nodes of [0, h]: E side by side as (s, GAUSS_POINTS s), so
        that Z0 @ it holds every node's state of every row of Z0 (one product), and Phi (GAUSS_POINTS, s, s)."""
        if keep and h in self.nodes:
            return self.nodes[h]
        pairs = [self.operators(h * c) for c in NODES]
        by_state = np.ascontiguousarray(np.stack([p[0] for p in pairs]).transpose(2, 0, 1).reshape(self.s, -1))
        found = by_state, np.stack([p[1] for p in pairs])
        if keep:
            self.nodes[h] = found
        return found

    @property
    def series_powers(self) -> np.ndarray:
        """A^k / (k + 1)!, k < SERIES_TERMS, (SERIES_TERMS, s, s): z(tau) = z + sum_k tau^(k+1) A^k / (k + 1)! (A z + b)
        on the flow of z' = A z + b."""
        if self._series_powers is None:
            A = self.big[:self.s, :self.s]
            powers = np.empty((SERIES_TERMS, self.s, self.s))
            powers[0] = np.eye(self.s)
            for k in range(1, SERIES_TERMS):
                powers[k] = powers[k - 1] @ A / (k + 1)
            self._series_powers = powers
        return self._series_powers

    def _taylor(self, z: np.ndarray, b: np.ndarray, h: float) -> np.ndarray | None:
        """Coefficients c_k (SERIES_TERMS + 1, s) of z(tau) = sum c_k tau^k from z, or None where omega h is past
        SERIES_REACH (whether they are good to rounding on [0, h] is the caller's to judge: good_to_rounding)."""
        if self.omega * h > SERIES_REACH:
            return None
        return np.concatenate([z[None], self.series_powers @ (self.big[:self.s, :self.s] @ z + b)])

    def state_series(self, z: np.ndarray, b: np.ndarray, h: float) -> np.ndarray | None:
        """Coefficients c_k (SERIES_TERMS + 1, s) of z(tau) = sum c_k tau^k on [0, h], or None where they are no good
        to rounding there: omega h past SERIES_REACH, or good_to_rounding's tests against the state's size."""
        series = self._taylor(z, b, h)
        if series is None or not _state_good(series, z, b, h):
            return None
        return series

    def guard_polynomial(self, z: np.ndarray, b: np.ndarray, row: np.ndarray, const: float, h: float):
        """row z(tau) + const on [0, h] as a function of tau: the flow's Taylor polynomial (a few microseconds a
        value, where the exponential takes tens), or None where it is no good to rounding there: omega h past
        SERIES_REACH, or good_to_rounding's tests failing both against the guard's own rounding (64 ulps of
        row |z| + |const|, modes.at_level) and against the state's (state_series: then the polynomial is what `at`
        steps to each tau, a ball's height while it flies fast)."""
        series = self._taylor(z, b, h)
        if series is None:
            return None
        coefficients = series @ row
        coefficients[0] += const
        if not good_to_rounding(np.abs(coefficients), h, float(np.abs(row) @ np.abs(z)) + abs(const)) and \
                not _state_good(series, z, b, h):
            return None
        highest_first = coefficients[::-1].tolist()

        def value(tau: float) -> float:
            total = 0.0
            for c in highest_first:
                total = total * tau + c
            return total

        return value


def _state_good(series: np.ndarray, z: np.ndarray, b: np.ndarray, h: float) -> bool:
    """good_to_rounding of a state's Taylor series against the state's own size on [0, h]."""
    return good_to_rounding(np.abs(series).max(axis=1), h, np.abs(z).max() + np.abs(b).max() * h)


def good_to_rounding(sizes: np.ndarray, h: float, scale: float) -> bool:
    """Whether a Taylor series whose coefficients are this large (by order) is good to rounding on [0, h]: its last
    terms below 1e-18 of its largest there, and the rounding of their sum within 64 ulps of `scale`."""
    terms = sizes * h ** np.arange(len(sizes))
    return terms[-3:].max() <= 1e-18 * terms.max() and terms.sum() <= 64 * scale
