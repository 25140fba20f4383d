"""Whole output steps of the exact event-driven solver taken together (piecewise.py's batches): until the first
that may hold an event, by doubling (steps d+1 .. 2d are E^d times steps 1 .. d plus the forcing's sum, one product a
doubling), every guard checked on a doubling's steps at once. A step where a guard below its level turns back is one
only where its top reaches the level (a yield surface's every oscillation peak otherwise ended a batch: 450 batches
instead of 137 for the 42 events of a 4,001-sample elastoplastic record, twice the time). A record's kinks, where the
force generators restart, are stepped one by one (in chunks checked together).

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math
from functools import cached_property

import numpy as np

from smdcli.solvers.exact.flow import GAUSS_POINTS, Flow
from smdcli.solvers.events.scene import Mode, at_level
from smdcli.solvers.events.record import step_integrals

BATCH_VALUES = 2 ** 21  # Gauss-node state values (16 MB) of the output steps taken together where no event interrupts
BATCH_STEPS = (256, 8192)  # the fewest and most steps a batch takes (whole powers of two), whatever the scene's size
CHUNK = 16  # steps across a kink checked for events together
# doubled steps checked for events together: checks of 1, 2, 4 and 8 steps cost more than the products they spare
# when an event comes early (a vibro-impact's 96 events in 5,001 steps: 7.4 checks a batch, 40 us each)
CHECKED_TOGETHER = 32


class Batches:
    """The batches of PiecewiseRun (which holds the grid, the scene and the running energy integrals)."""

    guarded_step = -1  # the output step a batch stopped before, where a guard may end the mode

    @cached_property
    def batch_steps(self) -> int:
        """The most output steps a batch takes: BATCH_VALUES Gauss-node values of the scene's state, within
        BATCH_STEPS."""
        fewest, most = BATCH_STEPS
        return min(most, max(fewest, 2 ** int(math.log2(BATCH_VALUES / (GAUSS_POINTS * self.scene.size)))))

    def kink_slack(self, size: np.ndarray, const: np.ndarray) -> np.ndarray:
        """How near its level a guard's value at a kink of the force ends a batch (size: the terms it sums): its
        rounding."""
        return at_level(size, const)

    def batch(self, flow: Flow, mode: Mode, states, z: np.ndarray, t: float, k: int, breaks, b_next: int,
              h_out: float, outputs):
        """Up to self.batch_steps output steps of h_out from (t, z) in this mode, stopped before the first step where a guard
        crosses or may touch (the step-by-step path takes that one): (z, t, k) after them, or None for none. Without
        a kink to reseed the generators at, the steps are taken by doubling (steps d+1 .. 2d are E^d times steps
        1 .. d plus the forcing's sum: a product for each doubling, not a Python step for each sample), and checked
        for events CHECKED_TOGETHER steps and then a doubling at a time, so that an event near the start wastes
        little."""
        grid = self.grid
        if abs(grid[k] - t - h_out) > 1e-9 * h_out or k == self.guarded_step:
            return None  # after an event, a step of its own; or the step a batch just stopped before
        ahead = grid[k:min(self.N, k + self.batch_steps)]
        # A force's kink on an output point (a record's sample) is taken in stride; any other break ends the batch.
        times, jumps = self.break_times, self.break_jumps
        within = slice(b_next, int(np.searchsorted(times, ahead[-1], side="right")))
        at = np.searchsorted(ahead, times[within])
        in_stride = (ahead[np.minimum(at, len(ahead) - 1)] == times[within]) & ~jumps[within]
        first = int(np.argmin(in_stride)) if not in_stride.all() else len(at)
        stop = float(times[within][first]) if first < len(at) else math.inf
        reseed = set(at[:first].tolist())
        whole = ahead < stop
        whole[1:] &= self.whole_steps[k:k + len(ahead) - 1]
        count = int(np.argmin(whole)) if not whole.all() else len(ahead)
        if count < 1:
            return None
        E, Phi = flow.operators(h_out, keep=True)
        shift = Phi @ mode.b
        Z = np.empty((count + 1, len(z)))  # each step's start (after a kink's reseeding)
        Z[0] = z
        # each step's end, as the flow left it: the next step's start but where a kink reseeds the generators
        ends = np.empty((count, len(z))) if reseed else Z[1:]
        # the generators restart at each kink (their states read at all at once): the step after it runs on the next
        # segment
        seeds = [(lo, hi, signal.exo_states(ahead[:count])) for lo, hi, signal, _ in self.scene.blocks] if reseed \
            else []
        clear, done = count, 0  # steps before the first that a guard may end; steps taken
        jumped_to = set()  # steps whose start a force's jump put past a guard's level (a stuck contact's breakaway)
        doubled = None if reseed else flow.doubled(Z, mode.b, h_out)
        while done < clear:  # in chunks, so that an event near the start wastes little
            if reseed:
                chunk = range(done, min(done + CHUNK, count))
                for i in chunk:
                    ends[i] = Z[i + 1] = E @ Z[i] + shift
                    if i in reseed:
                        for lo, hi, states_at in seeds:
                            Z[i + 1, lo:hi] = states_at[i]
            else:  # doublings until CHECKED_TOGETHER steps are new: a product is cheaper than a check
                start = done
                for done in doubled:
                    if done - start >= CHECKED_TOGETHER:
                        break
                chunk = range(start, done)
            starts, stops = Z[chunk.start:chunk.stop], ends[chunk.start:chunk.stop]
            if mode.guards:
                rows, consts, abs_rows = mode.guard_table
                # each guard's value and rate (columns, signed) at the steps' starts and ends; by doubling, the ends
                # are the next starts: one product for both
                if reseed:
                    at_starts, at_ends = starts @ rows.T + consts, stops @ rows.T + consts
                else:
                    values = Z[chunk.start:chunk.stop + 1] @ rows.T + consts
                    at_starts, at_ends = values[:-1], values[1:]
                n_guards = len(mode.guards)
                g0, slope0 = at_starts[:, :n_guards], at_starts[:, n_guards:]
                g1, slope1 = at_ends[:, :n_guards], at_ends[:, n_guards:]
                level = at_level(np.abs(starts) @ abs_rows.T, consts[:n_guards])
                below = g0 <= level  # or at it: it may come back
                if reseed:  # a start past its level, reseeded there: a jump passed it
                    for i in np.flatnonzero((g0 > level).any(axis=1)):
                        if chunk.start + int(i) - 1 in reseed:
                            clear = min(clear, chunk.start + int(i))
                            jumped_to.add(chunk.start + int(i))
                            break
                turning = below & (g1 < 0) & (slope0 > 0) & (slope1 < 0)
                may_end = below & ((g1 >= 0) | turning)
                if reseed:  # a guard at its level where a kink turns the force: the step path decides it there
                    at_kink = np.isin(np.arange(chunk.start, chunk.stop), list(reseed))
                    slack = self.kink_slack(np.abs(stops) @ abs_rows.T, consts[:n_guards])
                    may_end |= below & at_kink[:, None] & (g1 >= -slack)
                for i in np.flatnonzero(may_end.any(axis=1)):  # a turn whose top stays below: no event
                    if chunk.start + int(i) >= clear:
                        break
                    if any(not turning[i, j] or self.turn_may_hold_event(flow, mode, mode.guards[j][1],
                                                                         *mode.guards[j][2:], starts[i], h_out)
                           for j in np.flatnonzero(may_end[i])):
                        clear = chunk.start + int(i)
                        break
            done = chunk.stop
        if clear < count and clear not in jumped_to:
            self.guarded_step = k + clear  # the step path takes it: no batch tries it again
        if clear < 1:
            return None
        gained = step_integrals(self, flow, mode, states, Z[:clear], h_out, True)
        cumulative = {}
        for term in self.energy_terms:
            steps = np.cumsum(gained[term]) if term in gained else np.zeros(clear)
            cumulative[term] = self.cumulative[term] + steps
            self.cumulative[term] = float(cumulative[term][-1])
        outputs.store_many(k, Z[1:clear + 1], states, cumulative, mode)
        z, t = Z[clear].copy(), float(grid[k + clear - 1])
        if clear in jumped_to:  # the modes after the jump, decided at it (cross_break does so off the batch)
            states = self.settle(states, z, t)
            z = self.project(states, z)
            outputs.store(k + clear - 1, z, states)  # the point at the jump: its right limits, in the new modes
        return states, z, t, k + clear
