"""Linear scenes driven by tabulated forces (a record, a first-order hold) whose samples and output points fall on
one uniform grid of knots: the exact recurrence from knot to knot, taken in blocks.

Between two knots every force is linear in time (a table's first-order hold) or constant (its previous-value hold),
so one step is exact: y_(k+1) = E y_k + G w_k, with E and G from one exponential of the augmented system (linear.py;
for modal.py each mode's own) and w_k = (value, slope) each table's right limit at knot k. The dense and modal paths
reseed w at every breakpoint, one Python step per sample (15 ms for 2,001 samples of a 3-DOF frame, 78 ms to
integrate a 4,001-sample record to the ground's displacement); here the steps run J at a time across all blocks at
once (the forced part of each block), the blocks' starts one after another, and each block's free part as one
product with the stacked powers E^j: about 2 sqrt(steps) Python steps. The rounding is the dense path's: powers up
to E^J, a restart every block.

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from smdcli.model import Model
from smdcli.shapes.table import Table
from smdcli.solvers.exact.accurate_expm import flush_negligible, propagator
from smdcli.solvers.base import stated_rounding
from smdcli.text import plural

BLOCK = 64  # steps a block takes at most
# Seconds per Python-level product of the blocks' loops and per flop of a small product (2-core machine): they only
# set the block length, which trades J products for the powers and J for each block's forced part against
# steps / J for the blocks' starts
PRODUCT_S, _FLOP_S = 5e-6, 2.5e-10
CHUNK_ENTRIES = 1 << 21  # states (systems x state size) a chunk of steps holds: 16 MB an array


class Knots(NamedTuple):
    """An even grid of knots holding the output points and the tables' samples."""

    times: np.ndarray
    read_at: np.ndarray  # the times just after which the forces are read at each knot
    rows: np.ndarray  # where the output points are among the knots
    step: float


def uniform_knots(model: Model, grid: np.ndarray) -> Knots | None:
    """The output points and the tables' samples between them, where every force is a table and they are evenly
    spaced; else None. A sample within rounding of an output point is that point, the forces read at the later of
    the two: a previous-value hold's new value, a first-order hold's new slope."""
    if not model.signals or not all(isinstance(s, Table) for s in model.signals):
        return None
    t0, t1 = float(grid[0]), float(grid[-1])
    samples = model.breakpoints(t0, t1)
    same = 8 * np.spacing(max(abs(t0), abs(t1)))  # a sample and an output point apart by the times' rounding
    after = np.clip(np.searchsorted(grid, samples), 1, len(grid) - 1)
    below, above = samples - grid[after - 1], grid[after] - samples
    apart = np.minimum(below, above) > same
    knots = np.union1d(grid, samples[apart])
    if len(knots) < 2:
        return None
    h = (t1 - t0) / (len(knots) - 1)
    if np.abs(np.diff(knots) - h).max() > same:
        return None
    read_at = knots.copy()
    nearest = np.where(below <= above, after - 1, after)[~apart]
    where = np.searchsorted(knots, grid[nearest])
    np.maximum.at(read_at, where, samples[~apart])
    return Knots(knots, read_at, np.searchsorted(knots, grid), h)


def table_states(blocks, times: np.ndarray, offset: int) -> np.ndarray:
    """The signals' generator states just after each time (a table's: value, slope), (len(times), m); blocks:
    (lo, hi, signal) with lo and hi counted from `offset`."""
    w = np.empty((len(times), max((hi for _, hi, _ in blocks), default=offset) - offset))
    for lo, hi, signal in blocks:
        w[:, lo - offset:hi - offset] = signal.exo_states(times)
    return w


def applied(E: np.ndarray, y: np.ndarray) -> np.ndarray:
    """E_p y_p for each system p: E (P, s, s), y (..., P, s). One matrix product for one system; for many small ones
    a multiply-add per state component over all of them (einsum took 2 ms a call on 1,000 modes)."""
    if E.shape[0] == 1:  # one product over every leading axis: a batch of tiny ones costs a call each
        return (y.reshape(-1, y.shape[-1]) @ E[0].T).reshape(y.shape)
    out = y[..., 0, None] * E[:, :, 0]
    for t in range(1, E.shape[2]):
        out += y[..., t, None] * E[:, :, t]
    return out


def block_length(steps: int, systems: int, s: int) -> int:
    """recurrence's J: the fewest seconds for J powers (a product of `systems` s x s matrices each) and 2 J + steps /
    J Python-level products; at most BLOCK. 2,001 steps of a 5-DOF frame: 32 (0.69 ms, 1.17 at 64); of its 20-DOF
    sensitivity system: 16 (2.6 ms, 3.6 at 64)."""
    power = PRODUCT_S + _FLOP_S * 2 * systems * s ** 3
    return int(max(1, min(BLOCK, steps, round(math.sqrt(steps * PRODUCT_S / (PRODUCT_S + power))))))


def recurrence(E: np.ndarray, forced: np.ndarray, start: np.ndarray, rows: np.ndarray,
               flush: bool = False) -> tuple[np.ndarray, int]:
    """y_(k+1) = E y_k + forced_k from y_0 = start for independent systems side by side, at the steps `rows`
    (increasing): (len(rows), P, s), and the longest chain of dependent products (the rounding's count). E (P, s, s),
    or (1, s, s) for all; forced (steps, P, s), start (P, s). Blocks of J steps: the forced part of every block from
    rest, step by step across all blocks at once; the blocks' starts one after another; each block's free part one
    product with E^j. Taken CHUNK_ENTRIES states at a time, so that many systems over many steps need no more.
    flush: E's powers and each block's start flushed of negligible entries (accurate_expm.flush_negligible), as the
    dense path's are: no product meets a subnormal number."""
    steps, P, s = forced.shape
    J = block_length(steps, len(E), s)
    powers = np.empty((J + 1, len(E), s, s))  # one E for every system (a sensitivity's copies): its powers once
    powers[0] = np.eye(s)
    for j in range(J):
        powers[j + 1] = powers[j] @ E
        if flush:
            flush_negligible(powers[j + 1])
    chunk = max(J, CHUNK_ENTRIES // (P * s * J) * J)
    out = np.empty((len(rows), P, s))
    y = np.array(start, dtype=float)
    for first in range(0, max(steps, 1), chunk):
        last = min(steps, first + chunk)
        count = -(-(last - first) // J)
        padded = np.zeros((count * J, P, s))
        padded[:last - first] = forced[first:last]
        padded = padded.reshape(count, J, P, s)
        within = np.zeros((count, J + 1, P, s))  # each block's forced response from rest
        for j in range(J):
            within[:, j + 1] = applied(E, within[:, j]) + padded[:, j]
        starts = np.empty((count + 1, P, s))
        starts[0] = y
        if flush:
            flush_negligible(within)
        for b in range(count):
            starts[b + 1] = applied(powers[J], starts[b]) + within[b, J]
            if flush:
                flush_negligible(starts[b + 1])
        if E.shape[0] == 1:  # one E: one product for all blocks, systems and powers
            free = (starts[:count].reshape(count * P, s) @ powers[:J, 0].transpose(0, 2, 1))  # (J, count P, s)
            states = within[:, :J] + free.reshape(J, count, P, s).transpose(1, 0, 2, 3)
        else:
            states = within[:, :J].copy()
            for j in range(J):
                states[:, j] += applied(powers[j], starts[:count])
        states = states.reshape(count * J, P, s)
        lo = int(np.searchsorted(rows, first))
        hi = len(rows) if last == steps else int(np.searchsorted(rows, last))
        inside = rows[lo:hi] - first
        held = int(np.searchsorted(inside, count * J))  # rows past the chunk's blocks: its end, the next start
        if held and inside[held - 1] - inside[0] == held - 1:  # every step wanted: a slice, not a gather
            out[lo:lo + held] = states[inside[0]:inside[0] + held]
        else:
            out[lo:lo + held] = states[inside[:held]]
        out[lo + held:hi] = starts[count]
        y = starts[count]  # a chunk is whole blocks: its end is the next block's start
    return out, 2 * J + -(-steps // J)


def reseeded_steps(E: np.ndarray, shift: np.ndarray, start: np.ndarray, seeds: np.ndarray,
                   restarted: np.ndarray) -> np.ndarray:
    """The states after 0, 1, .., len(seeds) steps z -> E z + shift from start, the entries `restarted` set to
    seeds[i] after step i (force generators restarted at each of a record's samples; they do not depend on the rest
    of the state): (len(seeds) + 1, size). The rest is one recurrence driven by the restarts (`recurrence`)."""
    size = len(start)
    kept = np.setdiff1d(np.arange(size), restarted)
    before = np.vstack([start[restarted][None], seeds[:-1]])  # the restarted entries at each step's start
    forced = before @ E[np.ix_(kept, restarted)].T + shift[kept]
    rest, _ = recurrence(E[np.ix_(kept, kept)][None], forced[:, None], start[kept][None], np.arange(len(seeds) + 1))
    states = np.empty((len(seeds) + 1, size))
    states[0] = start
    states[1:, kept], states[1:, restarted] = rest[1:, 0], seeds
    return states


def solve_sampled(model: Model, knots: Knots, Aaug: np.ndarray, blocks) -> tuple:
    """x, v (N, n), the stated accuracy and a description; Aaug and blocks: exact.augmented's."""
    states, stated, message = sampled_states(model, knots, Aaug, blocks)
    return states[:, :model.n].copy(), states[:, model.n:].copy(), stated, message


def sampled_states(model: Model, knots: Knots, Aaug: np.ndarray, blocks) -> tuple[np.ndarray, float, str]:
    """The states [x, v] (N, 2n) at the output points, the stated accuracy and a description."""
    n, s, size = model.n, 2 * model.n, Aaug.shape[0]
    steps = len(knots.times) - 1
    step, norm, accurate = propagator(Aaug, knots.step)
    E, G = step[:s, :s], step[:s, s:]
    forced = table_states(blocks, knots.read_at[:-1], s) @ G.T
    states, chain = recurrence(E[None], forced[:, None], np.concatenate([model.x0, model.v0])[None], knots.rows)
    stated = stated_rounding(steps + chain, 1.0 if accurate else norm)  # E's own rounding enters every step
    message = (f"ok: {plural(steps, 'step')} between the tables' samples and the output points, each exact for "
               f"the tables' first-order hold, in blocks of {block_length(steps, 1, s)} (one matrix exponential of "
               f"size {size}{' in double-double, a stiff scene' if accurate else ''})")
    return states[:, 0], stated, message
