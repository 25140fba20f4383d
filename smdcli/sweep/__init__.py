"""Sweep layer: families of runs (parameters over grids, initial conditions) and frequency responses.

A member is the scenario with one edit of its TOML document per swept parameter, validated again like any
scenario, so a value that makes a bad scene is an input error naming the field. Linear families are solved
together: one state-transition recurrence over all members at once (batched.py). Nonlinear families run in a
process pool (pool.py), one member per task. Modules: spec, family, batched, pool, members, frequency, shooting.

Must not import: io, plots, commands, cli.
"""

from smdcli.sweep.batched import batched_exact, shared_signal_recurrence
from smdcli.sweep.family import Family, build_family, set_parameter
from smdcli.sweep.frequency import FrequencyResponse, frequency_response, input_index, receptance, resonance_peaks
from smdcli.sweep.members import FamilyResult, metrics, solve_family
from smdcli.sweep.pool import default_workers, run_pool
from smdcli.sweep.spec import (METRIC_UNITS, METRICS, SETTLING_BAND, SweepSpec, parameter_label, parameter_units,
                               parse_frequency, parse_ic, parse_values, read_spec)

__all__ = ["METRICS", "METRIC_UNITS", "SETTLING_BAND", "Family", "FamilyResult", "FrequencyResponse", "SweepSpec",
           "batched_exact", "build_family", "default_workers", "frequency_response",
           "input_index", "metrics", "parameter_label", "parameter_units", "parse_frequency",
           "parse_ic", "parse_values", "read_spec", "receptance", "resonance_peaks", "run_pool",
           "set_parameter", "shared_signal_recurrence", "solve_family"]
