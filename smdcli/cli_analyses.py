"""Commands that analyse a record or a scene: spectrum (response, inelastic and shock spectra), record
(processing and intensity measures), psd (random vibration), rsa (response-spectrum analysis).

Must not import: scipy, matplotlib, h5py at module level (the commands import what they need inside).
"""

from __future__ import annotations

from pathlib import Path
from typing import List, Optional

import typer

from smdcli.cli_support import _carried_out
from smdcli.progress import wanted as progress_wanted


# How a record file is read, as smd spectrum and smd record both take it
RECORD_UNITS = typer.Option(None, "--units", help="The record's units: g (default), m/s^2, cm/s^2, mm/s^2, gal "
                            "(cm/s^2), in/s^2 or ft/s^2; an AT2 or COSMOS file's own.")
RECORD_FORMAT = typer.Option(None, "--format", help="at2, cosmos, csv (two columns) or one_column (default: by "
                             "extension, .AT2, .V2, .V2c; one_column with --dt).")
RECORD_CHANNEL = typer.Option(None, "--channel", help="A COSMOS file's acceleration series, 1-based (default 1).")
RECORD_DT = typer.Option(None, "--dt", help="A one-column file's sampling interval, s.")
RECORD_SCALE = typer.Option(1.0, "--scale", help="Multiply the record's values by this.")
RECORD_SHIFT = typer.Option(0.0, "--shift", help="Then add this (in the record's units).")


def spectrum(
    record: Path = typer.Argument(..., help="Ground acceleration record: two columns (time s, acceleration), "
                                  "CSV or whitespace, header optional; a PEER .AT2, a COSMOS .V2; one column "
                                  "with --dt; or a scenario."),
    kind: str = typer.Option("pseudo", "--kind", help="pseudo: Sd, Sv, Sa over period; srs: shock response "
                             "spectrum, peak absolute acceleration over natural frequency."),
    periods: Optional[str] = typer.Option(None, "--periods", help="pseudo: periods in s, a, b, c | start:stop:step "
                                          "| linspace(a,b,n) | logspace(a,b,n) (default logspace(-2,1,200))."),
    damping: Optional[str] = typer.Option(None, "--damping", help="pseudo: damping ratios, 0.02,0.05,0.1 or "
                                          "linspace(a,b,n) (default 0.05)."),
    q: Optional[str] = typer.Option(None, "--q", help="srs: quality factors Q = 1/(2 zeta), e.g. 10 or 10,25 "
                                    "(default 10)."),
    frequencies: Optional[str] = typer.Option(None, "--frequencies", help="srs: natural frequencies in Hz, as "
                                              "--periods (default 1/12 octave, 10 Hz to 10 kHz)."),
    ductility: Optional[str] = typer.Option(None, "--ductility", help="Also constant-ductility spectra for these "
                                            "ductility factors, e.g. 1,2,4,8 (the largest strength giving each)."),
    strength: Optional[str] = typer.Option(None, "--strength", help="Or constant-strength spectra (ductility "
                                           "demand) for these yield strength coefficients Cy = fy/(m g)."),
    law: Optional[str] = typer.Option(None, "--law", help="Inelastic spectra: elastoplastic (default) or bilinear."),
    hardening: Optional[float] = typer.Option(None, "--hardening", help="Bilinear: post-yield stiffness ratio b, "
                                              "0 <= b < 1."),
    units: Optional[str] = RECORD_UNITS,
    file_format: Optional[str] = RECORD_FORMAT,
    channel: Optional[int] = RECORD_CHANNEL,
    dt: Optional[float] = RECORD_DT,
    scale: float = RECORD_SCALE,
    shift: float = RECORD_SHIFT,
    out: Path = typer.Option(Path("results"), "-o", "--out", help="Output folder."),
    no_plots: bool = typer.Option(False, "--no-plots", help="Write the HDF5 file only."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Print errors only."),
    as_json: bool = typer.Option(False, "--json", help="Print the summary as JSON."),
):
    """Response spectra of a record (elastic, inelastic, shock), exact between samples.

    Pseudo spectra Sd, Sv, Sa: OUT/<stem>_spectrum.h5 and a tripartite OUT/<stem>_spectrum.png. --ductility or
    --strength: inelastic spectra too, in the file's /inelastic and OUT/<stem>_inelastic.png. --kind srs: the shock
    response spectrum, OUT/<stem>_srs.h5 and OUT/<stem>_srs.png."""
    from smdcli.commands.spectrum import format_spectrum, spectrum_summary
    from smdcli.commands.spectrum import spectrum as run_spectrum

    _carried_out(lambda: run_spectrum(record, out, periods, damping, units, scale, shift, plots=not no_plots,
                                      progress=progress_wanted(quiet, as_json), kind=kind, q=q,
                                      frequencies=frequencies, ductility=ductility, strength=strength, law=law,
                                      hardening=hardening,
                                      reading={"format": file_format, "channel": channel, "dt": dt}),
                 {"record": str(record)}, as_json, quiet, spectrum_summary, lambda _, data: format_spectrum(data))


def record(
    record_file: Path = typer.Argument(..., metavar="RECORD", help="Ground acceleration record: two columns (time s, "
                                       "acceleration), CSV or whitespace, header optional; a PEER .AT2, a COSMOS "
                                       ".V2; one column with --dt; or a scenario."),
    baseline: str = typer.Option("none", "--baseline", help="none, linear or quadratic: the least-squares "
                                 "polynomial of the acceleration subtracted."),
    band: Optional[str] = typer.Option(None, "--filter", help="LOW,HIGH in Hz: zero-phase Butterworth band-pass "
                                       "(0 for an open end: 0,25 low-pass, 0.1,0 high-pass)."),
    order: int = typer.Option(4, "--order", help="The Butterworth filter's order (applied forwards and backwards)."),
    units: Optional[str] = RECORD_UNITS,
    file_format: Optional[str] = RECORD_FORMAT,
    channel: Optional[int] = RECORD_CHANNEL,
    dt: Optional[float] = RECORD_DT,
    scale: float = RECORD_SCALE,
    shift: float = RECORD_SHIFT,
    out: Path = typer.Option(Path("results"), "-o", "--out", help="Output folder."),
    no_plots: bool = typer.Option(False, "--no-plots", help="Write the HDF5 file only."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Print errors only."),
    as_json: bool = typer.Option(False, "--json", help="Print the summary as JSON."),
):
    """Process a record (baseline, band-pass) and measure it: PGA, PGV, PGD, Arias, D5-95, CAV.

    Also D5-75 and Housner intensity; writes OUT/<stem>_record.h5 and OUT/<stem>_record.png (acceleration,
    velocity, displacement and the Husid plot)."""
    from smdcli.commands.record import format_record, record_command, record_summary

    _carried_out(lambda: record_command(record_file, out, baseline, band, order, units, scale, shift,
                                        plots=not no_plots,
                                        reading={"format": file_format, "channel": channel, "dt": dt}),
                 {"record": str(record_file)}, as_json, quiet, record_summary, lambda _, data: format_record(data))


def psd(
    scenario: Path = typer.Argument(..., help="Scenario TOML file of a linear scene."),
    profile: str = typer.Option(..., "--input", help="The input PSD: a two-column table (Hz, level per Hz, log-log "
                                "between breakpoints), or white:LEVEL for white noise over all frequencies."),
    on: Optional[str] = typer.Option(None, "--on", help="A force PSD (N^2/Hz) on this mass; default: a support "
                                     "acceleration PSD."),
    units: str = typer.Option("g", "--units", help="A support PSD's units: g (g^2/Hz) or m/s^2 ((m/s^2)^2/Hz)."),
    out: Path = typer.Option(Path("results"), "-o", "--out", help="Output folder."),
    no_plots: bool = typer.Option(False, "--no-plots", help="Write the HDF5 file only."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Print errors only."),
    as_json: bool = typer.Option(False, "--json", help="Print the summary as JSON."),
):
    """Random vibration: response PSDs and RMS of every DOF and element force under a PSD.

    The input is a support acceleration or a force PSD (white noise solved exactly, by the Lyapunov equation);
    writes OUT/<stem>_psd.h5 and OUT/<stem>_psd.png."""
    from smdcli.commands.psd import format_psd, psd_summary
    from smdcli.commands.psd import psd as run_psd

    _carried_out(lambda: run_psd(scenario, profile, out, on, units, plots=not no_plots),
                 {"scenario": str(scenario)}, as_json, quiet, psd_summary, lambda _, data: format_psd(data))


def rsa(
    scenario: Path = typer.Argument(..., help="Scenario TOML file of a linear scene."),
    spectrum_file: Path = typer.Option(..., "--spectrum", help="A spectrum file of smd spectrum (.h5), or a design "
                                       "spectrum: two columns, period s and Sa in g."),
    combination: str = typer.Option("cqc", "--combination", help="cqc, srss or abssum (the file holds all three)."),
    modes: str = typer.Option("all", "--modes", help="The lowest N modes, or all."),
    out: Path = typer.Option(Path("results"), "-o", "--out", help="Output folder."),
    no_plots: bool = typer.Option(False, "--no-plots", help="Write the HDF5 file only."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Print errors only."),
    as_json: bool = typer.Option(False, "--json", help="Print the summary as JSON."),
):
    """Response-spectrum analysis: modes, participation, effective masses, CQC/SRSS/ABSSUM peaks.

    Peak displacements, element forces and base shear combined by each rule; writes OUT/<stem>_rsa.h5 and
    OUT/<stem>_rsa.png."""
    from smdcli.commands.rsa import format_rsa, rsa_summary
    from smdcli.commands.rsa import rsa as run_rsa

    _carried_out(lambda: run_rsa(scenario, spectrum_file, out, combination, modes, plots=not no_plots),
                 {"scenario": str(scenario)}, as_json, quiet, rsa_summary, lambda _, data: format_rsa(data))


def sensitivity(
    scenario: Path = typer.Argument(..., help="Scenario TOML file: a linear, yielding, friction, stop or "
                                  "smooth nonlinear scene."),
    param: List[str] = typer.Option(..., "--param", help="A parameter path, as a sweep takes it (repeat): "
                                    "spring[0].k, damper[1].c, mass.m1.m, mass.m1.x0, force[0].amplitude, "
                                    "force[0].omega, ground_motion.scale, damping.modal, system.K[0][0] ..."),
    out: Path = typer.Option(Path("results"), "-o", "--out", help="Output folder."),
    no_plots: bool = typer.Option(False, "--no-plots", help="Write the HDF5 file only."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Print errors only."),
    as_json: bool = typer.Option(False, "--json", help="Print the peaks' derivatives as JSON."),
):
    """Sensitivities dx/dp of a scene's response to its parameters, and of each DOF's peak.

    Linear scenes exactly (the scene and its sensitivity equations solved together by the matrix exponential);
    elastoplastic and bilinear springs, Coulomb friction and stops exactly event to event (each event's time
    derivative and the jump it makes); cubic springs, quadratic dampers and Bouc-Wen springs by the forward
    sensitivity equations; where a derivative does not exist (a graze) nan from there, and a note; writes
    OUT/<stem>_sensitivity.h5 (d_displacement, d_velocity, d_acceleration per unit of each parameter) and
    OUT/<stem>_sensitivity.png (p dx/dp of each DOF)."""
    from smdcli.commands.sensitivity import format_sensitivity, sensitivity_command, sensitivity_summary

    _carried_out(lambda: sensitivity_command(scenario, list(param), out, plots=not no_plots,
                                             progress=progress_wanted(quiet, as_json)),
                 {"scenario": str(scenario)}, as_json, quiet, sensitivity_summary,
                 lambda _, data: format_sensitivity(data))


def fit(
    scenarios: List[Path] = typer.Argument(..., help="Scenario TOML files, one per test of the same specimen "
                                           "(parameters with the same path are shared)."),
    data: Optional[List[Path]] = typer.Option(None, "--data", help="Measured data per scenario (repeat, in order): "
                                              "a CSV of time and columns <mass>.displacement|velocity|acceleration "
                                              "or <element>.force (units as 'm1.acceleration \\[g]'), or an smd HDF5 "
                                              "result. Default: each scenario's \\[fit] data."),
    param: Optional[List[str]] = typer.Option(None, "--param", help="A parameter path to fit (repeat), as a sweep "
                                              "takes it. Default: \\[fit] parameters."),
    bound: Optional[List[str]] = typer.Option(None, "--bound", help="PATH=LOWER:UPPER (repeat). Default: \\[fit] "
                                              "bounds; a positive parameter is kept positive."),
    max_iterations: int = typer.Option(100, "--max-iterations", help="Evaluations allowed before the fit stops "
                                       "unconverged (exit 1, the best point written): half for the whole data at "
                                       "once, the rest for growing spans of it where that stalls."),
    out: Path = typer.Option(Path("results"), "-o", "--out", help="Output folder."),
    no_plots: bool = typer.Option(False, "--no-plots", help="Write the HDF5 and TOML files only."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Print errors only."),
    as_json: bool = typer.Option(False, "--json", help="Print the estimates as JSON."),
):
    """Fit parameters to measured response: bounded least squares on exact sensitivities, with uncertainty.

    Writes OUT/<stem>_fit.h5 (estimates, standard errors, covariance, correlation, 95 % intervals, measured and
    fitted channels, history), OUT/<stem>_fitted.toml per scenario (runs as it is) and OUT/<stem>_fit.png. Exit 1
    when the fit does not converge within --max-iterations."""
    from smdcli.commands.fit import fit_command, fit_summary, format_fit

    run = _carried_out(lambda: fit_command(list(scenarios), list(data or []), list(param or []), list(bound or []),
                                           out, max_iterations, plots=not no_plots,
                                           progress=progress_wanted(quiet, as_json)),
                       {"scenario": str(scenarios[0])}, as_json, quiet, fit_summary, lambda _, d: format_fit(d))
    if not run.converged:
        raise typer.Exit(1)


def optimize(
    scenario: Path = typer.Argument(..., help="Scenario TOML file."),
    param: Optional[List[str]] = typer.Option(None, "--param", help="PATH=LO:HI, a parameter path as a sweep takes "
                                              "it and its bounds (repeat): spring[1].k=10:100, damper[0].c=0.1:5. "
                                              "Default: \\[optimize] parameters."),
    minimize: Optional[str] = typer.Option(None, "--minimize", help="peak_receptance:DOF (the largest |x/F| over "
                                           "all frequencies), peak_transmissibility:DOF (under support motion), "
                                           "rms:DOF, rms_drift:A-B or rms_acceleration:DOF (RMS under white noise of "
                                           "one-sided PSD 1 N^2/Hz on the input, 1 (m/s^2)^2/Hz on a shaking support, "
                                           "or --input-psd), "
                                           "or of the scenario's own run peak_displacement:DOF, peak_drift:A-B, "
                                           "peak_acceleration:DOF, residual_displacement:DOF, dissipated:ELEMENT "
                                           "(damper[0], friction[0]: the energy it dissipates, J). Default: "
                                           "\\[optimize] "
                                           "minimize."),
    subject_to: Optional[List[str]] = typer.Option(None, "--subject-to", help="'OBJECTIVE <= VALUE' (repeat): a "
                                                   "constraint on another measure, as --minimize names it "
                                                   "('peak_receptance:tmd <= 0.8')."),
    records: Optional[str] = typer.Option(None, "--records", help="A,B,...: record files, each in turn replacing "
                                          "the scenario's \\[ground_motion] file (its units and processing kept), "
                                          "for a time-domain objective."),
    over: str = typer.Option("max", "--over", help="With --records: max (the worst record, minimized as a minimax) "
                             "or mean."),
    starts: Optional[int] = typer.Option(None, "--starts", help="Local searches (default 8): from the scenario's "
                                         "values and a Latin hypercube in the bounds; every distinct optimum is "
                                         "reported."),
    input_dof: Optional[str] = typer.Option(None, "--input", help="The DOF a unit force acts on for the frequency "
                                            "objectives (default: the first force's)."),
    input_psd: Optional[str] = typer.Option(None, "--input-psd", help="The rms measures' input PSD, as smd psd "
                                            "takes it: a two-column file of Hz and one-sided level (log-log between "
                                            "breakpoints), or white:LEVEL. Default: white noise of level 1."),
    psd_units: Optional[str] = typer.Option(None, "--psd-units", help="g (default) or m/s^2: the levels of a "
                                            "support acceleration PSD (a force's are N^2/Hz)."),
    out: Path = typer.Option(Path("results"), "-o", "--out", help="Output folder."),
    no_plots: bool = typer.Option(False, "--no-plots", help="Write the HDF5 and TOML files only."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Print errors only."),
    as_json: bool = typer.Option(False, "--json", help="Print the optimum as JSON."),
):
    """Tune parameters within bounds to minimize a response measure, with exact gradients.

    A receptance's peak is minimized as the minimax it is (every peak located on the exact receptance, each with its
    exact gradient); an RMS under white noise from the Lyapunov equation; a run's peak displacement from its exact
    sensitivities. Writes OUT/<stem>_optimize.h5, OUT/<stem>_optimized.toml (runs as it is) and
    OUT/<stem>_optimize.png. Exit 1 when no search converged."""
    from smdcli.commands.optimize import format_optimize, optimize_command, optimize_summary

    run = _carried_out(lambda: optimize_command(scenario, list(param or []), minimize, out, starts, input_dof,
                                                plots=not no_plots, progress=progress_wanted(quiet, as_json),
                                                subject_to=tuple(subject_to or ()),
                                                records=tuple(r for r in (records or "").split(",") if r),
                                                over=over, input_psd=input_psd, psd_units=psd_units),
                       {"scenario": str(scenario)}, as_json, quiet, optimize_summary,
                       lambda _, d: format_optimize(d))
    if not run.converged:
        raise typer.Exit(1)


def fragility(
    data: Path = typer.Argument(..., metavar="DATA", help="An smd ida result (RESULT_ida.h5: its collapse "
                                "intensities), or multiple-stripe counts: a CSV with columns im,runs,collapses."),
    out: Path = typer.Option(Path("results"), "-o", "--out", help="Output folder."),
    no_plots: bool = typer.Option(False, "--no-plots", help="Write the HDF5 file only."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Print errors only."),
    as_json: bool = typer.Option(False, "--json", help="Print the summary as JSON."),
):
    """Fit a lognormal fragility curve by maximum likelihood, with profile-likelihood intervals.

    From collapse intensities (a lognormal sample) or from multiple-stripe counts (Baker's binomial likelihood);
    writes OUT/<input stem>_fragility.h5 and OUT/<input stem>_fragility.png."""
    from smdcli.commands.fragility import format_fragility, fragility_command, fragility_summary

    _carried_out(lambda: fragility_command(data, out, plots=not no_plots), {"data": str(data)}, as_json, quiet,
                 fragility_summary, lambda _, summary: format_fragility(summary))


def ida(
    scenario: Path = typer.Argument(..., help="Scenario TOML file shaken by a \\[ground_motion] record."),
    records: Optional[list[str]] = typer.Option(None, "--records", help="A folder of records or a record file "
                                                "(repeatable): .AT2, .V2, .V2c, .csv."),
    im: Optional[str] = typer.Option(None, "--im", help="sa (5 %, first mode; default), sa:T=<s>[,zeta=<ratio>], "
                                     "pga or pgv."),
    edp: Optional[str] = typer.Option(None, "--edp", help="max_drift_ratio (default with \\[building]), "
                                      "residual_drift, peak_displacement:<dof> or peak_acceleration:<dof>."),
    collapse: Optional[str] = typer.Option(None, "--collapse", help="drift=<ratio> or displacement=<m> (dynamic "
                                           "instability and the slope rule always count)."),
    runs: Optional[int] = typer.Option(None, "--runs", help="Runs filling each curve after the bisection (12)."),
    im_tolerance: Optional[float] = typer.Option(None, "--im-tolerance", help="The bisection's relative bracket "
                                                 "(1e-3)."),
    tail: Optional[float] = typer.Option(None, "--tail", help="Free vibration after each record, s (5)."),
    workers: Optional[int] = typer.Option(None, "--workers", help="Processes, a record each (default: the CPUs)."),
    scheduler: Optional[str] = typer.Option(None, "--scheduler", help="A Dask scheduler's address, or local."),
    resume: bool = typer.Option(False, "--resume", help="Keep the records an interrupted campaign finished."),
    out: Path = typer.Option(Path("results"), "-o", "--out", help="Output folder."),
    no_plots: bool = typer.Option(False, "--no-plots", help="Write the HDF5 file only."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Print errors only."),
    as_json: bool = typer.Option(False, "--json", help="Print the summary as JSON."),
):
    """Incremental dynamic analysis: each record scaled up to collapse, fractiles and a fragility curve.

    Hunt (doubling), bisection and fill per record (Vamvatsikos and Cornell 2002); writes OUT/<stem>_ida.h5,
    OUT/<stem>_ida.png and OUT/<stem>_fragility.png."""
    import os

    from smdcli.commands.ida import format_ida, ida_command, ida_summary

    _carried_out(lambda: ida_command(scenario, out, records, im, edp, collapse, runs, im_tolerance, tail,
                                     workers if workers is not None else os.cpu_count(), scheduler, resume,
                                     plots=not no_plots, progress=progress_wanted(quiet, as_json)),
                 {"scenario": str(scenario)}, as_json, quiet, ida_summary, lambda _, data: format_ida(data))
