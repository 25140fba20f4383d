"""smd: lumped spring-mass-damper systems, solved exactly where they can be.

The Python API (smdcli.api): load(path) -> Scenario, simulate(scenario_or_path, method, rtol, atol) -> Result,
write(result, path), sensitivity(scenario_or_path, params), fit(scenarios, data, params),
optimize(scenario_or_path, {path: (lo, hi)}, minimize), and the analyses (response_spectrum, constant_ductility, shock_response_spectrum,
process_record, response_spectrum_analysis...). They are imported on first use, so `smd --help` imports nothing heavy. Every error is an
SmdError with the line the command line prints: ScenarioError (bad input, exit 2), UsageError (a bad option or
path, exit 2), SolverFailed (exit 1).
"""

from smdcli.errors import ScenarioError, SmdError, SolverFailed, UsageError

__version__ = "0.1.0"
_ANALYSES = ("read_record", "build", "read_matrix", "response_spectrum", "constant_ductility", "constant_strength",
             "shock_response_spectrum", "process_record", "modal_participation", "response_spectrum_analysis")
__all__ = ["load", "simulate", "write", "sensitivity", "fit", "optimize", *_ANALYSES, "SmdError", "ScenarioError", "UsageError", "SolverFailed",
           "__version__"]


def __getattr__(name: str):
    """load, simulate, write and the analyses from smdcli.api, imported when first asked for (PEP 562)."""
    if name in ("load", "simulate", "write", "sensitivity", "fit", "optimize"):
        from smdcli import api

        return getattr(api, name)
    if name in _ANALYSES:
        from smdcli import api

        return api.analysis(name)
    raise AttributeError(f"module 'smdcli' has no attribute {name!r}")
