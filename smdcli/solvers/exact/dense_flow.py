"""The exact solver's dense path: its flow over a uniform grid's step (the step's propagator and its powers, stacked)
and what it costs, estimated: how it is chosen against the sparse action (action.py) and a sensitivity system's
arrow (arrow.py), and how many powers it stacks.

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math

import numpy as np

from smdcli.model import Model
from smdcli.solvers.exact.accurate_expm import flush_negligible, propagator
from smdcli.solvers.exact.sampled import BLOCK, PRODUCT_S

_POWERS_BYTES = 64 * 2**20
# Seconds per flop of a dense matrix product and per entry of a matrix-vector product (memory-bound), on a 2-core
# machine: they only decide between this path and the sparse action (action.py), whose cost is on the same scale, and
# how many of the step's powers the dense path stacks.
DENSE_FLOP_S, DENSE_ENTRY_S = 2e-11, 3e-10


def dense_cost(model: Model, grid: np.ndarray) -> float:
    """Estimated seconds of the dense path: expm (about 16 size^3 flops), the J stacked powers of the propagator,
    and a pass over the propagator per output step."""
    size = 2 * model.n + sum(s.exo().S.shape[0] for s in model.signals)
    J = stacked_powers(size, len(grid), 3 * model.n)
    return (16 + 2 * J) * size**3 * DENSE_FLOP_S + len(grid) * size**2 * DENSE_ENTRY_S


def stacked_powers(size: int, N: int, rows: int = 0) -> int:
    """How many powers of the step's propagator are stacked: the fewest seconds for J powers (each also multiplied by
    the `rows` read) and N / J blocks' starts (a product with the state each), at most BLOCK and 64 MB. A 60-mass
    chain's sensitivity system (size 242, 360 rows read) takes 4, not 64: its 64 powers were 90 % of its solve."""
    power = PRODUCT_S + 2 * (size ** 3 + rows * size ** 2) * DENSE_FLOP_S
    start = PRODUCT_S + size ** 2 * DENSE_ENTRY_S
    best = round(math.sqrt(max(N - 1, 1) * start / power))
    return max(1, min(BLOCK, N - 1, best, _POWERS_BYTES // (8 * size * size)))


class PowersFlow:
    """The dense path's flow over a uniform grid's step h (linear.propagate's; its other: arrow.ArrowFlow): the
    step's propagator to the powers 1 .. J, stacked. growth: the norm the exponential was squared from; accurate:
    whether it took double-double."""

    order = None  # the state in linear.augmented's order

    def __init__(self, Aaug: np.ndarray, h: float, N: int, rows: int, generators: slice):
        self.Aaug, self.generators = Aaug, generators
        self.J = J = stacked_powers(len(Aaug), N, rows)
        self._cache: dict[float, np.ndarray] = {}
        step, self.growth, self.accurate = propagator(Aaug, h)
        self._cache[h] = step
        self.powers = np.empty((J, len(Aaug), len(Aaug)))
        if N > 1:
            self.powers[0] = step
            done = 1
            while done < J:  # by doubling: powers done+1 .. 2 done are powers 1 .. done times the done-th
                more = min(done, J - done)
                np.matmul(self.powers[:more], self.powers[done - 1], out=self.powers[done:done + more])
                done += more
            flush_negligible(self.powers)

    def step(self, z: np.ndarray, count: int) -> np.ndarray:
        """z after count steps of h (1 <= count <= J)."""
        return self.powers[count - 1] @ z

    def advance(self, z: np.ndarray, dt: float) -> np.ndarray:
        """z after dt."""
        if dt not in self._cache:
            self._cache[dt] = propagator(self.Aaug, dt)[0]
        return self._cache[dt] @ z

    def tables(self, rows: np.ndarray) -> np.ndarray:
        """rows (r, size) times the powers 1 .. J: (J, r, size) (both flushed of negligible entries: no product meets
        a subnormal number)."""
        return np.matmul(rows, self.powers)

    @property
    def exponentials(self) -> int:
        """How many exponentials were taken."""
        return len(self._cache)
