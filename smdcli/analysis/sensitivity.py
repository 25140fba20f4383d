"""Response sensitivities dx/dp: of a linear scene exactly, the scene and its sensitivity equations solved together
by the matrix exponential (model_derivative.py builds the stacked system); of a smooth nonlinear scene by the
forward sensitivity equations (smooth_sensitivity.py); and the derivatives of each DOF's peak |x|, taken where
the peak is located between the samples.

The derivative of a peak: at the time t* of max |x_i| the slope of x_i is zero (or t* is an end of the run), so
d max|x_i| / dp = sign(x_i(t*)) dx_i/dp (t*) (the envelope theorem), with dx_i/dp read at t* on the quintic
Hermite interpolant of its own samples, velocities and accelerations.

Must not import: io, plots, commands, cli.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from smdcli.analysis.model_derivative import augmented_model, model_derivatives
from smdcli.analysis.sensitivity_result import METHOD, QUANTITIES, Sensitivity
from smdcli.analysis.stacked_blocks import accelerations_after
from smdcli.analysis.sensitivity_cost import forward_time, load_code, median_time
from smdcli.analysis.sensitivity_limits import refuse, too_many_dofs, too_much_memory
from smdcli.analysis.step_scale import block_scales
from smdcli.errors import SolverFailed, UsageError
from smdcli.model import Model, build, time_grid
from smdcli.scenario import Scenario
from smdcli.resources import HEAP_KEPT, fault_in, keep_freed_memory, small_blas
from smdcli.solvers.base import Tolerances
from smdcli.solvers.exact.hold import held_paths
from smdcli.solvers.ground import across_jumps
from smdcli.solvers.peaks import jump_times, located_peaks, quintic_each
from smdcli.solvers.registry import get_solver

ACCELERATIONS_AFTER = 30  # DOFs from which a linear scene's accelerations are found after its x and v (_linear)
SMOOTH_ERROR = 100  # a smooth scene's stated error, in units of its rtol: DOP853's global error over its local one
EVENT_METHOD = ("exact, event to event: between events the scene and its sensitivity equations solved together by "
                "the matrix exponential; at each event its time's derivative from the guard it crosses and the "
                "state's jump across it (the saltation), internal variables (plastic deformation) carried with "
                "their own sensitivities; the model's derivatives taken on the assembled scene (a five-point "
                "stencil in each parameter)")


def sensitivity(sc: Scenario, params: list[str], grid: np.ndarray | None = None, timed: bool = False,
                peaks: bool = True, advance=None, built: tuple[dict, Model] | None = None) -> Sensitivity:
    """The sensitivities of a linear, piecewise-linear (yielding, friction, stops) or smooth nonlinear scene's response
    to each parameter path (the sweep's paths), on the scenario's output grid or on `grid` (any increasing times
    from the scenario's start); `timed`: one forward run of the scene alone (built, solved and, with `peaks`, its
    peaks located) is timed after it (forward_time_s), for the cost's comparison with wall_time_s (neither clock
    holds the loading of code, and a short run is the median of repeats: sensitivity_cost.py); without `peaks` the
    peaks and their derivatives are left out (nan: a fit reads the histories only); advance(count): a progress
    bar's, over the output times of a smooth scene's integration; built: the scenario's TOML document and model,
    where the caller has them (a fit's trial point)."""
    import scipy.linalg  # noqa: F401  the solvers' own imports, before the clock: a process pays them once, and
    import scipy.sparse  # noqa: F401  forward_time_s, timed after, would not

    if not params:
        raise UsageError("smd sensitivity: give at least one --param PATH (spring[0].k, mass.m1.m, ...)")
    keep_freed_memory()
    with small_blas(2 * (len(params) + 1) * len(sc.dof_names)):
        if timed and built is None:
            _rehearse(sc, params, grid)
        start = time.perf_counter()
        doc, base = built if built is not None else (None, build(sc))
        building = time.perf_counter() - start
        refuse(sc, params, base)
        load_code(base)
        start = time.perf_counter()
        found = _sensitivity(sc, params, grid, peaks, advance, (doc, base))
        # all of it: the scene built, its derivatives, the solve, the peaks and the result; not the code's loading
        found.wall_time_s = building + time.perf_counter() - start
        if timed:
            found.wall_time_s = median_time(found.wall_time_s, lambda: _timed_again(sc, params, grid, peaks))
            forward_time(sc, found.time[:2], peaks)  # its code's first use (a nonlinear scene's kernels), untimed
            found.forward_time_s = median_time(forward_time(sc, found.time, peaks),
                                               lambda: forward_time(sc, found.time, peaks))
    return found


def _timed_again(sc: Scenario, params: list[str], grid: np.ndarray | None, peaks: bool) -> float:
    """Seconds of the sensitivities once more, built from the scenario (a repeat of a short run, its result dropped)."""
    start = time.perf_counter()
    _sensitivity(sc, params, grid, peaks, None, (None, build(sc)))
    return time.perf_counter() - start


def _rehearse(sc: Scenario, params: list[str], grid: np.ndarray | None) -> None:
    """The sensitivities on the grid's first two times, untimed: the code's first use in the process (its loading and
    the caches it fills: a one-DOF scene's first run took 13 ms after its imports, the next 3 ms) before the clock,
    as the forward run timed after finds it. A model of its own: the timed run's computes its own matrices (the
    state matrix, cached on the model, is part of the work). A failure is the timed run's to report."""
    try:
        base = build(sc)
        refuse(sc, params, base)
        load_code(base)
        times = time_grid(sc.time) if grid is None else np.asarray(grid, dtype=float)
        _sensitivity(sc, params, times[:2], True, None, (None, base))
    except Exception:  # noqa: BLE001  the timed run meets it again and says it
        return
    # the run's arrays (the scene's and each parameter's x, v and a, a few working copies of them) on pages the
    # process has touched, as the forward run timed after finds them; no more: 8 MB more flushed the CPU's caches
    # (a one-DOF scene's first sensitivity, 51 samples in 2 ms, read 2.3-3.4 forward runs with them, 2.1-2.6
    # without, in eight fresh processes each)
    fault_in(min(HEAP_KEPT // 2, 4 * 8 * len(QUANTITIES) * (len(params) + 1) * len(times) * base.n))


def _sensitivity(sc: Scenario, params: list[str], grid: np.ndarray | None, peaks: bool, advance,
                 built: tuple[dict | None, Model]) -> Sensitivity:
    doc, base = built
    piecewise = base.is_piecewise_linear
    # a linear scene is solved exactly with its forces' generators; a force without one (a chirp, a formula) is read
    # at t by the smooth sensitivity equations (held on the output grid, its error was the hold's: 7e-4 on a decaying
    # sine at 100 samples a second)
    linear = base.is_linear and not held_paths(base)
    if piecewise:
        from smdcli.analysis.event_sensitivity import EVENT_ERROR
    grid = time_grid(sc.time) if grid is None else np.asarray(grid, dtype=float)
    derivatives = model_derivatives(sc, base, grid, list(params), doc, flowed=linear)
    n, P = base.n, len(derivatives)
    tol = Tolerances()
    run = dense = mixed = tensions = None  # tensions: the nonsmooth elements' tensions and derivatives, on call
    scales = block_scales(derivatives)
    if linear:
        values, stated, method = _linear(sc, base, derivatives, grid, tol)
    else:
        if piecewise:
            blocks, stated, run = _events(base, derivatives, scales, grid)
            tensions = run.grid_tensions
            method = f"{EVENT_METHOD}; {run.held}" if run.held else EVENT_METHOD
        else:
            blocks, stated, dense, method, mixed, tensions = _smooth(sc, base, derivatives, scales, grid, advance)
        values = _split(blocks, scales)
    nominal = {q: values[i, 0] for i, q in enumerate(QUANTITIES)}
    derived = {q: values[i, 1:] for i, q in enumerate(QUANTITIES)}
    # each quantity's block peaks over time and DOFs (the scene's, then scale_i dx/dp_i), every block contiguous (one
    # reduction along memory for all of them: a small scene's cost is its numpy calls); fmax passes over nan, written
    # where no derivative exists
    peaks_of = _largest(values.reshape(len(QUANTITIES) * (P + 1), -1)).reshape(len(QUANTITIES), P + 1)
    peaks_of[:, 1:] *= scales
    largest = peaks_of[:, 1:]
    if linear:  # the run's error is relative to the stacked state's peak (every block a displacement)
        absolute = stated * peaks_of.max(axis=1, keepdims=True)
    elif piecewise:
        absolute = max(stated, EVENT_ERROR) * peaks_of.max(axis=1, keepdims=True)
    else:  # the integrator's: rtol of each component, atol a thousandth of rtol of the state's peak
        absolute = stated * (largest + 1e-3 * peaks_of[:, :1])
    relative = np.maximum(np.where(largest > 0, absolute / np.where(largest > 0, largest, 1.0), 0.0),
                          [d.error for d in derivatives])
    accuracy = {}
    for q, row in zip(QUANTITIES, relative):
        accuracy[f"d_{q}"] = row
        accuracy[q] = np.full(1, stated)
    notes = []  # the histories' too: a fit's trial point where they have no derivative says why
    evented = run if run is not None else mixed  # the events' run, where the scene has events
    if evented is not None and evented.undefined_from is not None:
        when, why = evented.undefined_from
        notes.append(f"from t = {when:.9g} s the response has no derivative ({why}): written as nan")
    for i, why in (evented.edges.items() if evented is not None else ()):
        notes.append(f"the response has no derivative in {params[i]} ({why}): written as nan")
    if not peaks:
        nan = np.full(n, np.nan)
        found = _result(sc, params, derivatives, grid, base, nominal, derived, nan, nan, np.full((P, n), np.nan),
                        accuracy, tuple(notes), method)
        found.law_tensions = _law_tensions(base, tensions, scales)
        return found
    # where the state or the acceleration jumps (the forces' and the ground's jumps, the events) the interpolant does
    # not hold: those intervals keep their samples (result_peaks' rule)
    events = np.unique(np.concatenate([jump_times(base, grid), [e[0] for e in getattr(evented, "events", ())]]))
    peaks, at = located_peaks(grid, nominal["displacement"], nominal["velocity"], nominal["acceleration"], events,
                              with_times=True)
    if run is None:  # the scene and its derivatives on each DOF's quintic at its peak's time, in one evaluation
        read = quintic_each(grid, values[0], values[1], values[2], at)  # (P + 1, n)
        d_peaks = np.sign(read[0]) * read[1:]
    else:  # on the exact flow at the peak's time
        sign = np.sign(quintic_each(grid, nominal["displacement"], nominal["velocity"], nominal["acceleration"], at))
        d_peaks = sign * np.stack([run.at(float(at[i]))[:, i] for i in range(n)], axis=1) / scales[:, None]
    for t, x, dx in getattr(evented, "peak_points", ()):  # a peak at an event between samples (a stick at the top)
        higher = np.abs(x) > peaks
        peaks[higher], at[higher] = np.abs(x[higher]), t
        d_peaks[:, higher] = np.sign(x[higher]) * dx[:, higher] / scales[:, None]
    # a peak within the run's own error of x (a DOF the motion has not reached: zeros, or the rounding of the solution)
    # has no derivative worth a number: its digits are the rounding's
    floor = stated * peaks_of[0].max()
    still = peaks <= floor
    # a DOF at rest whose derivative is zero throughout stays at rest to first order: its peak's derivative is 0
    resting = (peaks == 0) & ~derived["displacement"].any(axis=1)  # (P, n)
    d_peaks[:, still] = np.where(resting[:, still], 0.0, np.nan)
    notes += _unmoved(base.dofs, peaks, still & ~resting.all(axis=0), floor)
    found = _result(sc, params, derivatives, grid, base, nominal, derived, peaks, at, d_peaks, accuracy,
                    tuple(notes), method)
    found.event_times = events
    found.dense_acceleration_at = dense
    found.law_tensions = _law_tensions(base, tensions, scales)
    if run is not None:
        found.exact_at = lambda t: run.at(t)[:, :n] / scales[:, None]

        def state_at(t):
            z, S = run.state_at(t)
            return z[:2 * n], S[:, :2 * n] / scales[:, None]
        found.exact_state_at = state_at
        def rates_at(t, left=False):
            Z, rate, curvature = run.rates_at(t, left)
            size = run.scene.size
            return (rate[n:2 * n], curvature[n:2 * n],
                    *(q[size:].reshape(len(scales), size)[:, n:2 * n] / scales[:, None] for q in (rate, curvature)))
        found.exact_rates_at = rates_at
        found.event_moves = {t: dt / scales for t, dt in run.moves.items()}
        found.law_states = [(t, states, [{name: value / scales for name, value in d.items()} for d in dq])
                            for t, _, _, states, dq in run.checkpoints]
    return found


def _law_tensions(base: Model, source, scales: np.ndarray) -> Callable | None:
    """path -> a nonsmooth element's tension on the grid (N,) and its derivatives (P, N), from source() (all the
    elements' (N, E) and their scaled derivatives (N, P, E), taken on first use); None without a source."""
    if source is None:
        return None
    paths = [element.path for element in base.nonsmooth]
    table = []

    def tensions(path: str) -> tuple[np.ndarray, np.ndarray]:
        if not table:
            table.extend(source())
        e = paths.index(path)
        return table[0][:, e], table[1][:, :, e].T / scales[:, None]
    return tensions


def _unmoved(dofs, peaks: np.ndarray, still: np.ndarray, floor: float) -> list[str]:
    """One note for the DOFs whose peaks are within the run's error of x (floor, m): named, or counted where many."""
    which = np.flatnonzero(still)
    if not len(which):
        return []
    names = [dofs[i] for i in which]
    listed = ", ".join(names) if len(names) <= 4 else f"{len(names)} DOFs ({', '.join(names[:2])}, ..., {names[-1]})"
    many = len(names) > 1
    if not peaks[which].any():
        how = "do not move" if many else "does not move"
    else:
        how = f"move{'' if many else 's'} no more than the run's error of x ({floor:.2g} m)"
    return [f"{listed} {how}: {'their peaks have' if many else 'its peak |x| has'} no derivative (written as nan)"]


def _largest(rows: np.ndarray) -> np.ndarray:
    """Each row's largest magnitude over its numbers (nan passed over; 0 for none), from its extremes: no |rows|
    made (a fresh array's pages cost more than the pass)."""
    return np.maximum(np.maximum(np.fmax.reduce(rows, axis=1, initial=-np.inf),
                                 -np.fmin.reduce(rows, axis=1, initial=np.inf)), 0.0)


def _result(sc, params, derivatives, grid, base, nominal, derived, peaks, at, d_peaks, accuracy, notes,
            method) -> Sensitivity:
    from smdcli.sweep.spec import parameter_units

    return Sensitivity(
        scenario=str(sc.path), parameter=tuple(params), value=np.array([d.value for d in derivatives]),
        parameter_units=tuple(parameter_units(path, sc) for path in params), time=grid, dof=tuple(base.dofs),
        displacement=nominal["displacement"], velocity=nominal["velocity"], acceleration=nominal["acceleration"],
        d_displacement=derived["displacement"], d_velocity=derived["velocity"], d_acceleration=derived["acceleration"],
        peak_displacement=peaks, peak_time=at, d_peak_displacement=d_peaks, accuracy=accuracy,
        model_error=np.array([d.error for d in derivatives]), forward_time_s=float("nan"),
        notes=notes, model=base, derivatives=derivatives, method=method)


def _split(blocks: dict, scales: np.ndarray) -> np.ndarray:
    """Each quantity's (N, P + 1, n) blocks (the scene, then scale_i d/dp_i) as one (quantities, P + 1, N, n) array:
    the scene's (N, n), then its derivatives', each block contiguous."""
    N, blocks_count, n = blocks["displacement"].shape
    values = np.empty((len(QUANTITIES), blocks_count, N, n))
    for i, q in enumerate(QUANTITIES):
        values[i, 0] = blocks[q][:, 0]
        np.divide(np.moveaxis(blocks[q][:, 1:], 1, 0), scales[:, None, None], out=values[i, 1:])
    return values


def _linear(sc: Scenario, base, derivatives: list, grid: np.ndarray, tol: Tolerances) -> tuple[np.ndarray, float,
                                                                                             str]:
    """Each quantity's scene (N, n) and derivatives (P, N, n), as _split's one array, by the exact solver, its
    accuracy and how they were obtained (the method's text): a classically damped scene in its modal coordinates
    (modal_sensitivity.py); else on the dense and record-sample paths each read off the stacked state straight into
    its place (read_exactly; a derivative block reaches only itself, the scene and the forces: its products skip the
    rest); elsewhere (jumps, harmonics superposed, the sparse paths, unequal steps) as blocks of the stacked model's
    result."""
    from smdcli.analysis.modal_sensitivity import MODAL_METHOD, modal_sensitivities
    from smdcli.solvers.exact.linear import read_exactly

    P, n, N = len(derivatives), base.n, len(grid)
    too_much_memory(sc, P, n, N)
    stacked, scales = augmented_model(base, derivatives)
    modal = modal_sensitivities(base, stacked, scales, grid)
    if modal is not None:  # a classically damped scene: its modes and each parameter's, side by side
        return (*modal, MODAL_METHOD)
    too_many_dofs(sc, P, n)  # the dense stacked system's exponential, past what it takes
    values = np.empty((len(QUANTITIES), P + 1, N, n))
    total, reads = (P + 1) * n, []
    # a large scene's accelerations from its x and v by its own M a = F - C v - K x (a parameter's few entries of dM,
    # dC, dK), not read off the stacked state: a third of the rows read, where an acceleration's rows reach all of it
    after = n >= ACCELERATIONS_AFTER
    rates, inputs = stacked.state_matrix[total:], stacked.input_matrix[total:]
    for block in range(P + 1):
        rows, by = slice(block * n, (block + 1) * n), (1.0 if block == 0 else scales[block - 1])
        reads += [(np.eye(n, 2 * total, block * n) / by, None, values[0, block]),
                  (np.eye(n, 2 * total, total + block * n) / by, None, values[1, block])]
        if not after:
            reads.append((rates[rows] / by, inputs[rows] / by, values[2, block]))
    solved = None if stacked.jumps else read_exactly(stacked, grid, reads, copies=P)
    if solved is not None and after:
        accelerations_after(base, stacked, values, grid, scales)
    if solved is not None:
        stated = solved[0]
    else:
        exact = get_solver("exact")
        result = across_jumps(lambda piece, times: exact.solve(piece, times, tol), stacked, grid)
        if not result.success:
            raise SolverFailed(f"{sc.path}: the sensitivity equations could not be solved: {result.stats.message}")
        values = _split({q: getattr(result, q).reshape(N, P + 1, n) for q in QUANTITIES}, scales)
        stated = float(result.stats.stated_accuracy)
    if not np.isfinite(values[0]).all():
        raise SolverFailed(f"{sc.path}: the sensitivity equations could not be solved: not finite")
    return values, float(stated), METHOD


def _events(base, derivatives: list, scales: np.ndarray, grid: np.ndarray) -> tuple[dict, float, object]:
    """The same blocks for a piecewise-linear scene, exact event to event (event_sensitivity.py), its stated
    accuracy and the run (its sensitivities between samples, and where they stop existing)."""
    from smdcli.analysis.event_sensitivity import event_sensitivities
    from smdcli.solvers.events.piecewise import PiecewiseFailed

    try:
        x, v, a, S, d_a, run, stated = event_sensitivities(base, derivatives, scales, grid)
    except PiecewiseFailed as failed:  # the exact run's own failure (events that do not settle at one instant)
        raise SolverFailed(f"{base.source}: the exact event-to-event sensitivities failed: {failed}; differences of "
                           "runs by an event-located integrator (smd sweep --method DOP853) can stand in") from None
    n = base.n

    def stacked(nominal, derived):  # (N, n) and (N, P, n) -> (N, P + 1, n)
        return np.concatenate([nominal[:, None, :], derived], axis=1)
    return {"displacement": stacked(x, S[:, :, :n]), "velocity": stacked(v, S[:, :, n:2 * n]),
            "acceleration": stacked(a, d_a)}, stated, run


def _smooth(sc: Scenario, base, derivatives: list, scales: np.ndarray, grid: np.ndarray, advance=None) -> tuple:
    """The same blocks for a smooth nonlinear scene, by the forward sensitivity equations (smooth_sensitivity.py)
    at rtol 1e-9 or the scenario's tighter one; its stated accuracy SMOOTH_ERROR times that rtol, its dense
    accelerations, how the equations were integrated, the mixed run (events beside smooth terms) if one, and its
    laws' tensions on call."""
    from smdcli.analysis.smooth_sensitivity import RTOL, smooth_refusal, smooth_sensitivities, smooth_tensions

    rtol, mixed = min(RTOL, sc.solver.rtol), None
    if smooth_refusal(base) is None:
        y, S, rates, d_rates, rates_at, method = smooth_sensitivities(base, derivatives, scales, grid, rtol, advance)
    else:  # events beside smooth terms: from event to event (mixed_sensitivity.py)
        from smdcli.analysis.mixed_sensitivity import mixed_sensitivities

        y, S, rates, d_rates, rates_at, method, mixed = mixed_sensitivities(base, derivatives, scales, grid, rtol,
                                                                          sc.solver.atol, advance)
    n, N = base.n, len(grid)

    def stacked(nominal, derived):  # (N, n) and (N, n, P) -> (N, P + 1, n)
        return np.concatenate([nominal[:, None, :], np.moveaxis(derived, 2, 1)], axis=1)
    blocks = {"displacement": stacked(y[:, :n], S[:, :n]), "velocity": stacked(y[:, n:2 * n], S[:, n:2 * n]),
              "acceleration": stacked(rates[:, n:2 * n], d_rates[:, n:2 * n])}
    del N

    def acceleration_at(t: float, left: bool = False) -> tuple[np.ndarray, np.ndarray]:
        rate, d_rate = rates_at(t, left)
        return rate[n:2 * n], d_rate[n:2 * n].T / scales[:, None]
    acceleration_at.breaks = rates_at.breaks
    tensions = mixed.grid_tensions if mixed is not None else lambda: smooth_tensions(base, derivatives, scales, y, S)
    return blocks, SMOOTH_ERROR * rtol, acceleration_at, method, mixed, tensions
