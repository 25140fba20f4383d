"""OUT/<stem>_ida.h5: an incremental dynamic analysis campaign (`smd ida`).

Must not import: commands, cli.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from smdcli.io.atomic import atomic_path
from smdcli.io.fragility_hdf5 import write_fragility_group
from smdcli.io.hdf5 import write_provenance


def _padded(traces, read) -> np.ndarray:
    """(R, K) of each record's runs, NaN-padded to the longest."""
    longest = max((len(t.im) for t in traces), default=0)
    out = np.full((len(traces), longest), np.nan)
    for r, t in enumerate(traces):
        values = np.asarray(read(t), dtype=float)
        out[r, :len(values)] = values
    return out


def write_ida(path: Path, run) -> None:
    """/records/name, /runs/im, edp, collapse, wall_time_s (R, K), /collapse_im (R,), /fractiles/edp and im_16,
    im_50, im_84, /fragility/*; root attributes im, edp, collapse, im_units."""
    import h5py

    with atomic_path(path) as tmp, h5py.File(tmp, "w") as f:
        write_provenance(f, "ida")
        f.attrs["scenario_path"] = str(run.scenario)
        f.attrs["im"], f.attrs["edp"], f.attrs["collapse"] = run.im.text, run.edp.text, run.collapse.text
        f.attrs["im_units"], f.attrs["edp_units"] = run.im.units, run.edp.units
        f.attrs["wall_time_s"] = run.wall_time_s
        f.create_dataset("records/name", data=np.array([t.record for t in run.traces], dtype=object),
                         dtype=h5py.string_dtype("utf-8"))
        f.create_dataset("records/own_im", data=np.array([t.own_im for t in run.traces])).attrs["units"] = run.im.units
        runs = f.create_group("runs")
        runs.attrs["order"] = "as run: the hunt, the bisection, then the fill; NaN past a record's last run"
        runs.create_dataset("im", data=_padded(run.traces, lambda t: t.im)).attrs["units"] = run.im.units
        runs.create_dataset("edp", data=_padded(run.traces, lambda t: t.edp)).attrs["units"] = run.edp.units
        runs.create_dataset("collapse", data=_padded(run.traces, lambda t: t.collapse))
        runs.create_dataset("wall_time_s", data=_padded(run.traces, lambda t: t.wall)).attrs["units"] = "s"
        collapse = f.create_dataset("collapse_im", data=np.array([t.collapse_im for t in run.traces]))
        collapse.attrs["units"] = run.im.units
        collapse.attrs["description"] = "each record's final bracket's middle; NaN where it never collapsed"
        fractiles = f.create_group("fractiles")
        fractiles.create_dataset("edp", data=run.levels).attrs["units"] = run.edp.units
        for name, values in run.fractiles.items():
            fractiles.create_dataset(name, data=values).attrs["units"] = run.im.units
        if run.fragility is not None:
            write_fragility_group(f.create_group("fragility"), run.fragility, run.im.units)
