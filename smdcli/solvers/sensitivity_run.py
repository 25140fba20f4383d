"""The compiled forward-sensitivity kernel (smdcli.kernels.sensitivity) run over a grid: its kernels warmed (or
compiled, saying so), the stencil's models handed over as one padded tuple, a failure said where and why.

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import numpy as np

from smdcli.errors import SolverFailed

MAX_STEPS = 10**7


def warm_kernel() -> None:
    """Load the compiled sensitivity kernel from numba's cache (or compile it, saying so), before any clock starts."""
    from smdcli.solvers.integrators.compiled import warm

    warm("sensitivity")


def run_sensitivities(base, stencil: list, start: np.ndarray, grid: np.ndarray, cuts: np.ndarray, rtol: float,
                      atol: np.ndarray, source: str) -> tuple[np.ndarray, np.ndarray]:
    """(y, y') (N, len(start)) from start over the grid, restarting at the cuts: base the scene's kernel arrays,
    stencil (parameter, weight, arrays, M^-1 M_j or None where the model leaves M alone) of each model a parameter's
    derivative takes (none: the state alone; at most compiler.STENCIL_MODELS)."""
    from smdcli.kernels import sensitivity as kernel
    from smdcli.kernels.compiler import model_tuple
    from smdcli.kernels.rhs import work_size
    from smdcli.solvers.integrators.compiled import failure_text

    warm_kernel()
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
                              np.zeros(work_size(base)), np.zeros(3, dtype=np.int64), reached)
    if status != kernel.OK:
        raise SolverFailed(f"{source}: the sensitivity equations failed at t = {reached[0]:.6g} s: "
                           f"{failure_text(status, MAX_STEPS, np.inf)}")
    return out, rates
