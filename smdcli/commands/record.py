"""`smd record`: a ground acceleration record baseline-corrected, filtered, integrated and measured (PGA, PGV, PGD,
Arias intensity, significant durations, CAV, Housner intensity), written as HDF5 and a PNG.

Must not import: cli.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from smdcli.analysis.record import BASELINES, ProcessedRecord, process
from smdcli.errors import UsageError
from smdcli.io.folders import output_folder
from smdcli.scenario.records import Record
from smdcli.scenario.spec import STANDARD_GRAVITY


@dataclass
class RecordRun:
    """A processed record and the files written."""

    record: Record
    processed: ProcessedRecord
    warnings: list[str] = field(default_factory=list)
    outputs: list[Path] = field(default_factory=list)


def parse_band(text: str | None, step: float, where: str = "--filter") -> tuple[float, float] | None:
    """LOW,HIGH in Hz (0 for an open end) checked against the record's Nyquist frequency; None for no filter."""
    if text is None:
        return None
    parts = [p.strip() for p in str(text).split(",")]
    try:
        low, high = (float(p) for p in parts)
    except ValueError:
        raise UsageError(f"{where}: expected LOW,HIGH in Hz (0 for an open end), found {text!r}") from None
    nyquist = 0.5 / step
    if not (np.isfinite(low) and np.isfinite(high) and low >= 0 and high >= 0 and (low > 0 or high > 0)):
        raise UsageError(f"{where}: expected LOW,HIGH >= 0 Hz, not both 0, found {text!r}")
    if high > 0 and not (low < high < nyquist):
        raise UsageError(f"{where}: expected LOW < HIGH < the Nyquist frequency {nyquist:g} Hz, found {text!r}")
    if high == 0 and not low < nyquist:
        raise UsageError(f"{where}: expected LOW below the Nyquist frequency {nyquist:g} Hz, found {text!r}")
    return low, high


def check_processing(baseline: str, order: int, where: str = "") -> None:
    """One line for a baseline or filter order smd does not know."""
    if baseline not in BASELINES:
        raise UsageError(f"{where}--baseline: expected one of {', '.join(BASELINES)}, found {baseline!r}")
    if not 1 <= order <= 10:
        raise UsageError(f"{where}--order: expected a Butterworth order from 1 to 10, found {order}")


def record_command(path: str | Path, out: str | Path, baseline: str = "none", band: str | None = None,
                   order: int = 4, units: str | None = None, scale: float = 1.0, shift: float = 0.0,
                   plots: bool = True, reading: dict | None = None) -> RecordRun:
    """Read (reading: read_record's format, channel and dt), process and measure the record; write
    OUT/<stem>_record.h5 and .png."""
    from smdcli.commands.spectrum import _record

    path = Path(path)
    check_processing(baseline, order)
    record = _record(path, units, scale, shift, reading)
    if len(record.time) < 3 * (2 * order + 1) and band is not None:
        raise UsageError(f"{record.path}: {len(record.time)} samples are too few to filter at order {order}")
    with np.errstate(over="ignore", invalid="ignore"):
        processed = process(record.time, record.acceleration, baseline, parse_band(band, record.step), order)
    m = processed.measures
    if not all(np.isfinite([m.pga, m.pgv, m.pgd, m.arias, m.cav, m.housner, m.d5_95])):
        raise UsageError(f"{record.path}: the record's measures overflow double precision (peak "
                         f"{np.abs(record.acceleration).max():.3g} m/s^2); check its units and --scale")
    run = RecordRun(record, processed)
    from smdcli.scenario.records import velocity_drift

    warning = velocity_drift(record.path + (" as processed" if baseline != "none" or band else ""),
                             processed.velocity, processed.displacement)
    if warning:
        run.warnings.append(warning + ("" if baseline != "none" or band else " (--baseline, --filter)"))
    out_dir = output_folder(out)
    from smdcli.io.analysis_hdf5 import write_record
    from smdcli.io.atomic import together

    with together():
        h5 = out_dir / f"{path.stem}_record.h5"
        write_record(h5, record, processed)
        run.outputs.append(h5)
        if plots:
            from smdcli.plots.common import save_figure
            from smdcli.plots.record import record_figure

            png = out_dir / f"{path.stem}_record.png"
            save_figure(record_figure(processed, f"{path.name}"), png)
            run.outputs.append(png)
    return run


def record_summary(run: RecordRun) -> dict:
    """The facts of a record run as plain data (SI units)."""
    m, p, r = run.processed.measures, run.processed, run.record
    return {"record": r.path, "status": "ok", "exit_code": 0, "samples": len(r.time), "step_s": r.step,
            "duration_s": float(r.time[-1] - r.time[0]), "units_in_file": r.units, "format": r.format,
            "channel": r.channel, "baseline": p.baseline,
            "filter_hz": list(p.band) if p.band else None, "order": p.order if p.band else None,
            "pga_m_s2": m.pga, "pga_g": m.pga / STANDARD_GRAVITY, "pgv_m_s": m.pgv, "pgd_m": m.pgd,
            "arias_intensity_m_s": m.arias, "d5_95_s": m.d5_95, "d5_75_s": m.d5_75,
            "t5_s": m.t5, "t75_s": m.t75, "t95_s": m.t95, "cav_m_s": m.cav, "housner_si_m": m.housner,
            "final_velocity_m_s": float(p.velocity[-1]), "final_displacement_m": float(p.displacement[-1]),
            "warnings": run.warnings, "outputs": [str(o) for o in run.outputs]}


def format_record(d: dict) -> str:
    """Terminal text for a record run."""
    band = f", band-pass {d['filter_hz'][0]:g}..{d['filter_hz'][1]:g} Hz (order {d['order']}, zero phase)" \
        if d["filter_hz"] else ""
    channel = f", channel {d['channel']}" if d.get("channel") else ""
    lines = [f"{d['record']}: {d['format']}{channel} in {d['units_in_file']}, {d['samples']} samples every "
             f"{d['step_s']:g} s ({d['duration_s']:g} s); baseline {d['baseline']}{band}",
             f"  PGA {d['pga_g']:.4g} g ({d['pga_m_s2']:.4g} m/s^2), PGV {d['pgv_m_s']:.4g} m/s, PGD {d['pgd_m']:.4g} m",
             f"  Arias intensity {d['arias_intensity_m_s']:.4g} m/s; significant duration D5-95 {d['d5_95_s']:.4g} s "
             f"({d['t5_s']:.4g} to {d['t95_s']:.4g} s), D5-75 {d['d5_75_s']:.4g} s",
             f"  CAV {d['cav_m_s']:.4g} m/s; Housner spectrum intensity {d['housner_si_m']:.4g} m",
             f"  ends at velocity {d['final_velocity_m_s']:.3g} m/s, displacement {d['final_displacement_m']:.3g} m"]
    lines += [f"  {w}" for w in d["warnings"]]
    if d["outputs"]:
        lines.append(f"  wrote {', '.join(d['outputs'])}")
    return "\n".join(lines)
