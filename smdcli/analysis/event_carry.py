"""The event-to-event sensitivity run's S = dz/dp between its checkpoints: carried on a checkpoint's exact flow to
any time, the force generators (and their sensitivities) restarted at each break, and read at the output points
after the run.

A record restarts its generators at every sample, so that [z; S] jumps in its generator entries there; between
two samples it is z -> E z + Phi b. The rest of the state (displacements, velocities and their sensitivities) is
then one linear recurrence driven by the generators' known restarts (sampled.reseeded_steps): blocks of steps in a
few products, not a Python step a sample (2,000 samples of a 1-DOF record carried twice, once to each event and
once to the outputs, were 1.4 times the forward run's whole cost).

Must not import: io, plots, commands, cli.
"""

from __future__ import annotations

import numpy as np

from smdcli.analysis.event_edges import across_ground_jump
from smdcli.model.nonsmooth import whole_tension
from smdcli.solvers.exact.sampled import reseeded_steps

FEW_BREAKS = 32  # breaks up to which a carry steps from one to the next (a recurrence's set-up costs more)


class CarriedSensitivities:
    """EventSensitivityRun's carrying and reading of S (its checkpoints, flows, breaks and seeds)."""

    _seed_table: tuple[dict, np.ndarray] | None = None  # each made once a run, on first use
    _carried: dict[int, dict[float, np.ndarray]] | None = None
    _generators: np.ndarray | None = None
    _breaks_seen: set[float] | None = None
    _output_states: tuple | None = None  # outputs()'s checkpoint of each output point and [z; S] there
    output_rows = slice(None)  # the output points on the grid asked for (a finely held run's: every per_step-th)
    coarse = None  # a finely held run's twin at half as many samples (event_sensitivities), for Richardson's rule

    # ----------------------------------------------------------------------------- carrying S
    def carry(self, Z: np.ndarray, t_from: float, t_to: float, checkpoint: tuple, augmented=None) -> np.ndarray:
        """[z; S] carried from t_from to t_to on the flow of a checkpoint's mode (`augmented`: its flow, if at hand),
        the generators' sensitivities reseeded at each break between (a record's samples, which a batch takes in
        stride, and one at t_to: its right limits, as the run stores)."""
        _, _, _, states_c, dq_c = checkpoint
        augmented = augmented or self.augmented(states_c, dq_c)
        flow, forcing, _ = augmented
        if not len(self.break_times):
            h = t_to - t_from
            return flow.at(Z, forcing, h, abs(h - self.h_out) <= 1e-9 * self.h_out)
        lo = int(np.searchsorted(self.break_times, t_from, side="right"))
        hi = int(np.searchsorted(self.break_times, t_to, side="right"))
        if hi - lo > FEW_BREAKS and self._uniform(self.break_times[lo:hi]):  # to the first, then all at once
            first, last = float(self.break_times[lo]), float(self.break_times[hi - 1])
            states = self._across(self.carry(Z, t_from, first, checkpoint, augmented), augmented,
                                  self.break_times[lo + 1:hi], float(self.break_times[lo + 1]) - first)
            self._kept(checkpoint).update(zip(self.break_times[lo:hi].tolist(), states))
            Z, lo, t_from = states[-1], hi, last
        kept, steps = self._kept(checkpoint), {}  # steps: a whole step's E and forcing, by its length
        for stop in [*self.break_times[lo:hi].tolist(), t_to]:
            h = stop - t_from
            if h > 0 and abs(h - self.h_out) <= 1e-9 * self.h_out:  # a whole output step: its kept exponential
                if h not in steps:
                    E, Phi = flow.operators(h, keep=True)
                    steps[h] = E, Phi @ forcing
                E, shift = steps[h]
                Z, t_from = E @ Z + shift, stop
            elif h > 0:
                Z, t_from = flow.at(Z, forcing, h), stop
            if stop in self._break_set:
                Z = kept[stop] = self._reseeded(Z.copy(), stop)
        return Z

    def _kept(self, checkpoint: tuple) -> dict[float, np.ndarray]:
        """[z; S] at the breaks a carry from this checkpoint passed, by time: the run carries S to each event across a
        record's samples, and the outputs there are those states (not carried again)."""
        if self._carried is None:
            self._carried = {}
        return self._carried.setdefault(id(checkpoint), {})

    @staticmethod
    def _uniform(times: np.ndarray) -> bool:
        """Whether the times are evenly spaced (to 1e-9 of the spacing)."""
        steps = np.diff(times)
        return len(steps) > 0 and bool(np.all(np.abs(steps - steps[0]) <= 1e-9 * steps[0]))

    def _across(self, Z: np.ndarray, augmented, breaks: np.ndarray, h: float) -> np.ndarray:
        """[z; S] at a break (reseeded there) and at each of the breaks after it, h apart, reseeded at each:
        (len(breaks) + 1, size)."""
        flow, forcing, _ = augmented
        E, Phi = flow.operators(h, keep=True)
        table, seeds = self._seeds_table()
        rows = np.array([table[float(t)] for t in breaks], dtype=int)
        return reseeded_steps(E, Phi @ forcing, Z, seeds[rows], self._generator_columns())

    @property
    def _break_set(self) -> set[float]:
        """The run's break times (set once the run has started)."""
        if self._breaks_seen is None:
            self._breaks_seen = set(self.break_times.tolist())
        return self._breaks_seen

    def _generator_columns(self) -> np.ndarray:
        """Where [z; S] holds the generators' states: each block's entries past its displacements and velocities."""
        if self._generators is None:
            s, n = self.scene.size, self.n
            self._generators = (np.arange(self.P + 1)[:, None] * s + np.arange(2 * n, s)[None]).ravel()
        return self._generators

    def _seeds_table(self) -> tuple[dict, np.ndarray]:
        """Each break's row ({time: row}) and every break's reseeded generator entries of [z; S], (breaks, entries):
        the state's own generators, then each sensitivity's (their derivatives), all at once."""
        if self._seed_table is None:
            at = self.break_times

            def reseeded(scene, c):  # (breaks, generators); none where only the ground's jumps break the run
                return np.hstack([np.zeros((len(at), 0))] + [signal.exo_states(at) for _, _, signal, _ in scene.blocks])
            own = reseeded(self.scene, 0.0)
            seeds = np.hstack([own] + [self.total(i, reseeded) for i in range(self.P)])
            self._seed_table = {float(t): row for row, t in enumerate(at)}, seeds
        return self._seed_table

    def _reseeded(self, Z: np.ndarray, t: float) -> np.ndarray:
        """Z with its generators reseeded at break t and each sensitivity's generator block set to their derivative
        there."""
        table, seeds = self._seeds_table()  # t is a break: carry and cross_break reseed nowhere else
        Z[self._generator_columns()] = seeds[table[t]]
        return Z

    def across_jump(self, before, after, z: np.ndarray, S: np.ndarray, t: float) -> np.ndarray:
        """S (P, s) across the ground's jump at t (z: the state before it, S reseeded there): x's and v's by
        event_edges.across_ground_jump (the jump's derivative, the modes it decides, a held constraint's
        projection), the numbers the jump sets carried; where it gives none (a pulse's start that moves with the
        parameter, modes decided otherwise within its step), no derivative from t."""
        rows = across_ground_jump(self, t, before, after, z, lambda i: S[i], reseed=True)
        if isinstance(rows, str):
            self.no_derivative(t, rows)
            return S
        jumped_S = S.copy()
        jumped_S[:, :2 * self.n] = rows
        return jumped_S

    # ----------------------------------------------------------------------------- between samples
    def outputs(self) -> tuple[np.ndarray, np.ndarray]:
        """S (N, P, s) and its rate at the output points, each on the flow from the last checkpoint at or before it
        (after an event at its time: the right limits, as the run stores), from the output before in the same segment
        (all at once where _stepped can); nan from where the response has no derivative."""
        N, P, s = len(self.grid), self.P, self.scene.size
        S_out, rates_out = np.full((N, P, s), np.nan), np.full((N, P, s), np.nan)
        times = np.array([c[0] for c in self.checkpoints])
        ends = self.undefined_from[0] if self.undefined_from is not None else np.inf
        grid = self.grid[self.grid < ends]
        segments = np.searchsorted(times, grid, side="right") - 1
        Zs = np.empty((len(grid), (P + 1) * s))
        steps = np.abs(np.diff(grid) - self.h_out) <= 1e-9 * self.h_out
        for j in np.unique(segments):  # each checkpoint's outputs, stepped from one to the next on its flow
            t_c, z_c, S_c, states_c, dq_c = self.checkpoints[j]
            augmented = self.augmented(states_c, dq_c)
            _, forcing, big = augmented
            Z, t_prev = np.concatenate([z_c, S_c.ravel()]), t_c
            rows = np.flatnonzero(segments == j)
            kept = {t_c: Z, **self._kept(self.checkpoints[j])}
            if len(kept) > 1 and all(t in kept for t in grid[rows].tolist()):
                Zs[rows], rows = [kept[t] for t in grid[rows].tolist()], ()
            if len(rows) > 2 and steps[rows[0]:rows[-1]].all():
                stepped = self._stepped(Z, t_c, grid[rows], self.checkpoints[j], augmented)
                if stepped is not None:
                    Zs[rows], rows = stepped, ()
            for k in rows:
                t = float(grid[k])
                if t > t_prev:
                    Z = self.carry(Z, t_prev, t, self.checkpoints[j], augmented)
                Zs[k], t_prev = Z, t
            at = segments == j
            S_out[:len(grid)][at] = Zs[at, s:].reshape(-1, P, s)
            rates_out[:len(grid)][at] = (Zs[at] @ big[s:].T + forcing[s:]).reshape(-1, P, s)
        edged = list(self.edges)
        S_out[:, edged], rates_out[:, edged] = np.nan, np.nan
        self._output_states = segments, Zs
        return S_out, rates_out

    def tensions(self) -> tuple[np.ndarray, np.ndarray]:
        """Every nonsmooth element's tension at the output points (N, E) and its scaled derivatives (N, P, E), after
        outputs(): in a checkpoint's mode a tension is a row of the state plus a constant (a held element's, the
        constraint's force), T = R z + c, so scale_i dT/dp_i = R s_i + (d R z + d c), the last two the total
        derivative of the mode's rows along the parameter with its internal variables' sensitivities (a plastic
        deformation's moves c); nan where the response has no derivative."""
        segments, Zs = self._output_states
        N, P, s, E = len(self.grid), self.P, self.scene.size, len(self.scene.elements)
        tension, derived = np.full((N, E), np.nan), np.full((N, P, E), np.nan)
        for j in np.unique(segments):
            _, _, _, states_c, dq_c = self.checkpoints[j]
            at = np.flatnonzero(segments == j)
            z, S = Zs[at, :s], Zs[at, s:].reshape(len(at), P, s)
            rows, const = _whole_rows(self.scene, self.scene.mode(states_c))
            tension[at] = z @ rows.T + const
            for i in range(P):
                def read(scene, c, i=i):
                    return np.concatenate(_whole_rows(scene, scene.mode(self.shifted(states_c, i, c, dq_c))), axis=None)
                flat = self.total(i, read)
                derived[at, i] = S[:, i] @ rows.T + z @ flat[:E * s].reshape(E, s).T + flat[E * s:]
        derived[:, list(self.edges)] = np.nan
        return tension, derived

    def grid_tensions(self) -> tuple[np.ndarray, np.ndarray]:
        """tensions() on the grid asked for, combined by Richardson's rule with the coarse twin's where the forces
        were held finely, as the state is."""
        tension, derived = (q[self.output_rows] for q in self.tensions())
        if self.coarse is not None:
            coarse = [q[self.coarse.output_rows] for q in self.coarse.tensions()]
            tension, derived = (4.0 * tension - coarse[0]) / 3.0, (4.0 * derived - coarse[1]) / 3.0
        return tension, derived

    def _stepped(self, Z: np.ndarray, t_c: float, times: np.ndarray, checkpoint: tuple, augmented) -> np.ndarray | None:
        """[z; S] at evenly spaced output times from its checkpoint (Z there), all at once: by doubling where no
        break falls among them, by the reseeded recurrence where each time after the first is a break (a record
        sampled at the output step; the last may not be); None otherwise."""
        flow, forcing, _ = augmented
        lo, hi = np.searchsorted(self.break_times, [times[0], times[-1]], side="right")
        inner = self.break_times[lo:hi]  # the breaks in (first, last]
        if len(inner) and not (len(inner) > FEW_BREAKS and len(inner) >= len(times) - 2
                               and np.array_equal(inner, times[1:len(inner) + 1])):
            return None
        start = self.carry(Z, t_c, float(times[0]), checkpoint, augmented) if times[0] > t_c else Z
        if not len(inner):
            return flow.stepped(start, forcing, self.h_out, len(times) - 1)
        states = self._across(start, augmented, inner, self.h_out)
        if len(inner) == len(times) - 1:
            return states
        return np.vstack([states, flow.at(states[-1], forcing, float(times[-1] - times[-2]), True)[None]])

    def state_at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(z, S) at time t on the exact flow, from the last checkpoint before it (S nan where the response has no
        derivative): the state between samples, as the energy a damper dissipates across an event needs."""
        times = [c[0] for c in self.checkpoints]
        j = max(int(np.searchsorted(times, t, side="right")) - 1, 0)
        t_c, z_c, S_c, _, _ = self.checkpoints[j]
        Z = np.concatenate([z_c, S_c.ravel()]) if t == t_c else \
            self.carry(np.concatenate([z_c, S_c.ravel()]), t_c, t, self.checkpoints[j])
        S = Z[len(z_c):].reshape(self.P, len(z_c))
        if self.undefined_from is not None and t >= self.undefined_from[0]:
            S = np.full_like(S, np.nan)
        S[list(self.edges)] = np.nan
        return Z[:len(z_c)], S

    def rates_at(self, t: float, left: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(Z, Z', Z'') at time t on the exact flow, Z = [z; S] stacked (S nan where the response has no
        derivative): right limits, or (left) the limits before an event at t, from the last checkpoint before it.
        Within a mode Z' = A Z + b with b constant, so Z'' = A Z'."""
        times = [c[0] for c in self.checkpoints]
        j = max(int(np.searchsorted(times, t, side="left" if left else "right")) - 1, 0)
        t_c, z_c, S_c, states_c, dq_c = self.checkpoints[j]
        augmented = self.augmented(states_c, dq_c)
        Z = np.concatenate([z_c, S_c.ravel()])
        if t != t_c:
            Z = self.carry(Z, t_c, t, self.checkpoints[j], augmented)
        _, forcing, big = augmented
        rate = big @ Z + forcing
        out = (Z, rate, big @ rate)
        if self.undefined_from is not None and t >= self.undefined_from[0]:
            for q in out:
                q[len(z_c):] = np.nan
        for i in self.edges:
            for q in out:
                q[len(z_c) * (i + 1):len(z_c) * (i + 2)] = np.nan
        return out

    def at(self, t: float) -> np.ndarray:
        """S at time t (nan where the response has no derivative), from the last checkpoint before it."""
        return self.state_at(t)[1]


def _whole_rows(scene, mode) -> tuple[np.ndarray, np.ndarray]:
    """(rows (E, s), constants (E,)) of each element's whole tension in a mode, rows z + constants: the law's and the
    stiffness kept in K (whole_tension's, a bilinear spring's b k)."""
    return whole_tension(scene.elements, mode.tension_rows.T, mode.d_rows.T).T, mode.tension_const
