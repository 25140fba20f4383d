"""OUT/<stem>_fragility.h5: a fitted lognormal fragility (`smd fragility`, and `smd ida`'s /fragility group).

Must not import: commands, cli.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from smdcli.io.atomic import atomic_path
from smdcli.io.hdf5 import write_provenance


def write_fragility_group(group, fragility, im_units: str) -> None:
    """/fragility/theta, beta, theta_95, beta_95 (each with its units) and the log-likelihood."""
    for name, value, units in (("theta", fragility.theta, im_units), ("beta", fragility.beta, "1"),
                               ("theta_95", np.array(fragility.theta_95), im_units),
                               ("beta_95", np.array(fragility.beta_95), "1")):
        ds = group.create_dataset(name, data=value)
        ds.attrs["units"] = units
    group.attrs["log_likelihood"] = fragility.log_likelihood
    group.attrs["method"] = fragility.method
    group.attrs["interval"] = "95 % profile likelihood (chi-square 3.841, one degree of freedom)"


def write_fragility(path: Path, run) -> None:
    """The fit and the data it was fitted to."""
    import h5py

    f_ = run.fragility
    with atomic_path(path) as tmp, h5py.File(tmp, "w") as f:
        write_provenance(f, "fragility")
        f.attrs["source"] = run.source
        f.attrs["im_units"] = run.im_units
        write_fragility_group(f.create_group("fragility"), f_, run.im_units)
        data = f.create_group("data")
        data.create_dataset("im", data=f_.im).attrs["units"] = run.im_units
        if f_.runs is not None:
            data.create_dataset("runs", data=f_.runs.astype(int))
            data.create_dataset("collapses", data=f_.collapses.astype(int))
