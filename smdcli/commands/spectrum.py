"""`smd spectrum`: the response spectra of a ground-motion record, written as HDF5 and a tripartite PNG.

Must not import: cli.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from smdcli.errors import UsageError
from smdcli.io.folders import output_folder
from smdcli.scenario.record_files import read_record
from smdcli.scenario.records import Record
from smdcli.scenario.spec import STANDARD_GRAVITY
from smdcli.analysis.inelastic import InelasticSpectrum
from smdcli.analysis.shock import ShockSpectrum
from smdcli.analysis.spectrum import Spectrum, response_spectrum

DEFAULT_PERIODS = "logspace(-2,1,200)"
DEFAULT_DAMPING = "0.05"
DEFAULT_Q = "10"
KINDS = ("pseudo", "srs")
MIN_DEFAULT_HZ, MAX_DEFAULT_HZ = 10.0, 10_000.0
MAX_OSCILLATORS = 100_000  # periods x damping ratios in one run
MAX_PIECES = 2e9  # pieces of closed-form response in a shock spectrum run (about 10 s on 2 cores)


@dataclass
class SpectrumRun:
    """A record's spectra and the files written."""

    record: Record
    spectrum: Spectrum | ShockSpectrum
    wall_time_s: float
    warnings: list[str] = field(default_factory=list)
    inelastic: InelasticSpectrum | None = None
    outputs: list[Path] = field(default_factory=list)


def _numbers(option: str, spec: str) -> np.ndarray:
    from smdcli.sweep.spec import parse_values

    try:
        return np.asarray(parse_values(spec), dtype=float)
    except ValueError as exc:
        raise UsageError(f"{option}: {exc}") from None


def spectrum(path: str | Path, out: str | Path, periods: str | None = None, damping: str | None = None,
             units: str | None = None, scale: float = 1.0, shift: float = 0.0, plots: bool = True,
             progress: bool = False, kind: str = "pseudo", q: str | None = None,
             frequencies: str | None = None, ductility: str | None = None, strength: str | None = None,
             law: str | None = None, hardening: float | None = None, reading: dict | None = None) -> SpectrumRun:
    """Read the record, compute Sd, Sv, Sa for every damping ratio and period, write OUT/<stem>_spectrum.*; or with
    kind "srs" the shock response spectrum over natural frequency per Q, OUT/<stem>_srs.*. reading: how the file is
    read (format, channel, dt: read_record's)."""
    import time

    path = Path(path)
    if kind not in KINDS:
        raise UsageError(f"--kind: expected one of {', '.join(KINDS)}, found {kind!r}")
    inelastic = _inelastic_options(ductility, strength, law, hardening)
    if kind == "srs":
        if inelastic is not None:
            raise UsageError("--ductility and --strength belong to --kind pseudo: inelastic spectra of a record")
        if periods is not None or damping is not None:
            raise UsageError("--periods and --damping belong to --kind pseudo; a shock spectrum takes "
                             "--frequencies (Hz) and --q")
        return _shock(path, out, units, scale, shift, plots, q or DEFAULT_Q, frequencies, reading)
    if q is not None or frequencies is not None:
        raise UsageError("--q and --frequencies belong to --kind srs; a pseudo spectrum takes --periods and --damping")
    periods = periods or DEFAULT_PERIODS
    damping = damping or DEFAULT_DAMPING
    T = _numbers("--periods", periods)
    zeta = _numbers("--damping", damping)
    if not (np.isfinite(T).all() and (T > 0).all()):
        raise UsageError(f"--periods: expected positive periods in seconds, found {T[~(np.isfinite(T) & (T > 0))][0]:g}")
    if not (np.isfinite(zeta).all() and (zeta >= 0).all()):
        raise UsageError(f"--damping: expected damping ratios >= 0, found {zeta[~(np.isfinite(zeta) & (zeta >= 0))][0]:g}")
    if len(T) * len(zeta) > MAX_OSCILLATORS:
        raise UsageError(f"--periods x --damping: expected at most {MAX_OSCILLATORS} oscillators, found "
                         f"{len(T)} x {len(zeta)}")
    record = _record(path, units, scale, shift, reading)
    _check_cost(record, T, len(zeta))
    out_dir = output_folder(out)
    from smdcli.progress import bar

    start = time.perf_counter()
    with bar("spectra", len(T) * len(zeta), progress) as advance:
        result = response_spectrum(record.time, record.acceleration, T, zeta, advance)
    if not np.isfinite(result.Sa).all():
        raise UsageError(f"{record.path}: the spectrum overflows double precision (peak acceleration "
                         f"{np.abs(record.acceleration).max():.3g} m/s^2 over periods up to {T.max():g} s); "
                         "check the record's units and --scale")
    inelastic_result = None
    if inelastic is not None:
        from smdcli.analysis.inelastic import constant_ductility, constant_strength

        which, targets, b = inelastic
        with bar(f"constant-{which} spectra", len(T) * len(zeta), progress) as advance:
            if which == "ductility":
                inelastic_result = constant_ductility(record.time, record.acceleration, T, zeta, targets, b, advance)
            else:
                inelastic_result = constant_strength(record.time, record.acceleration, T, zeta, targets, b)
                advance(len(T) * len(zeta))
    run = SpectrumRun(record, result, time.perf_counter() - start, inelastic=inelastic_result)
    warning = record.drift_warning()
    if warning:
        run.warnings.append(warning)
    from smdcli.io.atomic import together
    from smdcli.io.analysis_hdf5 import write_spectrum

    with together():
        h5 = out_dir / f"{path.stem}_spectrum.h5"
        write_spectrum(h5, record, result, inelastic_result)
        run.outputs.append(h5)
        if plots:
            from smdcli.plots.common import save_figure
            from smdcli.plots.spectrum import inelastic_figure, spectrum_figure

            png = out_dir / f"{path.stem}_spectrum.png"
            save_figure(spectrum_figure(result, record, f"Response spectrum of {path.name}"), png)
            run.outputs.append(png)
            if inelastic_result is not None:
                png = out_dir / f"{path.stem}_inelastic.png"
                save_figure(inelastic_figure(inelastic_result, f"Inelastic spectra of {path.name}"), png)
                run.outputs.append(png)
    return run


def _inelastic_options(ductility: str | None, strength: str | None, law: str | None,
                       hardening: float | None) -> tuple[str, np.ndarray, float] | None:
    """("ductility" or "strength", the targets, the hardening ratio b), or None when no inelastic spectrum is
    asked for; refused with one line where the options do not fit together."""
    from smdcli.analysis.inelastic import LAWS

    if ductility is None and strength is None:
        if law is not None or hardening is not None:
            raise UsageError("--law and --hardening need --ductility or --strength (an inelastic spectrum)")
        return None
    if ductility is not None and strength is not None:
        raise UsageError("--ductility and --strength: expected one of them (constant ductility or constant strength)")
    law = law or ("bilinear" if hardening is not None else "elastoplastic")
    if law not in LAWS:
        raise UsageError(f"--law: expected one of {', '.join(LAWS)}, found {law!r}")
    if law == "elastoplastic" and hardening not in (None, 0.0):
        raise UsageError(f"--hardening: an elastoplastic spring has none; use --law bilinear (found {hardening:g})")
    if law == "bilinear" and hardening is None:
        raise UsageError("--law bilinear: expected --hardening b (post-yield stiffness b k, 0 <= b < 1)")
    b = 0.0 if hardening is None else float(hardening)
    if not (0.0 <= b < 1.0):
        raise UsageError(f"--hardening: expected 0 <= b < 1, found {b:g}")
    if ductility is not None:
        targets = _numbers("--ductility", ductility)
        bad = ~(np.isfinite(targets) & (targets >= 1.0))
        if bad.any():
            raise UsageError(f"--ductility: expected ductility factors >= 1, found {targets[bad][0]:g}")
        return "ductility", targets, b
    targets = _numbers("--strength", strength)
    bad = ~(np.isfinite(targets) & (targets > 0.0))
    if bad.any():
        raise UsageError(f"--strength: expected yield strength coefficients Cy = fy / (m g) > 0, found "
                         f"{targets[bad][0]:g}")
    return "strength", targets, b


def _record(path: Path, units: str | None, scale: float, shift: float, reading: dict | None = None) -> Record:
    """The record of a record file (reading: read_record's format, channel and dt), or of a scenario's
    [ground_motion]."""
    reading = {key: value for key, value in (reading or {}).items() if value is not None}
    if path.suffix.lower() == ".toml":
        if units is not None or (scale, shift) != (1.0, 0.0) or reading:
            raise UsageError(f"{path}: --units, --scale, --shift, --format, --channel and --dt apply to a record file; "
                             "a scenario's record takes them from its [ground_motion] table")
        return scenario_record(path)
    return read_record(path, units, scale, shift, **reading)


def default_frequencies(step: float) -> np.ndarray:
    """1/12-octave natural frequencies from 10 Hz to 10 kHz, the top kept below a quarter of the sampling rate
    (the bottom then two decades below it)."""
    top = min(MAX_DEFAULT_HZ, 0.25 / step)
    bottom = min(MIN_DEFAULT_HZ, top / 100)
    bands = int(math.floor(12 * math.log2(top / bottom) + 1e-9))
    return bottom * 2.0 ** (np.arange(bands + 1) / 12)


def _shock(path: Path, out, units: str | None, scale: float, shift: float, plots: bool, q: str,
           frequencies: str | None, reading: dict | None = None) -> SpectrumRun:
    """The shock response spectrum run: OUT/<stem>_srs.h5 and .png."""
    import time

    from smdcli.analysis.shock import shock_response_spectrum

    Q = _numbers("--q", q)
    if not (np.isfinite(Q).all() and (Q > 0).all()):
        raise UsageError(f"--q: expected quality factors > 0 (Q = 1 / (2 zeta)), found {Q[~(np.isfinite(Q) & (Q > 0))][0]:g}")
    F = _numbers("--frequencies", frequencies) if frequencies is not None else None
    if F is not None and not (np.isfinite(F).all() and (F > 0).all()):
        raise UsageError(f"--frequencies: expected natural frequencies in Hz > 0, found {F[~(np.isfinite(F) & (F > 0))][0]:g}")
    if F is not None and len(F) * len(Q) > MAX_OSCILLATORS:
        raise UsageError(f"--frequencies x --q: expected at most {MAX_OSCILLATORS} oscillators, found "
                         f"{len(F)} x {len(Q)}")
    record = _record(path, units, scale, shift, reading)
    F = default_frequencies(record.step) if F is None else F
    pieces = np.maximum(1.0, np.ceil(8 * record.step * F)).sum() * len(Q) * len(record.time)
    if pieces > MAX_PIECES:
        raise UsageError(f"--frequencies x --q: {pieces:.3g} pieces of response to solve over {len(record.time)} "
                         f"samples of {record.path} (limit {MAX_PIECES:.0e}); use fewer or lower frequencies, fewer "
                         "quality factors, or a shorter record")
    out_dir = output_folder(out)
    start = time.perf_counter()
    result = shock_response_spectrum(record.time, record.acceleration, F, Q)
    if not np.isfinite(result.maximax).all():
        raise UsageError(f"{record.path}: the shock spectrum overflows double precision; check the record's units "
                         "and --scale")
    run = SpectrumRun(record, result, time.perf_counter() - start)
    from smdcli.io.atomic import together
    from smdcli.io.analysis_hdf5 import write_shock_spectrum

    with together():
        h5 = out_dir / f"{path.stem}_srs.h5"
        write_shock_spectrum(h5, record, result)
        run.outputs.append(h5)
        if plots:
            from smdcli.plots.common import save_figure
            from smdcli.plots.spectrum import shock_spectrum_figure

            png = out_dir / f"{path.stem}_srs.png"
            save_figure(shock_spectrum_figure(result, record, f"Shock response spectrum of {path.name}"), png)
            run.outputs.append(png)
    return run


def _check_cost(record: Record, periods: np.ndarray, dampings: int) -> None:
    """Refuse, before anything is allocated, periods the record cannot resolve and runs too large to finish."""
    from smdcli.analysis.spectrum import MAX_PIECES_PER_INTERVAL, MAX_WORK, PIECES_PER_PERIOD, spectrum_cost

    most, work = spectrum_cost(len(record.time), record.step, periods, dampings)
    if most > MAX_PIECES_PER_INTERVAL:
        shortest = record.step * PIECES_PER_PERIOD / MAX_PIECES_PER_INTERVAL
        raise UsageError(f"--periods: {periods.min():.3g} s is far below the record's sampling interval "
                         f"{record.step:.3g} s ({record.path}); the shortest period it resolves is {shortest:.3g} s")
    if work > MAX_WORK:
        raise UsageError(f"--periods x --damping: {work:.3g} pieces of closed-form response to solve over {len(record.time)} "
                         f"samples of {record.path} (limit {MAX_WORK:.0e}); use fewer or longer periods, fewer "
                         "damping ratios, or a shorter record")


def scenario_record(path: Path) -> Record:
    """The ground acceleration record of a scenario's [ground_motion] (a table of acceleration), in m/s^2."""
    from smdcli.solvers.run import load
    from smdcli.scenario.records import sampled_record

    sc = load(path)
    ground = sc.ground_motion
    if ground is None or ground.quantity != "acceleration" or ground.shape.type != "table":
        found = "no [ground_motion]" if ground is None else f"a {ground.shape.type} ground {ground.quantity}"
        raise UsageError(f"{path}: expected a scenario whose [ground_motion] is an acceleration record "
                         f'(quantity = "acceleration", type = "table"), found {found}')
    shape = ground.shape
    text = shape.file_text if shape.file else "\n".join(f"{t!r}, {v!r}" for t, v in zip(shape.t, shape.values))
    return sampled_record(sc.path, "ground_motion.t" if not shape.file else "ground_motion.file",
                          shape.file or sc.path, shape.t, shape.values, ground.units, text)


def spectrum_summary(run: SpectrumRun) -> dict:
    """The facts of a spectrum run as plain data: the record, each damping ratio's peak Sa and where."""
    r, s = run.record, run.spectrum
    if isinstance(s, ShockSpectrum):
        return _shock_summary(run)
    peaks = []
    for i, zeta in enumerate(s.damping):
        j = int(np.argmax(s.Sa[i]))
        peaks.append({"damping": float(zeta), "peak_Sa_m_s2": float(s.Sa[i, j]), "peak_Sa_g": float(s.Sa[i, j] / STANDARD_GRAVITY),
                      "at_period_s": float(s.period[j]), "peak_Sd_m": float(s.Sd[i].max())})
    return {"record": r.path, "status": "ok", "exit_code": 0, "kind": "pseudo", "samples": len(r.time), "step_s": r.step,
            "duration_s": float(r.time[-1] - r.time[0]), "units_in_file": r.units,
            "pga_m_s2": float(np.abs(r.acceleration).max()), "periods": len(s.period),
            "period_range_s": [float(s.period.min()), float(s.period.max())],
            "damping": [float(z) for z in s.damping], "peaks": peaks, "wall_time_s": run.wall_time_s,
            **({"inelastic": _inelastic_summary(run.inelastic)} if run.inelastic is not None else {}),
            "warnings": run.warnings, "outputs": [str(p) for p in run.outputs]}


def _inelastic_summary(x: InelasticSpectrum) -> dict:
    """Per target at the first damping ratio: the largest Cy and where, Ry at the longest and shortest period."""
    rows = []
    for k, target in enumerate(x.targets):
        cy = x.Cy[k, 0]
        j = int(np.nanargmax(cy)) if np.isfinite(cy).any() else 0
        rows.append({x.kind: float(target), "damping": float(x.damping[0]), "peak_Cy": float(cy[j]),
                     "at_period_s": float(x.period[j]), "found": int(x.found[k].sum()),
                     "Ry_range": [float(np.nanmin(x.Ry[k])), float(np.nanmax(x.Ry[k]))] if x.found[k].any() else None,
                     "ductility_range": [float(np.nanmin(x.ductility[k])), float(np.nanmax(x.ductility[k]))]
                     if x.found[k].any() else None})
    return {"kind": x.kind, "law": "bilinear" if x.hardening else "elastoplastic", "hardening": x.hardening,
            "targets": [float(t) for t in x.targets], "oscillators": int(x.found.size), "rows": rows}


def _shock_summary(run: SpectrumRun) -> dict:
    """The facts of a shock spectrum run: the record, each Q's largest maximax and where."""
    r, s, g = run.record, run.spectrum, STANDARD_GRAVITY
    peaks = []
    for i, q in enumerate(s.q):
        j = int(np.argmax(s.maximax[i]))
        peaks.append({"q": float(q), "damping": float(1 / (2 * q)), "peak_maximax_g": float(s.maximax[i, j] / g),
                      "at_frequency_hz": float(s.frequency[j]), "peak_positive_g": float(s.positive[i].max() / g),
                      "peak_negative_g": float(s.negative[i].min() / g)})
    return {"record": r.path, "status": "ok", "exit_code": 0, "kind": "srs", "samples": len(r.time), "step_s": r.step,
            "duration_s": float(r.time[-1] - r.time[0]), "units_in_file": r.units,
            "pga_m_s2": float(np.abs(r.acceleration).max()), "frequencies": len(s.frequency),
            "frequency_range_hz": [float(s.frequency.min()), float(s.frequency.max())], "q": [float(q) for q in s.q],
            "peaks": peaks, "wall_time_s": run.wall_time_s, "warnings": run.warnings,
            "outputs": [str(p) for p in run.outputs]}


def format_spectrum(data: dict) -> str:
    """Terminal text for a spectrum run."""
    g = STANDARD_GRAVITY
    if data.get("kind") == "srs":
        lines = [f"{data['record']}: {data['samples']} samples every {data['step_s']:g} s ({data['duration_s']:g} s), "
                 f"peak {data['pga_m_s2'] / g:.4g} g",
                 f"  shock spectrum  {data['frequencies']} natural frequencies {data['frequency_range_hz'][0]:.4g}.."
                 f"{data['frequency_range_hz'][1]:.4g} Hz x {len(data['q'])} Q, absolute acceleration, exact between "
                 f"samples and over the residual; {data['wall_time_s'] * 1e3:.0f} ms"]
        for p in data["peaks"]:
            lines.append(f"  Q {p['q']:<6g} maximax {p['peak_maximax_g']:.4g} g at {p['at_frequency_hz']:.4g} Hz "
                         f"(positive {p['peak_positive_g']:.4g} g, negative {p['peak_negative_g']:.4g} g)")
        lines += [f"  {w}" for w in data["warnings"]]
        if data["outputs"]:
            lines.append(f"  wrote    {', '.join(data['outputs'])}")
        return "\n".join(lines)
    lines = [f"{data['record']}: {data['samples']} samples every {data['step_s']:g} s ({data['duration_s']:g} s), "
             f"PGA {data['pga_m_s2'] / g:.4g} g",
             f"  spectra  {data['periods']} periods {data['period_range_s'][0]:g}..{data['period_range_s'][1]:g} s x "
             f"{len(data['damping'])} damping ratios, exact between samples; {data['wall_time_s'] * 1e3:.0f} ms"]
    for p in data["peaks"]:
        lines.append(f"  zeta {p['damping']:<6g} peak Sa {p['peak_Sa_g']:.4g} g at T = {p['at_period_s']:.4g} s, "
                     f"peak Sd {p['peak_Sd_m']:.4g} m")
    if "inelastic" in data:
        x = data["inelastic"]
        law = x["law"] + (f" b = {x['hardening']:g}" if x["hardening"] else "")
        lines.append(f"  inelastic  constant {x['kind']} ({law}), exact event to event; at zeta {x['rows'][0]['damping']:g}:")
        for r in x["rows"]:
            if x["kind"] == "ductility":
                ry = f"Ry {r['Ry_range'][0]:.3g}..{r['Ry_range'][1]:.3g}" if r["Ry_range"] else "no strength found"
                lines.append(f"    mu {r['ductility']:<5g} peak Cy {r['peak_Cy']:.4g} at T = {r['at_period_s']:.4g} s, "
                             f"{ry}")
            else:
                mu = r["ductility_range"]
                lines.append(f"    Cy {r['strength']:<7g} ductility demand {mu[0]:.3g}..{mu[1]:.3g}")
    lines += [f"  {w}" for w in data["warnings"]]
    if data["outputs"]:
        lines.append(f"  wrote    {', '.join(data['outputs'])}")
    return "\n".join(lines)
