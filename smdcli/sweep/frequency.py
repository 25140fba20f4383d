"""Frequency responses: the exact receptance of linear members, resonance peaks, and measured responses of
nonlinear ones (see shooting.py).

Must not import: io, plots, commands, cli."""

from __future__ import annotations

import difflib
import math
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from smdcli.errors import ScenarioError, UsageError
from smdcli.model import Model
from smdcli.model.accuracy import modes_accuracy
from smdcli.model.system import GROUND_DOF
from smdcli.scenario import Scenario
from smdcli.sweep.family import Family
from smdcli.sweep.pool import default_workers, run_pool
from smdcli.sweep.shooting import MEASURED_ACCURACY, _measure_direction

# ------------------------------------------------------- frequency response


@dataclass
class FrequencyResponse:
    """Steady-state amplitude per unit force and phase lag, (S, F, n) each, of every member."""

    omega: np.ndarray  # (F,) rad/s
    dofs: tuple[str, ...]
    input_dof: str
    amplitude: np.ndarray  # m/N
    phase: np.ndarray  # rad, lag of displacement behind force
    peaks: list[dict] = field(default_factory=list)
    measured: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)  # direction -> (amp, phase)
    steady: dict[str, np.ndarray] = field(default_factory=dict)  # direction -> (S, F) bool: settled to a period
    exact: bool = True
    difference: float | None = None  # largest |measured - exact| / max exact amplitude, linear scenes
    wall_time_s: float = 0.0
    # Under [ground_motion]: amplitude is the displacement transmissibility |X / U| (absolute motion over the
    # ground's), phase its lag, and this the force transmissibility |F_T| / (k_g |U|), (S, F).
    force_transmissibility: np.ndarray | None = None
    # Stated accuracies of the exact data sets, relative to each one's largest magnitude: amplitudes and phases
    # through the condition of the dynamic stiffness, peaks through how well their zero of slope is determined.
    accuracy: dict[str, float] = field(default_factory=dict)

    @property
    def ground(self) -> bool:
        """Whether this is a transmissibility (the ground moves) rather than a receptance (a force acts)."""
        return self.force_transmissibility is not None


def input_index(model: Model, name: str | None, source: str) -> int:
    """The DOF a unit force acts on: the one named, else that of the first force (not the ground's motion), else the
    first DOF."""
    if name is None:
        return next((dof for dof in model.force_dofs if dof != GROUND_DOF), 0)
    if name not in model.dofs:
        hint = difflib.get_close_matches(name, model.dofs, n=1)
        raise UsageError(f"--input: unknown DOF {name!r} in {source}"
                         + (f" (did you mean {hint[0]!r}?)" if hint else f"; DOFs are {', '.join(model.dofs)}"))
    return model.dofs.index(name)


def receptance(M: np.ndarray, C: np.ndarray, K: np.ndarray, omega: np.ndarray, dof: int) -> np.ndarray:
    """H = (K - w^2 M + i w C)^-1 b for a unit force on `dof`: (S, F, n) complex, all members and frequencies at once.

    A singular dynamic stiffness (an undamped resonance hit exactly) gives an infinite amplitude.
    """
    w = omega[None, :, None, None]
    Z = K[:, None] - w**2 * M[:, None] + 1j * w * C[:, None]
    n = Z.shape[-1]
    b = np.zeros(n, complex)
    b[dof] = 1.0
    if n == 1:
        with np.errstate(divide="ignore", invalid="ignore"):
            H = 1.0 / Z[..., 0]
        return np.where(Z[..., 0] == 0, np.inf, H)
    try:
        return np.linalg.solve(Z, np.broadcast_to(b, Z.shape[:-1])[..., None])[..., 0]
    except np.linalg.LinAlgError:
        H = np.empty(Z.shape[:-1], complex)
        for index in np.ndindex(Z.shape[:2]):
            try:
                H[index] = np.linalg.solve(Z[index], b)
            except np.linalg.LinAlgError:
                H[index] = np.inf
        return H


def transmissibility(M: np.ndarray, C: np.ndarray, K: np.ndarray, omega: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Under a harmonic ground displacement U e^(i w t): the absolute displacement per unit U, (S, F, n) complex,
    and the force through the ground elements per k_g U, (S, F) complex (k_g = 1^T K 1, the stiffness to ground).

    The relative motion solves Z Y = w^2 M 1 U (Z = K - w^2 M + i w C); X = U 1 + Y; the ground feels
    1^T (K + i w C) Y. One DOF: |X / U| = sqrt((1 + (2 zeta r)^2) / ((1 - r^2)^2 + (2 zeta r)^2)), |F_T| / (k U) =
    r^2 |X / U|."""
    ones = np.ones(M.shape[-1])
    w = omega[None, :, None]
    inertia = (M @ ones)[:, None, :] * w**2  # (S, F, n)
    Z = K[:, None] - w[..., None] ** 2 * M[:, None] + 1j * w[..., None] * C[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        try:
            Y = np.linalg.solve(Z, inertia[..., None].astype(complex))[..., 0]
        except np.linalg.LinAlgError:  # an undamped resonance hit exactly
            Y = np.full(Z.shape[:-1], np.inf, complex)
            for index in np.ndindex(Z.shape[:2]):
                try:
                    Y[index] = np.linalg.solve(Z[index], inertia[index])
                except np.linalg.LinAlgError:
                    pass
        grounding = (K @ ones)[:, None, :] + 1j * w * (C @ ones)[:, None, :]  # 1^T (K + i w C), (S, F, n)
        force = (grounding * Y).sum(axis=-1) / (ones @ K @ ones)[:, None]
    return 1.0 + Y, force


def phase_lag(family: Family, omega: np.ndarray, H: np.ndarray) -> np.ndarray:
    """Lag of displacement behind force: for one DOF atan2(w c, k - w^2 m) in [0, pi] (the book's 9-35); unwrapped along frequency for several."""
    if H.shape[-1] == 1:
        c, k, mass = family.C[:, 0, :1], family.K[:, 0, :1], family.M[:, 0, :1]
        return np.arctan2(omega * c, k - omega**2 * mass)[..., None]
    with np.errstate(invalid="ignore"):
        lag = np.unwrap(-np.angle(H), axis=1)
    first = lag[:, :1]
    return lag - 2 * np.pi * np.round(first / (2 * np.pi))


def resonance_peaks(family: Family, omega: np.ndarray, amplitude: np.ndarray, dof: int,
                    ground: bool = False) -> list[dict]:
    """Local maxima of every member's amplitude per DOF, each located as the zero of d|H|^2/dw between grid
    neighbours (well-conditioned, where the maximum of |H| itself is not: its location moves by sqrt(eps)), with
    the accuracy of that location and of the amplitude there."""
    peaks = []
    labels = family.labels
    for s in range(len(family)):
        if not np.any(family.C[s]):
            # Undamped: the peaks are poles at the natural frequencies, of unbounded amplitude.
            model = family.model(s)
            modes = model.modes
            w_error = modes_accuracy(model)["natural_frequencies_rad_s"] * float(modes.natural_frequencies.max())
            for w, shape in zip(modes.natural_frequencies, modes.shapes.T):
                if omega[0] <= w <= omega[-1] and abs(shape[dof]) > 1e-12 * np.abs(shape).max():
                    for j, name in enumerate(family.base.dofs):
                        if abs(shape[j]) > 1e-12 * np.abs(shape).max():
                            peaks.append({"member": s, "label": labels[s], "dof": name, "omega": float(w),
                                          "amplitude": math.inf, "omega_error": w_error,
                                          "amplitude_error": 0.0})
            continue
        matrices = (family.M[s], family.C[s], family.K[s])
        for j, name in enumerate(family.base.dofs):
            a = amplitude[s, :, j]
            for f in range(1, len(omega) - 1):
                if not (a[f] > a[f - 1] and a[f] >= a[f + 1]):
                    continue
                if not np.isfinite(a[f]):
                    peaks.append({"member": s, "label": labels[s], "dof": name, "omega": float(omega[f]),
                                  "amplitude": math.inf, "omega_error": 0.0, "amplitude_error": 0.0})
                    continue
                w, size, w_error, size_error = _peak(matrices, omega[f - 1], omega[f + 1], j, dof, ground)
                peaks.append({"member": s, "label": labels[s], "dof": name, "omega": w, "amplitude": size,
                              "omega_error": w_error, "amplitude_error": size_error})
    return peaks


def amplitude_slope(matrices, w: float, j: int, dof: int, ground: bool,
                    conditioned: bool = True) -> tuple[float, float, float, float]:
    """(d|H_j|^2/dw, |H_j|, the condition number of Z, a bound of the slope's rounding) at w: H = Z^-1 b with
    Z = K - w^2 M + i w C, dH/dw = Z^-1 (db/dw - Z' H), Z' = -2 w M + i C; under ground motion H is the absolute
    motion 1 + Y with b = w^2 M 1. Without `conditioned`, the last two are nan: the condition number is an SVD of
    Z, which cost a 70-mass chain's frequency response 2.3 s of 4.4 when taken at each of Brent's iterates."""
    from scipy.linalg import lu_factor, lu_solve

    M, C, K = matrices
    n = len(M)
    Z = K - w**2 * M + 1j * w * C
    if ground:
        ones = np.ones(n)
        b, db = w**2 * (M @ ones), 2 * w * (M @ ones)
    else:
        b, db = np.zeros(n, complex), np.zeros(n, complex)
        b[dof] = 1.0
    factor = lu_factor(Z, check_finite=False)
    Y = lu_solve(factor, b.astype(complex), check_finite=False)
    dY = lu_solve(factor, db - (-2 * w * M + 1j * C) @ Y, check_finite=False)
    H = Y[j] + 1.0 if ground else Y[j]
    slope = 2.0 * float((np.conj(H) * dY[j]).real)
    if not conditioned:
        return slope, abs(H), math.nan, math.nan
    condition = float(np.linalg.cond(Z))
    rounding = 2.0 * abs(H) * abs(dY[j]) * 8 * n * np.finfo(float).eps * condition
    return slope, abs(H), condition, rounding


def _peak(matrices, low: float, high: float, j: int, dof: int, ground: bool) -> tuple[float, float, float, float]:
    """(w, |H_j(w)|, error of w, error of |H_j|) of the maximum of |H_j| in [low, high]: the zero of its slope where
    the slope falls through zero, bisected by Brent's method to rounding."""
    from scipy.optimize import brentq

    def slope(w):
        return amplitude_slope(matrices, w, j, dof, ground, conditioned=False)[0]

    grid = np.linspace(low, high, 17)
    values = np.array([slope(w) for w in grid])
    falls = np.flatnonzero((values[:-1] > 0) & (values[1:] <= 0))
    if not len(falls):  # flat to rounding: the sample with the largest amplitude
        sizes = [amplitude_slope(matrices, w, j, dof, ground, conditioned=False)[1] for w in grid]
        w = float(grid[int(np.argmax(sizes))])
        return w, float(max(sizes)), float(grid[1] - grid[0]), 0.0
    best = max(falls, key=lambda i: amplitude_slope(matrices, grid[i + 1], j, dof, ground, conditioned=False)[1])
    lo, hi = grid[best], grid[best + 1]
    w = float(brentq(slope, lo, hi, xtol=1e-300, rtol=4 * np.finfo(float).eps))
    _, size, condition, rounding = amplitude_slope(matrices, w, j, dof, ground)
    # The zero moves by the slope's rounding over the slope's own derivative there (a central difference)
    h = 1e-5 * max(w, 1e-300)
    curvature = abs(slope(w + h) - slope(w - h)) / (2 * h)
    w_error = rounding / curvature if curvature > 0 else float(hi - lo)
    w_error = max(w_error, 4 * np.finfo(float).eps * w)
    size_error = 8 * len(matrices[0]) * np.finfo(float).eps * condition * size
    return w, size, float(w_error), float(size_error)


def frequency_accuracy(omega: np.ndarray) -> float:
    """The frequency grid: parsed values (a start:stop:step or linspace), each a few roundings from its decimal."""
    return 4 * float(np.finfo(float).eps) * len(omega)


def exact_accuracy(family: Family, omega: np.ndarray, phase: np.ndarray, peaks: list[dict]) -> dict[str, float]:
    """Stated accuracies of an exact response: a solve of Z = K - w^2 M + i w C is exact for a Z within c n eps of it,
    so |H| and its phase move by c n eps cond(Z) (relative and in radians), at worst over members and frequencies."""
    from smdcli.model.accuracy import EPS

    w = omega[None, :, None, None]
    Z = family.K[:, None] - w**2 * family.M[:, None] + 1j * w * family.C[:, None]
    with np.errstate(all="ignore"):
        condition = np.linalg.cond(Z)
    worst = float(np.nanmax(np.where(np.isfinite(condition), condition, np.inf), initial=1.0))
    n = family.base.n
    amplitude = 8 * n * EPS * worst
    top_phase = float(np.nanmax(np.abs(phase), initial=0.0))
    accuracy = {"amplitude": amplitude, "normalized_amplitude": amplitude + 2 * EPS,
                "force_transmissibility": (n + 2) * amplitude,
                "phase": amplitude / top_phase if top_phase > 0 else 0.0,
                "frequency": frequency_accuracy(omega), "frequency_ratio": 8 * EPS}
    finite = [p for p in peaks if math.isfinite(p["amplitude"])]
    top = max((abs(p["omega"]) for p in peaks), default=0.0)
    tallest = max((p["amplitude"] for p in finite), default=0.0)
    accuracy["peaks/omega"] = max((p["omega_error"] for p in peaks), default=0.0) / top if top > 0 else 0.0
    accuracy["peaks/amplitude"] = (max((p["amplitude_error"] for p in finite), default=0.0) / tallest
                                   if tallest > 0 else 0.0)
    return accuracy


def _driving_force(sc: Scenario) -> int:
    """Index of the sine or cosine force whose frequency a measured response steps through."""
    for force in sc.forces:
        if force.type in ("sine", "cosine"):
            return force.index
    raise ScenarioError(sc.path, "force", "a measured frequency response needs a sine or cosine force to step "
                        "through the frequencies; add one (its amplitude sets the force level)")


def frequency_response(family: Family, workers: int | None = None,
                       progress: Callable[[int], None] | None = None) -> FrequencyResponse:
    """Exact receptance of linear members; measured by simulation to steady state for nonlinear ones (or on request)."""
    start = time.perf_counter()
    spec = family.spec
    omega = spec.frequency
    base = family.base
    dof = input_index(base, spec.input, family.scenario.path)
    linear = base.is_linear
    S, F, n = len(family), len(omega), base.n
    ground = base.ground is not None and spec.input is None
    if ground and (not linear or spec.measure):
        why = f"{base.nonlinear_paths[0]} is nonlinear" if not linear else "--measure was asked for"
        raise UsageError(f"{family.scenario.path}: the transmissibility under [ground_motion] is computed exactly for "
                         f"linear scenes, not measured by simulation; {why} (give --input DOF and a sine [[force]] "
                         "for a measured receptance, or simulate each frequency)")
    forces = None
    if linear and ground:
        H, forces = transmissibility(family.M, family.C, family.K, omega)
        amplitude = np.abs(H)
        with np.errstate(invalid="ignore"):
            lag = np.unwrap(-np.angle(H), axis=1)
        phase = lag - 2 * np.pi * np.round(lag[:, :1] / (2 * np.pi))
        peaks = resonance_peaks(family, omega, amplitude, dof, ground=True)
    elif linear:
        H = receptance(family.M, family.C, family.K, omega, dof)
        amplitude, phase = np.abs(H), phase_lag(family, omega, H)
        peaks = resonance_peaks(family, omega, amplitude, dof)
    else:
        amplitude = phase = np.full((S, F, n), np.nan)
        peaks = []
    response = FrequencyResponse(omega, base.dofs, "ground" if ground else base.dofs[dof], amplitude, phase, peaks,
                                 exact=linear, force_transmissibility=None if forces is None else np.abs(forces))
    if linear:
        response.accuracy = exact_accuracy(family, omega, phase, peaks)
    if linear and not spec.measure:
        response.wall_time_s = time.perf_counter() - start
        if progress:
            progress(S)
        return response
    directions = ("up", "down") if spec.direction == "both" else (spec.direction,)
    tasks = []
    for s in range(S):
        member = family.member_scenario(s)
        index = _driving_force(member)
        for d in directions:
            tasks.append((member, omega if d == "up" else omega[::-1], index))
    # Each task (a member's sweep in one direction) is sequential along frequency, each frequency starting from the
    # last one's state; tasks run side by side in processes: on threads the Duffing sweep took 2.3-2.6 s against
    # 1.3-1.7 s, each frequency's Python set-up around its compiled shooting solve holding the GIL.
    outcomes = run_pool(_measure_direction, tasks, workers or default_workers(), progress, steps=True)
    for i, d in enumerate(directions):
        amp = np.stack([outcomes[s * len(directions) + i][0] for s in range(S)])
        lag = np.stack([outcomes[s * len(directions) + i][1] for s in range(S)])
        settled = np.stack([outcomes[s * len(directions) + i][2] for s in range(S)])
        if d == "down":
            amp, lag, settled = amp[:, ::-1], lag[:, ::-1], settled[:, ::-1]
        response.measured[d] = (amp, lag)
        response.steady[d] = settled
        for s in range(S):
            for j, name in enumerate(base.dofs):
                if np.isfinite(amp[s, :, j]).any():
                    f = int(np.nanargmax(amp[s, :, j]))
                    response.peaks.append({"member": s, "label": family.labels[s], "dof": name, "direction": d,
                                           "omega": float(omega[f]), "amplitude": float(amp[s, f, j])})
    response.accuracy["measured"] = MEASURED_ACCURACY
    if not linear:  # the peaks are the measured ones: at a grid frequency, of a measured amplitude
        response.accuracy.update({"peaks/omega": 0.0, "peaks/amplitude": MEASURED_ACCURACY,
                                  "frequency": frequency_accuracy(omega)})
    if linear:
        amp = response.measured[directions[0]][0]
        ok = np.isfinite(amplitude) & np.isfinite(amp)
        response.difference = float(np.abs(amp - amplitude)[ok].max() / amplitude[ok].max())
    response.wall_time_s = time.perf_counter() - start
    return response
