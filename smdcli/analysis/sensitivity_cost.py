"""What P sensitivities cost, on the clock `smd sensitivity --json` reports: the code a scene's run takes loaded
before any clock starts, one forward run of the scene timed as each of a finite difference's P + 1 runs takes it, and
a short run's seconds as the median of repeats (smd compare's rule).

Must not import: io, plots, commands, cli.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable

import numpy as np

from smdcli.model import Model, build
from smdcli.scenario import Scenario
from smdcli.solvers.base import TIME_ONCE_S, Tolerances
from smdcli.solvers.exact.hold import held_paths
from smdcli.solvers.ground import across_jumps
from smdcli.solvers.peaks import result_peaks
from smdcli.solvers.registry import get_solver

REPEATS = 5  # a short run's timings, whose median is its seconds


def load_code(base: Model) -> None:
    """Load the code the scene's sensitivities and its forward run take (modules; the compiled sensitivity kernel from
    numba's cache) before the clock: a process loads it once, and simulate's clock leaves its loading out too (a
    one-DOF scene's first sensitivity in a process took 30 ms, 25 of them imports). base: a scene smd takes."""
    import smdcli.analysis.modal_sensitivity  # noqa: F401
    import smdcli.solvers.dispatch  # noqa: F401
    import smdcli.solvers.exact.linear  # noqa: F401

    if base.is_linear and not held_paths(base):
        return
    if base.is_piecewise_linear:
        import scipy.optimize  # noqa: F401  an event's root (brentq)

        import smdcli.analysis.event_sensitivity  # noqa: F401
        import smdcli.solvers.events.piecewise  # noqa: F401
        return
    from smdcli.analysis.smooth_sensitivity import COMPILED, smooth_refusal

    if smooth_refusal(base):  # events beside smooth terms: the compiled event-driven run, then the compiled kernel
        import scipy.integrate  # noqa: F401
        import scipy.interpolate  # noqa: F401  a graze's search
        import scipy.optimize  # noqa: F401

        from smdcli.analysis.mixed_sensitivity import RECORDED_BY
        from smdcli.solvers.events.integrated import load_method
        from smdcli.solvers.sensitivity_run import warm_kernel

        load_method(RECORDED_BY)
        warm_kernel()
        return
    if COMPILED:
        from smdcli.solvers.events.compiled_modes import mode_arrays  # noqa: F401
        from smdcli.solvers.events.smooth_scene import SmoothScene  # noqa: F401
        from smdcli.solvers.sensitivity_run import warm_kernel

        warm_kernel()


def forward_time(sc: Scenario, grid: np.ndarray, peaks: bool = False) -> float:
    """Seconds of one forward run of the scene alone, as each of a finite difference's P + 1 runs takes it: the scene
    built (at a moved parameter it is another scene) and solved on the grid (exact, or auto's for a nonlinear scene),
    both with their results, and with `peaks` each DOF's peak located (a difference of the peaks needs every run's);
    what the P sensitivities are measured against."""
    from smdcli.solvers.dispatch import solve

    start = time.perf_counter()
    base = build(sc)
    if base.is_linear:
        exact = get_solver("exact")
        result = across_jumps(lambda piece, times: exact.solve(piece, times, Tolerances()), base.dense(), grid)
    else:
        result = solve(base, grid, "auto", Tolerances())
    if peaks:
        result_peaks(result)
    return time.perf_counter() - start


def median_time(first: float, again: Callable[[], float]) -> float:
    """The median of a run's seconds and up to REPEATS - 1 more of it, taken while each lasts under TIME_ONCE_S (smd
    compare's rule: a longer run's noise is a small share of it; a run of milliseconds is its noise and its CPU's
    warm-up, the first of a 51-sample one-DOF scene's a third slower than those after)."""
    times = [first]
    while len(times) < REPEATS and times[-1] <= TIME_ONCE_S:
        times.append(again())
    return statistics.median(times)
