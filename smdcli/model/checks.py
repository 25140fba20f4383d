"""Checks of an assembled scene: numbers that overflow double precision, named by the field that put them there,
and forces a run could not restart at or evaluate.

Must not import: solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math

import numpy as np

from smdcli.errors import ScenarioError
from smdcli.model.grid import time_grid
from smdcli.model.mass import mass_solve
from smdcli.scenario import Scenario


def check_matrices_finite(M: np.ndarray, C: np.ndarray, K: np.ndarray, scenario: Scenario,
                           dofs: tuple[str, ...]) -> None:
    """Refuse a scene whose accelerations overflow (a mass of 1e-320 kg under a stiffness), naming the mass: no
    method could solve it, and the undamped modes [damping] needs could not be computed."""
    # also each column's sum of magnitudes (the state matrix's 1-norm, what its exponential is scaled by): two
    # entries of 1e308 in one column are each finite and their norm is not
    with np.errstate(all="ignore"):
        if not isinstance(M, np.ndarray):  # a sparse scene's diagonal M: each row of K and C over its mass
            K_over, C_over = (A.multiply(1.0 / M.diagonal()[:, None]).tocsr() for A in (K, C))
            bad = ~(finite_rows(K_over) & finite_rows(C_over))
            bad |= ~np.isfinite(np.asarray(abs(K_over).sum(axis=0) + abs(C_over).sum(axis=0)).ravel())
        elif np.count_nonzero(M) == np.count_nonzero(np.diagonal(M)):  # each row's largest entry over its mass
            bad = ~np.isfinite(np.maximum.reduce([K.max(axis=1), -K.min(axis=1), C.max(axis=1), -C.min(axis=1)])
                               / np.diagonal(M))
            over = 1.0 / np.abs(np.diagonal(M))[:, None]
            bad |= ~np.isfinite((np.abs(K) * over).sum(axis=0) + (np.abs(C) * over).sum(axis=0))
        else:
            try:
                rows = np.hstack([mass_solve(M, K), mass_solve(M, C)])
            except np.linalg.LinAlgError:
                rows = np.full((len(dofs), 2 * len(dofs)), np.nan)
            bad = ~np.isfinite(rows).all(axis=1)
            n = len(dofs)
            bad |= ~np.isfinite(np.abs(rows[:, :n]).sum(axis=0) + np.abs(rows[:, n:]).sum(axis=0))
    if bad.any():
        i = int(np.argmax(bad))
        where = f"mass[{i}].m" if scenario.system is None else "system.M"
        raise ScenarioError(scenario.path, where, f"M^-1 K or M^-1 C is not finite for DOF {dofs[i]!r}: "
                                                  "a mass too small for the stiffness or damping it carries")


def check_finite(scenario: Scenario, dofs: tuple[str, ...], **matrices: np.ndarray) -> None:
    """Refuse an assembled K or C that overflows, naming the field that put the overflow there."""
    for name, matrix in matrices.items():
        bad = ~finite_rows(matrix)
        if bad.any():
            i = int(np.argmax(bad))
            raise ScenarioError(scenario.path, _blame(scenario, name, dofs[i]),
                                f"the assembled {name} overflows double precision at DOF {dofs[i]!r}; expected "
                                "numbers whose sums and products stay below 1.8e308")


def finite_rows(matrix) -> np.ndarray:
    """Per row, whether every entry is finite: a dense array or a CSR matrix (its stored entries)."""
    if isinstance(matrix, np.ndarray):
        return np.isfinite(matrix).all(axis=1)
    bad = np.repeat(np.arange(matrix.shape[0]), np.diff(matrix.indptr))[~np.isfinite(matrix.data)]
    finite = np.ones(matrix.shape[0], dtype=bool)
    finite[bad] = False
    return finite


def _blame(scenario: Scenario, matrix: str, dof: str) -> str:
    """The field that put an overflowing entry into K or C at a DOF: [damping], an element on it, or [system]."""
    if scenario.system is not None:
        return f"system.{matrix}" if matrix == "K" or scenario.damping is None else f"damping.{scenario.damping.given}"
    elements = scenario.springs if matrix == "K" else scenario.dampers
    own = [e for e in elements if dof in e.connects]
    with np.errstate(all="ignore"):
        if own and not math.isfinite(sum(abs(e.coef) for e in own)):
            return f"{own[0].path}.{'k' if matrix == 'K' else 'c'}"
    if matrix == "C" and scenario.damping is not None:
        return f"damping.{scenario.damping.given}"
    return f"{own[0].path}.{'k' if matrix == 'K' else 'c'}" if own else "mass"


MAX_EDGES = 1_000_000  # force discontinuities in one run: each is a restart of the integration


def check_forces(model, scenario: Scenario) -> None:
    """Refuse forces with more discontinuities than a run can restart at, or not finite on the output grid
    (e.g. exp(9**9), 1/(t-1))."""
    if not model.signals:
        return
    for j, signal in enumerate(model.signals):
        edges = signal.edge_count(scenario.time.start, scenario.time.end, MAX_EDGES)
        if not edges <= MAX_EDGES:
            raise ScenarioError(scenario.path, model.force_paths[j],
                                f"{edges:.3g} discontinuities in the run (limit {MAX_EDGES:.0e}); "
                                "the period is too short for the time span")
    grid = time_grid(scenario.time)
    for j, signal in enumerate(model.signals):
        values = signal.value(grid)
        bad = ~np.isfinite(values)
        if bad.any():
            t_bad = grid[np.argmax(bad)]
            raise ScenarioError(scenario.path, model.force_paths[j], f"force is not finite at t = {t_bad:g} s (value {values[bad][0]})")
