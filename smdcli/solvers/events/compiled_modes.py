"""smd's compiled ODE methods on nonsmooth scenes: each mode handed to a compiled kernel (smdcli.kernels.events for
the explicit pairs; radau, bdf, stiff) as arrays, integrated there step by step with its guards watched on the
method's interpolant, and back in Python only at an event, where the decisions of smdcli.solvers.events.decisions are taken.

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import numpy as np

from smdcli.elements.base import KINK, SMOOTH_NONE
from smdcli.kernels.arrays import (GUARD_D, GUARD_INTERNAL, GUARD_RATE, GUARD_TENSION, LAW_PARAMETERS, ModelArrays,
                                   csr)
from smdcli.kernels import tableaus
from smdcli.solvers.registry import BY_NAME

ACCUMULATED = ("dissipated", "input", "hysteretic", "friction", "impact")  # energy terms integrated with the motion
QUANTITIES = {"d": GUARD_D, "rate": GUARD_RATE, "tension": GUARD_TENSION}


def compiled_modes(name: str) -> tuple[str, int] | None:
    """(kernel module, method id) of the compiled kernel that runs a method's modes (the registry's compiled_modes);
    None where an OdeSolver class steps them from Python (smdcli.solvers.events.integrated)."""
    modes = BY_NAME[name].compiled_modes
    return None if modes is None else (modes[0], getattr(tableaus, modes[1]) if modes[1] else 0)


def scene_arrays(scene) -> ModelArrays:
    """The kernels' arrays of a SmoothScene (smdcli.solvers.events.smooth_scene) with what every mode shares: the state's
    internal variables and energy terms, the elements' rows and belts, M 1 and the dampers' C."""
    from smdcli.kernels.arrays import model_arrays

    model = scene.model
    return model_arrays(model)._replace(
        ns_q=int(scene.q_size), ns_acc=len(ACCUMULATED), mass_row=np.ascontiguousarray(model.M.sum(axis=1), dtype=float),
        c_dense=np.ascontiguousarray(model.C, dtype=float), ns_R=np.ascontiguousarray(scene.R, dtype=float),
        ns_belt=np.ascontiguousarray(scene.belts, dtype=float))


def mode_arrays(base: ModelArrays, scene, mode, states) -> ModelArrays:
    """The kernels' arrays of one mode of a SmoothScene, from its scene_arrays: the projected linear part, constant
    forces, the elements' pieces and smooth laws, the held tensions' rows and the guards."""
    n, E = scene.n, scene.E
    Minv = scene.Minv
    P = np.eye(n)
    lin = np.hstack([-mode.Kt, -mode.Ct])
    h_lin, h_f, h_g = np.zeros((E, 2 * n)), np.zeros((E, n)), np.zeros(E)
    held = np.zeros(E, dtype=np.int64)
    if mode.hold is not None:
        MG, S_pinv, G = mode.hold
        P = P - MG @ S_pinv @ G
        H = S_pinv @ G @ Minv
        for i, e in enumerate(mode.held):
            h_lin[e], h_f[e], h_g[e] = H[i] @ lin, H[i], H[i] @ base.mass_row
            held[e] = 1
    PM = P @ Minv
    a_ptr, a_idx, a_val = csr(PM @ lin)
    mi_ptr, mi_idx, mi_val = csr(PM)
    stiff, damp, const = np.zeros(E), np.zeros(E), np.zeros(E)
    law, par, term = np.zeros(E, dtype=np.int64), np.zeros((E, LAW_PARAMETERS)), np.full(E, -1, dtype=np.int64)
    pd, pc, px = np.zeros(E), np.zeros(E), np.zeros(E)
    for e, (element, state, part) in enumerate(zip(scene.elements, states, scene.q_slices)):
        piece, compiled = element.law.piece(state), element.law.kernel_piece(state)
        if piece.nonlinear is not None and compiled.law == SMOOTH_NONE:  # nonsmooth_refusal's promise, kept here
            raise AssertionError(f"{element.path}: a smooth tension without a compiled kernel code")
        stiff[e], damp[e], const[e] = piece.stiffness, piece.damping, piece.constant
        law[e] = compiled.law
        par[e, :len(compiled.parameters)] = compiled.parameters
        par[e, LAW_PARAMETERS - 1] = part.start - 2 * n  # the first internal variable's place in q
        term[e] = ACCUMULATED.index(compiled.term) if compiled.term else -1
        pd[e], pc[e], px[e] = compiled.pd, compiled.pc, compiled.px
    el, qty, level, direction, kink = [], [], [], [], []
    for e, guard, _, _ in mode.guards:
        el.append(e)
        kink.append(int(guard.kind == KINK))
        level.append(guard.level)
        direction.append(guard.direction)
        if guard.quantity.startswith("internal:"):
            name = guard.quantity.split(":", 1)[1]
            if scene.elements[e].law.ode_states.index(name) != 0:
                raise AssertionError(f"a guard on {name}: compiled guards watch a law's first internal variable")
            qty.append(GUARD_INTERNAL)
        else:
            qty.append(QUANTITIES[guard.quantity])
    ints = lambda values: np.array(values, dtype=np.int64)  # noqa: E731
    return base._replace(
        a_ptr=a_ptr, a_idx=a_idx, a_val=a_val, mi_ptr=mi_ptr, mi_idx=mi_idx, mi_val=mi_val,
        f_const=np.ascontiguousarray(mode.g, dtype=float), ground_row=P @ np.ones(n), ns_held=held, ns_stiff=stiff,
        ns_damp=damp,
        ns_const=const, ns_law=law, ns_par=par, ns_term=term, ns_pd=pd, ns_pc=pc, ns_px=px, h_lin=h_lin, h_f=h_f, h_g=h_g,
        gd_el=ints(el), gd_qty=ints(qty), gd_level=np.array(level, dtype=float), gd_dir=ints(direction),
        gd_kink=ints(kink))


class CompiledModes:
    """An event-driven run's compiled half (for smdcli.solvers.events.integrated.EventDriver): each mode's arrays
    (built once, cached by the mode), the rows the kernel writes, its counters and scratch."""

    def __init__(self, driver, size: int):
        from smdcli.kernels.rhs import work_size

        self.driver = driver
        N, n, E = len(driver.grid), driver.n, driver.scene.E
        self.base = scene_arrays(driver.scene)
        self.modes: dict = {}
        self.rows, self.rows_a = np.full((N, size), np.nan), np.full((N, n), np.nan)
        self.rows_t = np.full((N, E), np.nan)
        self.counts, self.floats = np.zeros(5, dtype=np.int64), np.zeros(5)
        self.work = np.zeros(work_size(self.base))
        self._cuts = self._cut_index = None

    def cut_index(self, cuts) -> tuple[np.ndarray, np.ndarray]:
        """The cuts' times, and for each cut the first at or after it where the ground jumps (else the last): once
        per run, where each event's advance walked the rest of the cuts (a sampled force's 6,400 over 1 s, at each
        of thousands of events: most of a run's time)."""
        if self._cuts is not cuts:
            jumps = np.array([jump is not None for _, jump in cuts] + [True])
            jumps[-2] = True  # the last cut ends every walk
            after = np.flatnonzero(jumps)
            self._cuts = cuts
            self._cut_index = (np.array([c[0] for c in cuts], dtype=float),
                               after[np.searchsorted(after, np.arange(len(cuts)))])
        return self._cut_index

    def advance(self, states, t: float, y: np.ndarray, cuts, segment: int, k: int, outputs):
        """EventDriver.advance by the compiled kernel: the mode integrated from (t, y) to the next jump of the
        ground (or the end) or its first event, rows stored: (y, time reached, the event (t, element, guard) or
        None, why it failed or None, next row)."""
        import importlib

        from smdcli.kernels import erk, radau
        from smdcli.kernels.guards import EVENT
        from smdcli.solvers.integrators.compiled import failure_text

        driver = self.driver
        scene = driver.scene
        mode = scene.mode(states)
        arrays = self.modes.get(mode.key)
        if arrays is None:
            arrays = self.modes[mode.key] = mode_arrays(self.base, scene, mode, states)
        from smdcli.kernels.guards import SKIP_EVERY_KINK

        skip_t, skip_guard = -np.inf, -1
        if driver.fired is not None:
            skip_t = driver.fired[0]
            for g, (e, guard, _, _) in enumerate(mode.guards):
                if (e, guard) == driver.fired[1:]:
                    skip_guard = g
            if driver.kinks_left == skip_t:
                skip_guard = SKIP_EVERY_KINK
        # on through the force discontinuities (a restart each, in the kernel) up to the next jump of the ground;
        # where something is held, back at each discontinuity: a force's jump may pass a stuck contact's breakaway
        # or pull a stop away, and the modes are decided there (EventDriver.cross_break)
        cut_times, next_jump = self.cut_index(cuts)
        last = min(segment + 1, len(cuts) - 1)
        if mode.hold is None:
            last = int(next_jump[last])
        times = cut_times[segment:last + 1] if segment <= last else np.array([t, t], dtype=float)
        spacing = driver.held_spacing(mode)
        if spacing:  # restarts that bound the steps where nothing moves but the forces on what holds it
            times = np.union1d(times, np.arange(t + spacing, times[-1], spacing))
        y = np.array(y, dtype=float)
        k0 = k
        module, method = driver.kernel_method
        kernel = importlib.import_module(f"smdcli.kernels.{module}").integrate_mode
        status, k, fired = kernel(arrays, method, y, float(t), times[1:], 0.5 * (times[:-1] + times[1:]), driver.grid,
                                  k, driver.tol.rtol, np.full(len(y), driver.tol.atol), driver.max_steps,
                                  driver.bound, float(skip_t), skip_guard, self.rows, self.rows_a, self.rows_t,
                                  self.counts, self.floats, self.work, 0.0)
        outputs.store_rows(k0, k, self.rows[k0:k], self.rows_a[k0:k], self.rows_t[k0:k], states)
        t_reached = float(self.floats[erk.T_REACHED])
        driver.counts.update(nfev=int(self.counts[erk.NFEV]), steps_accepted=int(self.counts[erk.ACCEPTED]),
                             steps_rejected=int(self.counts[erk.REJECTED]))
        if module != "events":  # the implicit kernels' counters (radau's layout, which bdf and stiff share)
            driver.counts.update(njev=int(self.counts[radau.NJEV]), nlu=int(self.counts[radau.NLU]))
        if status == EVENT:
            e, guard, _, _ = mode.guards[fired]
            return y, t_reached, (t_reached, e, guard), None, k
        if status != erk.OK:
            return y, t_reached, None, failure_text(status, driver.max_steps, driver.bound), k
        return y, float(times[-1]), None, None, k
