"""The file of `smd sensitivity`: a scene's response and its derivatives with respect to its parameters.

Must not import: commands, cli.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from smdcli.analysis.sensitivity import QUANTITIES
from smdcli.io.atomic import atomic_path
from smdcli.io.hdf5 import axis, stated, with_scales, write_header
from smdcli.scenario import Scenario

def write_sensitivity(path: Path, scenario: Scenario, s) -> None:
    """/time, /dof, /parameter, /value, the nominal /displacement /velocity /acceleration (N, n), their derivatives
    /d_<quantity> (P, N, n) per unit of each parameter, /metrics/peak_displacement (n,) with its time and
    /d_metrics/peak_displacement (P, n); `units` (one per parameter) and `stated_accuracy` (one per parameter,
    relative to that parameter's largest value) on every d_ data set."""
    import h5py

    with atomic_path(path) as tmp, h5py.File(tmp, "w") as f:
        write_header(f, scenario, "sensitivity")
        f.attrs["method"] = s.method
        time = f.create_dataset("time", data=s.time)
        time.attrs["units"] = "s"
        time.make_scale("time")
        dof = axis(f, "dof", s.dof)
        parameter = axis(f, "parameter", list(s.parameter))
        value = with_scales(f.create_dataset("value", data=s.value), parameter)
        value.attrs["units"] = np.array([u or "1" for u in s.parameter_units], dtype=h5py.string_dtype())
        with_scales(f.create_dataset("model_error", data=s.model_error), parameter).attrs["description"] = (
            "the estimated relative error of each parameter's derivative of the assembled model (the stencil's)")
        for quantity, units in QUANTITIES.items():
            ds = with_scales(f.create_dataset(quantity, data=getattr(s, quantity)), time, dof)
            ds.attrs["units"] = units
            stated(ds, float(s.accuracy[quantity][0]))
            ds = with_scales(f.create_dataset(f"d_{quantity}", data=getattr(s, f"d_{quantity}")), parameter, time, dof)
            ds.attrs["units"] = np.array(s.units(quantity), dtype=h5py.string_dtype())
            ds.attrs["stated_accuracy"] = np.asarray(s.accuracy[f"d_{quantity}"], dtype=float)
            ds.attrs["accuracy_relative_to"] = "each parameter's largest |value| in this data set"
        metrics = f.create_group("metrics")
        peak = with_scales(metrics.create_dataset("peak_displacement", data=s.peak_displacement), dof)
        peak.attrs["units"] = "m"
        peak.attrs["description"] = "max |x| of each DOF, located between the samples"
        with_scales(metrics.create_dataset("peak_time", data=s.peak_time), dof).attrs["units"] = "s"
        d_metrics = f.create_group("d_metrics")
        ds = with_scales(d_metrics.create_dataset("peak_displacement", data=s.d_peak_displacement), parameter, dof)
        ds.attrs["units"] = np.array(s.units("displacement"), dtype=h5py.string_dtype())
        ds.attrs["description"] = "d max|x_i| / dp: sign(x_i) dx_i/dp at the located peak's time (nan: no derivative)"
        ds.attrs["stated_accuracy"] = np.asarray(s.accuracy["d_displacement"], dtype=float)
        if s.notes:
            f.attrs["notes"] = "\n".join(s.notes)
