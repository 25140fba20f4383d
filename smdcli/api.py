"""smd from Python: load a scenario, simulate it (nothing written), write the result where you choose.

    import smdcli
    result = smdcli.simulate("scenarios/two_dof_forced.toml")      # or a Scenario from smdcli.load(...)
    result.displacement, result.energy.max_relative_residual, result.elements.spring
    smdcli.write(result, "out/two_dof.h5")                          # the file `smd simulate` writes
    s = smdcli.sensitivity("scenarios/two_dof_forced.toml", ["spring[0].k", "mass.m1.m"])
    s.d_displacement                                                # (P, N, n): dx/dp per unit of each parameter
    f = smdcli.fit("frame.toml", "shaker_test.csv", ["spring[0].k", "damping.alpha"])
    f.estimate, f.standard_error, f.confidence_95                   # the fit of `smd fit`, nothing written

The analyses (smdcli.analysis) take a record, a Model or a Result and return arrays; these are the ones the
commands run, exposed here by name:

    smdcli.read_record(path, units="g")                  # a Record: time, acceleration in m/s^2
    smdcli.response_spectrum(t, a, periods, dampings)     # Sd, Sv, Sa, exact between samples
    smdcli.constant_ductility(t, a, periods, dampings, ductilities, hardening)   # Cy, Ry, ...
    smdcli.constant_strength(t, a, periods, dampings, strengths, hardening)
    smdcli.shock_response_spectrum(t, a, frequencies_hz, q)
    smdcli.process_record(t, a, baseline, band, order)     # corrected, integrated, measured
    smdcli.modal_participation(M, K, C) and smdcli.response_spectrum_analysis(M, K, C, Sa_of_T_zeta, ...)
    smdcli.build(scenario)                                # the Model: M, C, K, dofs, modes
    smdcli.read_matrix(h5file["model/K"])                 # a result's M, C or K: dense, or CSR where stored sparse

Errors are exceptions: ScenarioError for bad input (the CLI's exit 2), SolverFailed when a method fails (exit 1).
Must not import: cli.
"""

from __future__ import annotations

from pathlib import Path

from smdcli.errors import SolverFailed, UsageError
from smdcli.result import Result
from smdcli.scenario import Scenario


def load(path: str | Path) -> Scenario:
    """Read and validate a scenario file; raises ScenarioError with the file, field and problem."""
    from smdcli.solvers.run import load as load_checked

    return load_checked(path)


def simulate(scenario: Scenario | str | Path, method: str | None = None, rtol: float | None = None,
             atol: float | None = None) -> Result:
    """Solve a scenario (a Scenario or a path) as `smd simulate` does, writing nothing; SolverFailed on failure."""
    from smdcli.commands.simulate import Options, solve_run
    from smdcli.model import build, time_grid
    from smdcli.solvers.run import check_overrides, failure_message

    check_overrides(method, rtol, atol)
    sc = scenario if isinstance(scenario, Scenario) else load(scenario)
    model = build(sc)
    result = solve_run(sc, model, time_grid(sc.time), Options(method=method, rtol=rtol, atol=atol))
    if not result.success:
        raise SolverFailed(failure_message(sc, model, result), result=result)
    return result


def write(result: Result, path: str | Path) -> Path:
    """Write a result from simulate() as the HDF5 file `smd simulate` writes (atomically); returns its path."""
    from smdcli.io.hdf5 import write_simulation

    if result.origin is None:
        raise UsageError("write() takes a result from smdcli.simulate(), which knows the scenario it came from")
    path = Path(path)
    scenario, model = result.origin
    write_simulation(path, scenario, model, result)
    return path


def sensitivity(scenario: Scenario | str | Path, params: list[str]):
    """Sensitivities of a scene (a Scenario or a path; linear, piecewise linear or smooth nonlinear) to parameter
    paths, as `smd sensitivity` takes them, writing nothing: .parameter, .time, .displacement, .d_displacement
    (P, N, n) and the file's other arrays."""
    from smdcli.analysis.sensitivity import sensitivity as sensitivities

    sc = scenario if isinstance(scenario, Scenario) else load(scenario)
    return sensitivities(sc, [params] if isinstance(params, str) else list(params))


def fit(scenarios, data, params, bounds: dict | None = None, max_iterations: int = 100):
    """Fit parameter paths of one or more scenarios (paths or Scenarios) to measured data (a CSV or an smd HDF5
    result per scenario), writing nothing: .parameter, .estimate, .standard_error, .covariance, .confidence_95,
    .converged and the rest of `smd fit`'s file. A scenario's [fit] channels and weights apply."""
    from smdcli.analysis.fit import fit as fitted, make_test
    from smdcli.analysis.fit_data import read_measured

    scenarios = [scenarios] if isinstance(scenarios, (str, Path, Scenario)) else list(scenarios)
    data = [data] if isinstance(data, (str, Path)) else list(data)
    if len(data) != len(scenarios):
        raise UsageError(f"fit(): give one data file per scenario ({len(scenarios)}), found {len(data)}")
    loaded = [s if isinstance(s, Scenario) else load(s) for s in scenarios]
    tests = [make_test(sc, read_measured(d)) for sc, d in zip(loaded, data)]
    return fitted(tests, [params] if isinstance(params, str) else list(params), bounds, max_iterations)


def optimize(scenario: Scenario | str | Path, params: dict, minimize: str, starts: int = 8, input_dof: str | None = None,
             subject_to: tuple[str, ...] = (), records: tuple = (), over: str = "max", input_psd=None):
    """The parameter values within bounds ({path: (lo, hi)}) that minimize an objective subject to 'MEASURE <= VALUE'
    constraints (`smd optimize`'s), writing nothing: .parameter, .optimum, .value, .value_before, .optima, .peaks,
    .constraints, .converged and the rest of its file. input_psd: the rms measures' one-sided input PSD in SI, a
    white level or (frequencies Hz, levels) breakpoints (default white noise of level 1)."""
    from smdcli.analysis.optimize import optimize as optimized

    sc = scenario if isinstance(scenario, Scenario) else load(scenario)
    return optimized(sc, [(path, float(lo), float(hi)) for path, (lo, hi) in params.items()], minimize, starts,
                     input_dof, subject_to=tuple([subject_to] if isinstance(subject_to, str) else subject_to),
                     records=tuple(records), over=over, psd=_psd(input_psd))


def _psd(given):
    """A white level, or (frequencies, levels) as random_vibration's Profile; None as it is."""
    if given is None or isinstance(given, (int, float)):
        return None if given is None else float(given)
    import numpy as np

    from smdcli.analysis.random_vibration import Profile

    return Profile(*(np.asarray(q, dtype=float) for q in given))


# name -> (module, attribute): the analyses and the pieces they take, imported on first use
ANALYSES = {
    "read_record": ("smdcli.scenario.record_files", "read_record"),
    "build": ("smdcli.model", "build"),
    "read_matrix": ("smdcli.io.hdf5", "read_matrix"),
    "response_spectrum": ("smdcli.analysis.spectrum", "response_spectrum"),
    "constant_ductility": ("smdcli.analysis.inelastic", "constant_ductility"),
    "constant_strength": ("smdcli.analysis.inelastic", "constant_strength"),
    "shock_response_spectrum": ("smdcli.analysis.shock", "shock_response_spectrum"),
    "process_record": ("smdcli.analysis.record", "process"),
    "modal_participation": ("smdcli.analysis.rsa", "modal_participation"),
    "response_spectrum_analysis": ("smdcli.analysis.rsa", "response_spectrum_analysis"),
}


def analysis(name: str):
    """One of ANALYSES, imported."""
    import importlib

    module, attribute = ANALYSES[name]
    return getattr(importlib.import_module(module), attribute)
