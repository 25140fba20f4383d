"""`smd spectrum`: the response spectra of a ground-motion record, written as HDF5 and a tripartite PNG.

Must not import: cli.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from smdcli.errors import UsageError
from smdcli.io.folders import output_folder
from smdcli.scenario.records import Record, read_record
from smdcli.scenario.spec import STANDARD_GRAVITY
from smdcli.solvers.spectrum import Spectrum, response_spectrum

DEFAULT_PERIODS = "logspace(-2,1,200)"
DEFAULT_DAMPING = "0.05"
MAX_OSCILLATORS = 100_000  # periods x damping ratios in one run


@dataclass
class SpectrumRun:
    """A record's spectra and the files written."""

    record: Record
    spectrum: Spectrum
    wall_time_s: float
    warnings: list[str] = field(default_factory=list)
    outputs: list[Path] = field(default_factory=list)


def _numbers(option: str, spec: str) -> np.ndarray:
    from smdcli.sweep.spec import parse_values

    try:
        return np.asarray(parse_values(spec), dtype=float)
    except ValueError as exc:
        raise UsageError(f"{option}: {exc}") from None


def spectrum(path: str | Path, out: str | Path, periods: str = DEFAULT_PERIODS, damping: str = DEFAULT_DAMPING,
             units: str = "g", scale: float = 1.0, shift: float = 0.0, plots: bool = True,
             progress: bool = False) -> SpectrumRun:
    """Read the record, compute Sd, Sv, Sa for every damping ratio and period, write OUT/<stem>_spectrum.*."""
    import time

    path = Path(path)
    T = _numbers("--periods", periods)
    zeta = _numbers("--damping", damping)
    if not (np.isfinite(T).all() and (T > 0).all()):
        raise UsageError(f"--periods: expected positive periods in seconds, found {T[~(np.isfinite(T) & (T > 0))][0]:g}")
    if not (np.isfinite(zeta).all() and (zeta >= 0).all()):
        raise UsageError(f"--damping: expected damping ratios >= 0, found {zeta[~(np.isfinite(zeta) & (zeta >= 0))][0]:g}")
    if len(T) * len(zeta) > MAX_OSCILLATORS:
        raise UsageError(f"--periods x --damping: expected at most {MAX_OSCILLATORS} oscillators, found "
                         f"{len(T)} x {len(zeta)}")
    if path.suffix.lower() == ".toml":
        if (units, scale, shift) != ("g", 1.0, 0.0):
            raise UsageError(f"{path}: --units, --scale and --shift apply to a record file; a scenario's record "
                             "takes them from its [ground_motion] table")
        record = scenario_record(path)
    else:
        record = read_record(path, units, scale, shift)
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
    run = SpectrumRun(record, result, time.perf_counter() - start)
    warning = record.drift_warning()
    if warning:
        run.warnings.append(warning)
    from smdcli.io.atomic import together
    from smdcli.io.hdf5 import write_spectrum

    with together():
        h5 = out_dir / f"{path.stem}_spectrum.h5"
        write_spectrum(h5, record, result)
        run.outputs.append(h5)
        if plots:
            from smdcli.plots.common import save_figure
            from smdcli.plots.spectrum import spectrum_figure

            png = out_dir / f"{path.stem}_spectrum.png"
            save_figure(spectrum_figure(result, record, f"Response spectrum of {path.name}"), png)
            run.outputs.append(png)
    return run


def _check_cost(record: Record, periods: np.ndarray, dampings: int) -> None:
    """Refuse, before anything is allocated, periods the record cannot resolve and runs too large to finish."""
    from smdcli.solvers.spectrum import MAX_SUB_POINTS, MAX_WORK, POINTS_PER_PERIOD, spectrum_cost

    most, work = spectrum_cost(len(record.time), record.step, periods, dampings)
    if most > MAX_SUB_POINTS:
        shortest = record.step * POINTS_PER_PERIOD / MAX_SUB_POINTS
        raise UsageError(f"--periods: {periods.min():.3g} s is far below the record's sampling interval "
                         f"{record.step:.3g} s ({record.path}); the shortest period it resolves is {shortest:.3g} s")
    if work > MAX_WORK:
        raise UsageError(f"--periods x --damping: {work:.3g} response values to evaluate over {len(record.time)} "
                         f"samples of {record.path} (limit {MAX_WORK:.0e}); use fewer or longer periods, fewer "
                         "damping ratios, or a shorter record")


def scenario_record(path: Path) -> Record:
    """The ground acceleration record of a scenario's [ground_motion] (a table of acceleration), in m/s^2."""
    from smdcli.scenario import load
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
    peaks = []
    for i, zeta in enumerate(s.damping):
        j = int(np.argmax(s.Sa[i]))
        peaks.append({"damping": float(zeta), "peak_Sa_m_s2": float(s.Sa[i, j]), "peak_Sa_g": float(s.Sa[i, j] / STANDARD_GRAVITY),
                      "at_period_s": float(s.period[j]), "peak_Sd_m": float(s.Sd[i].max())})
    return {"record": r.path, "status": "ok", "exit_code": 0, "samples": len(r.time), "step_s": r.step,
            "duration_s": float(r.time[-1] - r.time[0]), "units_in_file": r.units,
            "pga_m_s2": float(np.abs(r.acceleration).max()), "periods": len(s.period),
            "period_range_s": [float(s.period.min()), float(s.period.max())],
            "damping": [float(z) for z in s.damping], "peaks": peaks, "wall_time_s": run.wall_time_s,
            "warnings": run.warnings, "outputs": [str(p) for p in run.outputs]}


def format_spectrum(data: dict) -> str:
    """Terminal text for a spectrum run."""
    g = STANDARD_GRAVITY
    lines = [f"{data['record']}: {data['samples']} samples every {data['step_s']:g} s ({data['duration_s']:g} s), "
             f"PGA {data['pga_m_s2'] / g:.4g} g",
             f"  spectra  {data['periods']} periods {data['period_range_s'][0]:g}..{data['period_range_s'][1]:g} s x "
             f"{len(data['damping'])} damping ratios, exact between samples; {data['wall_time_s'] * 1e3:.0f} ms"]
    for p in data["peaks"]:
        lines.append(f"  zeta {p['damping']:<6g} peak Sa {p['peak_Sa_g']:.4g} g at T = {p['at_period_s']:.4g} s, "
                     f"peak Sd {p['peak_Sd_m']:.4g} m")
    lines += [f"  {w}" for w in data["warnings"]]
    if data["outputs"]:
        lines.append(f"  wrote    {', '.join(data['outputs'])}")
    return "\n".join(lines)
