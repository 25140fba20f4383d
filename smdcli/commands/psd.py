"""`smd psd`: random vibration of a linear scene under a support acceleration PSD (g^2/Hz, as test standards give
it) or a force PSD on a mass: response PSDs and RMS values of every DOF and element force.

Must not import: cli.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from smdcli.analysis.random_vibration import (Profile, input_vector, profile_variance, quantities, state_matrix,
                                              transfer, white_noise_variance)
from smdcli.errors import UsageError
from smdcli.io.folders import output_folder
from smdcli.scenario.spec import STANDARD_GRAVITY

CURVE_POINTS = 2000  # log-spaced frequencies of the response PSD curves written and drawn
MODE_POINTS = 201  # more of them across each mode's half-power band (+-10 bandwidths)


@dataclass
class PsdRun:
    """A random-vibration analysis and the files written."""

    scenario: str
    dofs: tuple[str, ...]
    support: bool
    on: str | None
    units: str  # of the input PSD: g^2/Hz, (m/s^2)^2/Hz or N^2/Hz
    profile: Profile | None  # in SI per Hz; None for white noise
    white: float | None  # SI per Hz
    names: tuple[str, ...]
    groups: tuple[str, ...]
    rms: np.ndarray
    method: str
    frequency: np.ndarray
    input_psd: np.ndarray
    response_psd: np.ndarray  # (F, q)
    natural_hz: np.ndarray
    damping: np.ndarray
    outputs: list[Path] = field(default_factory=list)


def read_profile(spec: str, factor: float, option: str = "--input") -> tuple[Profile | None, float | None]:
    """(profile, None) from a two-column table of Hz and level, or (None, level) from white:LEVEL; levels in SI (the
    file's times factor); errors name the option that gave it."""
    if spec.startswith("white:"):
        try:
            level = float(spec[len("white:"):])
        except ValueError:
            raise UsageError(f"{option}: expected white:LEVEL with a number, found {spec!r}") from None
        if not (math.isfinite(level) and level > 0):
            raise UsageError(f"{option}: expected a white-noise level > 0, found {spec!r}")
        if not math.isfinite(level * factor):
            raise UsageError(f"{option}: {spec}: the level overflows double precision once converted to SI")
        return None, level * factor
    from smdcli.scenario.records import ColumnsError, read_columns

    path = Path(spec)
    if not path.exists():
        raise UsageError(f"{option}: {spec}: no such PSD profile (a two-column table of Hz and level, or white:LEVEL)")
    try:
        frequency, level = read_columns(path, ("frequency Hz", "level", "frequencies"))
    except ColumnsError as exc:
        raise UsageError(f"{path}: {exc}") from None
    if len(frequency) < 2 or frequency[0] <= 0 or (level <= 0).any():
        raise UsageError(f"{path}: expected at least two breakpoints of a frequency > 0 Hz and a level > 0, found "
                         f"{len(frequency)} from {frequency[0]:g} Hz, smallest level {level.min():g}")
    with np.errstate(over="ignore"):
        levels = level * factor
    if not np.isfinite(levels).all():
        raise UsageError(f"{path}: a level overflows double precision once converted to SI; check --units")
    return Profile(frequency, levels), None


def psd(path: str | Path, spec: str, out: str | Path, on: str | None = None, units: str = "g",
        plots: bool = True) -> PsdRun:
    """Read the scene and the input PSD, compute the response PSDs and RMS values, write OUT/<stem>_psd.*."""
    from smdcli.model import build
    from smdcli.solvers.run import load

    path = Path(path)
    support = on is None
    if support and units not in ("g", "m/s^2"):
        raise UsageError(f"--units: expected g or m/s^2 for a support acceleration PSD, found {units!r}")
    factor = (STANDARD_GRAVITY**2 if units == "g" else 1.0) if support else 1.0
    profile, white = read_profile(spec, factor)
    sc = load(path)
    model = build(sc).dense()  # every mode, in the frequency domain
    if not model.is_linear:
        raise UsageError(f"{path}: random vibration by frequency response needs a linear scene; this one has "
                         "nonlinear or nonsmooth elements")
    if not support and on not in model.dofs:
        raise UsageError(f"--on: expected a mass of {path} ({', '.join(model.dofs[:8])}), found {on!r}")
    M, C, K = model.M, model.C, model.K
    if np.linalg.eigvalsh(K).min() <= 1e-12 * np.abs(K).max():
        raise UsageError(f"{path}: the scene has a rigid-body mode (no spring to ground): its stationary response "
                         "to random input is unbounded")
    modes = model.modes
    natural_hz = modes.natural_frequencies / (2 * math.pi)
    springs = [(e.name, e.a, e.b, e.coef) for e in model.elements if e.kind == "spring"]
    dampers = [(e.name, e.a, e.b, e.coef) for e in model.elements if e.kind == "damper"]
    Q = quantities(M, C, K, model.dofs, springs, dampers)
    A = state_matrix(M, C, K)
    B = input_vector(M, support, None if support else model.dofs.index(on))
    with np.errstate(over="ignore", invalid="ignore"):  # an overflow is refused below, in one line
        variance = _variance(A, B, Q, profile, white, support, natural_hz)
    if white is not None:
        method = "white noise over all frequencies: the Lyapunov equation, exact"
        low, high = natural_hz.min() / 20, natural_hz.max() * 20
    else:
        method = "profile: |H|^2 S integrated per segment (quad_vec, relative 1e-12)"
        low, high = profile.frequency[0], profile.frequency[-1]
    direct = np.zeros(len(variance), dtype=bool)  # a force's own mass under white noise: infinite by right
    if not support and white is not None:
        accel = [i for i, g in enumerate(Q.groups) if g == "acceleration"]
        direct[[accel[j] for j in np.flatnonzero(B[len(M):])]] = True
    finite = np.isfinite(variance) | (np.isposinf(variance) & direct)
    if not finite.all():
        raise UsageError(f"{path}: the response to {spec} overflows double precision; check the input's levels "
                         "and --units")
    f = _curve_frequencies(low, high, natural_hz, modes.damping_ratios)
    H = transfer(A, B, Q, f, support)
    S = np.full_like(f, white) if white is not None else profile(f)
    run = PsdRun(str(path), model.dofs, support, on, ("g^2/Hz" if units == "g" else "(m/s^2)^2/Hz") if support
                 else "N^2/Hz", profile, white, Q.names, Q.groups, np.sqrt(variance), method, f, S,
                 np.abs(H) ** 2 * S[:, None], natural_hz, modes.damping_ratios)
    out_dir = output_folder(out)
    from smdcli.io.analysis_hdf5 import write_psd
    from smdcli.io.atomic import together

    with together():
        h5 = out_dir / f"{path.stem}_psd.h5"
        write_psd(h5, run)
        run.outputs.append(h5)
        if plots:
            from smdcli.plots.common import save_figure
            from smdcli.plots.psd import psd_figure

            png = out_dir / f"{path.stem}_psd.png"
            save_figure(psd_figure(run), png)
            run.outputs.append(png)
    return run


def _variance(A, B, Q, profile, white, support: bool, natural_hz) -> np.ndarray:
    """Each quantity's variance: exact for white noise, by quadrature for a profile."""
    if white is not None:
        return white_noise_variance(A, B, Q, white, support)
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # quad_vec's notices of an overflowing integrand: refused by the caller
        return profile_variance(A, B, Q, profile, support, natural_hz)


def _curve_frequencies(low: float, high: float, natural_hz: np.ndarray, zeta: np.ndarray) -> np.ndarray:
    """Log-spaced frequencies over [low, high] and a dense band across each mode's resonance inside it."""
    parts = [np.geomspace(low, high, CURVE_POINTS)]
    for fn, z in zip(natural_hz, zeta):
        width = max(z, 1e-4) * fn
        band = np.linspace(fn - 10 * width, fn + 10 * width, MODE_POINTS)
        parts.append(band[(band >= low) & (band <= high)])
    return np.unique(np.concatenate(parts))


def miles(fn: float, zeta: float, level_g2: float) -> float:
    """Miles' equation: Grms = sqrt(pi / 2 fn Q S(fn)), Q = 1 / (2 zeta), S in g^2/Hz."""
    return math.sqrt(math.pi / 2 * fn * (1 / (2 * zeta)) * level_g2)


def psd_summary(run: PsdRun) -> dict:
    """The facts of a random-vibration run as plain data (RMS in SI; accelerations also in g)."""
    rms = {}
    for name, group, value in zip(run.names, run.groups, run.rms):
        rms.setdefault(group, {})[name] = float(value)
    data = {"scenario": run.scenario, "status": "ok", "exit_code": 0,
            "input": "support acceleration" if run.support else f"force on {run.on}", "input_units": run.units,
            "white_noise": run.white is not None, "method": run.method,
            "natural_frequencies_hz": [float(f) for f in run.natural_hz],
            "rms": rms, "outputs": [str(p) for p in run.outputs]}
    if run.support:
        data["rms_acceleration_g"] = {k: v / STANDARD_GRAVITY for k, v in rms["acceleration"].items()}
        level = (run.white if run.white is not None else float(run.profile(np.array([run.natural_hz[0]]))[0]))
        if len(run.dofs) == 1 and run.damping[0] > 0 and level > 0:  # Miles needs the input at fn
            data["miles_grms_g"] = miles(float(run.natural_hz[0]), float(run.damping[0]),
                                         level / STANDARD_GRAVITY**2)
        if run.profile is not None:
            data["input_grms_g"] = run.profile.rms / STANDARD_GRAVITY
    return data


def format_psd(d: dict) -> str:
    """Terminal text for a random-vibration run."""
    lines = [f"{d['scenario']}: random vibration, {d['input']} ({d['input_units']}); {d['method']}"]
    if "input_grms_g" in d:
        lines.append(f"  input    {d['input_grms_g']:.4g} g RMS")
    fn = ", ".join(f"{f:.4g}" for f in d["natural_frequencies_hz"][:6])
    lines.append(f"  modes    {fn}{' ...' if len(d['natural_frequencies_hz']) > 6 else ''} Hz")
    for dof, x in d["rms"]["displacement"].items():
        acc = (f"{d['rms_acceleration_g'][dof]:.4g} g" if "rms_acceleration_g" in d
               else f"{d['rms']['acceleration'][dof]:.4g} m/s^2")
        lines.append(f"  {dof:<8} RMS displacement {x:.4g} m, velocity {d['rms']['velocity'][dof]:.4g} m/s, "
                     f"acceleration {acc}")
    for group in ("spring_force", "damper_force"):
        if d["rms"].get(group):
            lines.append(f"  RMS {group.replace('_', ' ')} [N]: " +
                         ", ".join(f"{k} {v:.4g}" for k, v in d["rms"][group].items()))
    if "miles_grms_g" in d:
        lines.append(f"  Miles' equation sqrt(pi/2 fn Q S(fn)): {d['miles_grms_g']:.4g} g (assumes a flat input "
                     "around fn and light damping)")
    if d["outputs"]:
        lines.append(f"  wrote {', '.join(d['outputs'])}")
    return "\n".join(lines)
