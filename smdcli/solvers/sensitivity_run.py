"""The compiled forward-sensitivity kernels run over a grid: explicit DOP853 (smdcli.kernels.sensitivity), and
implicit Radau IIA (smdcli.kernels.implicit_sensitivity) from the start where that one finds the scene stiff; their
kernels warmed (or compiled, saying so), the stencil's models handed over as one padded tuple, a failure said where
and why.

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import numpy as np

from smdcli.errors import SolverFailed

MAX_STEPS = 10**7
# which kernel: None, DOP853 turning to Radau where Hairer's test finds the scene stiff; "explicit", DOP853 alone;
# "implicit", Radau from the start (the tests take each)
KERNEL: str | None = None


def warm_kernel(implicit: bool = False) -> None:
    """Load a compiled sensitivity kernel from numba's cache (or compile it, saying so), before any clock starts."""
    from smdcli.solvers.integrators.compiled import warm

    warm("implicit_sensitivity" if implicit else "sensitivity")


def run_sensitivities(base, stencil: list, start: np.ndarray, grid: np.ndarray, cuts: np.ndarray, rtol: float,
                      atol: np.ndarray, source: str, implicit: bool = False) -> tuple[np.ndarray, np.ndarray, bool]:
    """(y, y', implicit) (N, len(start)) from start over the grid, restarting at the cuts: base the scene's kernel
    arrays, stencil (parameter, weight, arrays, M^-1 M_j or None where the model leaves M alone) of each model a
    parameter's derivative takes (none: the state alone; at most compiler.STENCIL_MODELS); by Radau where implicit,
    or where DOP853 finds the scene stiff (implicit then True)."""
    from smdcli.kernels import implicit_sensitivity, sensitivity
    from smdcli.kernels.compiler import model_tuple
    from smdcli.kernels.rhs import work_size
    from smdcli.solvers.integrators.compiled import failure_text

    implicit = implicit or KERNEL == "implicit"
    kernel = implicit_sensitivity if implicit else sensitivity
    watch = () if implicit else (np.inf if KERNEL == "explicit" else sensitivity.STIFF_RHO,)
    warm_kernel(implicit)
    models = model_tuple([arrays for _, _, arrays, _ in stencil], base)
    out, rates = np.full((len(grid), len(start)), np.nan), np.full((len(grid), len(start)), np.nan)
    ratios = np.zeros((len(stencil), base.n, base.n))
    for j, (_, _, _, ratio) in enumerate(stencil):
        if ratio is not None:
            ratios[j] = ratio
    reached = np.zeros(1)  # where a failure met
    status = kernel.integrate(base, models, np.array([w for _, w, _, _ in stencil], dtype=float),
                              np.array([p for p, _, _, _ in stencil], dtype=np.int64), ratios,
                              np.array([r is not None for *_, r in stencil], dtype=np.bool_),
                              np.asarray(start, dtype=float), grid, cuts, float(rtol), atol, MAX_STEPS, out, rates,
                              np.zeros(work_size(base)), np.zeros(3, dtype=np.int64), reached, *watch)
    if status == sensitivity.STIFF:
        return run_sensitivities(base, stencil, start, grid, cuts, rtol, atol, source, implicit=True)
    if status != kernel.OK:
        raise SolverFailed(f"{source}: the sensitivity equations failed at t = {reached[0]:.6g} s: "
                           f"{failure_text(status, MAX_STEPS, np.inf)}")
    return out, rates, implicit
