"""`smd rsa`: response-spectrum analysis of a linear scene under a spectrum (a file of `smd spectrum`, or a design
spectrum as a table of period and Sa in g): modes, participation, peaks combined by CQC, SRSS and ABSSUM.

Must not import: cli.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from smdcli.analysis.rsa import COMBINATIONS, ResponseSpectrumAnalysis, response_spectrum_analysis
from smdcli.errors import UsageError
from smdcli.io.folders import output_folder
from smdcli.scenario.spec import STANDARD_GRAVITY


@dataclass
class SpectrumSource:
    """Sa (m/s^2) over period and damping, as read: one row per damping ratio (a design table has one, at 5 %)."""

    path: str
    kind: str  # "smd spectrum file" or "design spectrum table"
    period: np.ndarray
    damping: np.ndarray
    Sa: np.ndarray  # (Z, P)

    def __call__(self, period: np.ndarray, damping: np.ndarray) -> np.ndarray:
        """Sa at each mode's period (linear in log period between tabulated ones) and damping (linear between the
        file's damping ratios; a table's single ratio is used for every mode)."""
        low, high = self.period.min(), self.period.max()
        for T in period:
            if not low * (1 - 1e-12) <= T <= high * (1 + 1e-12):
                raise UsageError(f"{self.path}: a mode's period {T:.6g} s is outside the spectrum's periods "
                                 f"{low:.6g}..{high:.6g} s")
        x = np.log(self.period)
        rows = np.array([np.interp(np.log(period), x, row) for row in self.Sa])  # (Z, modes)
        if len(self.damping) == 1:
            return rows[0]
        return np.array([np.interp(z, self.damping, rows[:, i]) for i, z in enumerate(damping)])


def read_spectrum_source(path: Path) -> SpectrumSource:
    """A spectrum file written by `smd spectrum` (.h5), or a two-column table: period s, Sa in g."""
    if not path.is_file():
        raise UsageError(f"{path}: no such spectrum file")
    if path.suffix.lower() in (".h5", ".hdf5"):
        import h5py

        try:
            with h5py.File(path, "r") as f:
                if "Sa" not in f or "period" not in f:
                    raise UsageError(f"{path}: expected a pseudo spectrum file of `smd spectrum` (with /Sa and "
                                     "/period), found none")
                return SpectrumSource(str(path), "smd spectrum file", f["period"][:], f["damping"][:], f["Sa"][:])
        except OSError as exc:
            raise UsageError(f"{path}: cannot read as HDF5: {exc}") from None
    from smdcli.scenario.records import ColumnsError, read_columns

    try:
        period, sa = read_columns(path, ("period s", "Sa g", "periods"))
    except ColumnsError as exc:
        raise UsageError(f"{path}: {exc}") from None
    if len(period) < 2 or period[0] <= 0 or (sa < 0).any():
        raise UsageError(f"{path}: expected at least two rows of a period > 0 s and Sa >= 0 g, found {len(period)} "
                         f"from {period[0]:g} s, smallest Sa {sa.min():g}")
    return SpectrumSource(str(path), "design spectrum table", period, np.array([0.05]), sa[None, :] * STANDARD_GRAVITY)


@dataclass
class RsaRun:
    """A response-spectrum analysis and the files written."""

    scenario: str
    dofs: tuple[str, ...]
    elements: tuple[str, ...]
    source: SpectrumSource
    analysis: ResponseSpectrumAnalysis
    combination: str
    outputs: list[Path] = field(default_factory=list)


def rsa(path: str | Path, spectrum: str | Path, out: str | Path, combination: str = "cqc", modes: str = "all",
        plots: bool = True) -> RsaRun:
    """Read the scene and the spectrum, combine the modal peaks, write OUT/<stem>_rsa.h5 and .png."""
    from smdcli.model import build
    from smdcli.solvers.run import load

    path = Path(path)
    if combination not in COMBINATIONS:
        raise UsageError(f"--combination: expected one of {', '.join(COMBINATIONS)}, found {combination!r}")
    try:
        count = None if modes == "all" else int(modes)
    except ValueError:
        raise UsageError(f"--modes: expected a number of modes or all, found {modes!r}") from None
    if count is not None and count < 1:
        raise UsageError(f"--modes: expected at least 1, found {count}")
    sc = load(path)
    model = build(sc).dense()  # every mode it combines
    if not model.is_linear:
        raise UsageError(f"{path}: response-spectrum analysis needs a linear scene; this one has nonlinear or "
                         "nonsmooth elements (use smd simulate with its [ground_motion])")
    source = read_spectrum_source(Path(spectrum))
    if np.linalg.eigvalsh(model.K).min() <= 1e-12 * np.abs(model.K).max():
        raise UsageError(f"{path}: the scene has a rigid-body mode (no spring to ground); a response spectrum needs "
                         "every mode to have a period")
    springs = [e for e in model.elements if e.kind == "spring"]
    analysis = response_spectrum_analysis(model.M, model.K, model.C, source, count,
                                          tuple((e.a, e.b, e.coef) for e in springs))
    run = RsaRun(str(path), model.dofs, tuple(e.name for e in springs), source, analysis, combination)
    out_dir = output_folder(out)
    from smdcli.io.atomic import together
    from smdcli.io.analysis_hdf5 import write_rsa

    with together():
        h5 = out_dir / f"{path.stem}_rsa.h5"
        write_rsa(h5, run)
        run.outputs.append(h5)
        if plots:
            from smdcli.plots.common import save_figure
            from smdcli.plots.rsa import rsa_figure

            png = out_dir / f"{path.stem}_rsa.png"
            save_figure(rsa_figure(run), png)
            run.outputs.append(png)
    return run


def rsa_summary(run: RsaRun) -> dict:
    """The facts of an RSA run as plain data."""
    a, m = run.analysis, run.analysis.modes
    modes = [{"mode": i + 1, "period_s": float(m.period[i]), "damping": float(m.damping[i]),
              "participation": float(m.participation[i]), "effective_mass_kg": float(m.effective_mass[i]),
              "cumulative_mass_ratio": float(m.cumulative_ratio[i]),
              "Sa_g": float(a.Sa[i] / STANDARD_GRAVITY) if i < a.used else None} for i in range(len(m.period))]
    combined = {}
    for rule in COMBINATIONS:
        c = a.combined(rule)
        combined[rule] = {"displacement_m": dict(zip(run.dofs, map(float, c["displacement"]))),
                          "element_force_N": dict(zip(run.elements, map(float, c["force"]))),
                          "element_deformation_m": dict(zip(run.elements, map(float, c["deformation"]))),
                          "base_shear_N": float(c["base_shear"])}
    return {"scenario": run.scenario, "status": "ok", "exit_code": 0, "spectrum": run.source.path,
            "spectrum_kind": run.source.kind, "modes_used": a.used, "total_mass_kg": m.total_mass,
            "combination": run.combination, "modes": modes, "combined": combined,
            "outputs": [str(p) for p in run.outputs]}


def format_rsa(data: dict) -> str:
    """Terminal text for an RSA run."""
    lines = [f"{data['scenario']}: response spectrum {data['spectrum']} ({data['spectrum_kind']}), "
             f"{data['modes_used']} of {len(data['modes'])} modes combined by {data['combination'].upper()}",
             "  mode   period [s]   zeta     Gamma    M_eff [kg]  cumulative   Sa [g]"]
    for m in data["modes"]:
        sa = f"{m['Sa_g']:.4g}" if m["Sa_g"] is not None else "-"
        lines.append(f"  {m['mode']:<5} {m['period_s']:11.5g} {m['damping']:7.4f} {m['participation']:9.4g} "
                     f"{m['effective_mass_kg']:12.5g} {m['cumulative_mass_ratio']:10.1%}   {sa}")
    c = data["combined"][data["combination"]]
    lines.append("  peak displacement [m]: " + ", ".join(f"{k} {v:.4g}" for k, v in c["displacement_m"].items()))
    if c["element_force_N"]:
        lines.append("  peak element force [N]: " + ", ".join(f"{k} {v:.4g}" for k, v in c["element_force_N"].items()))
    lines.append(f"  base shear {c['base_shear_N']:.5g} N (total mass {data['total_mass_kg']:.5g} kg)")
    if data["outputs"]:
        lines.append(f"  wrote {', '.join(data['outputs'])}")
    return "\n".join(lines)
