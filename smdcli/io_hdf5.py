"""HDF5 results: written to a temporary name in the target folder, renamed when complete."""

from __future__ import annotations

import os
import tempfile
from contextlib import contextmanager, suppress
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from smdcli import __version__
from smdcli.model import Model
from smdcli.result import Result
from smdcli.scenario import Scenario

SCHEMA_VERSION = 1


@contextmanager
def atomic_path(final: Path):
    """Yield a temporary path beside `final`; rename it onto `final` only if the block succeeds."""
    final = Path(final)
    fd, tmp = tempfile.mkstemp(prefix=f".{final.name}.", suffix=".part", dir=final.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        os.replace(tmp, final)
    except BaseException:
        with suppress(OSError):
            os.unlink(tmp)
        raise


def write_header(f, scenario: Scenario, kind: str) -> None:
    """The root attributes every smd file carries."""
    f.attrs["smd_version"] = __version__
    f.attrs["schema_version"] = SCHEMA_VERSION
    f.attrs["kind"] = kind
    f.attrs["created"] = datetime.now(timezone.utc).isoformat(timespec="seconds")
    f.attrs["title"] = scenario.title
    f.attrs["scenario"] = scenario.text
    f.attrs["scenario_path"] = str(scenario.path)


def write_simulation(path: Path, scenario: Scenario, model: Model, result: Result) -> None:
    """Write one simulate run in the layout of DESIGN.md."""
    import h5py

    with atomic_path(path) as tmp, h5py.File(tmp, "w") as f:
        write_header(f, scenario, "simulate")

        time = f.create_dataset("time", data=result.time)
        time.attrs["units"] = "s"
        time.make_scale("time")
        dof = f.create_dataset("dof", data=np.array(result.dofs, dtype=object), dtype=h5py.string_dtype("utf-8"))
        dof.make_scale("dof")
        for name, data, units in (
            ("displacement", result.displacement, "m"),
            ("velocity", result.velocity, "m/s"),
            ("acceleration", result.acceleration, "m/s^2"),
            ("force", result.force, "N"),
        ):
            ds = f.create_dataset(name, data=data)
            ds.attrs["units"] = units
            ds.dims[0].attach_scale(time)
            ds.dims[1].attach_scale(dof)

        solver = f.create_group("solver")
        for key, value in result.stats.as_attrs().items():
            solver.attrs[key] = value
        if result.t_failed is not None:
            solver.attrs["t_failed"] = result.t_failed

        group = f.create_group("model")
        for name in ("M", "C", "K"):
            group.create_dataset(name, data=getattr(model, name))
        modes = group.create_group("modes")
        m = model.modes
        modes.attrs["natural_frequencies_rad_s"] = m.natural_frequencies
        modes.attrs["damping_ratios"] = m.damping_ratios
        modes.attrs["regimes"] = np.array(m.regimes, dtype=object).astype(str).tolist()
        modes.attrs["stiffness_ratio"] = model.stiffness_ratio
        modes.create_dataset("natural_frequencies_rad_s", data=m.natural_frequencies)
        modes.create_dataset("damping_ratios", data=m.damping_ratios)
        modes.create_dataset("shapes", data=m.shapes)
        modes.create_dataset("eigenvalues", data=np.stack([m.eigenvalues.real, m.eigenvalues.imag], axis=1))
        if model.nonlinear_paths:
            group.attrs["nonlinear_elements"] = list(model.nonlinear_paths)

