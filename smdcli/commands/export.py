"""`smd export`: a result file as one CSV table that pandas, a spreadsheet or MATLAB reads.

A simulate file: one row per output time, a column per (data set, DOF or element). A sweep file: one row per
member, its swept parameters and its metrics. Values are written as %.17g, which reads back bit for bit.

Must not import: cli.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from smdcli.commands.diff import open_result
from smdcli.errors import UsageError

# Time series of a simulate file, in the order they are exported: (name, path in the file, column names from).
SERIES = (("displacement", "displacement", "dof"), ("velocity", "velocity", "dof"),
          ("acceleration", "acceleration", "dof"), ("force", "force", "dof"),
          ("absolute_displacement", "absolute_displacement", "dof"),
          ("absolute_velocity", "absolute_velocity", "dof"),
          ("absolute_acceleration", "absolute_acceleration", "dof"),
          ("spring_force", "elements/spring_force", "elements/spring"),
          ("damper_force", "elements/damper_force", "elements/damper"),
          ("reaction", "elements/reaction", None),
          ("added_damping_force", "elements/added_damping_force", "dof"),
          *((f"energy.{term}", f"energy/{term}", None)
            for term in ("kinetic", "strain", "dissipated", "input", "residual")))


def _names(f, path: str) -> list[str]:
    """The strings of a name data set (DOFs, elements)."""
    return [v.decode() if isinstance(v, bytes) else str(v) for v in f[path][()]]


def _time_series(f) -> dict[str, tuple[str, str | None]]:
    """Every time series of a simulate file (a data set whose first axis is the time's, outside model/ and
    events/): SERIES first, in its order, then the rest as the file holds them (friction and stop forces, the
    hysteretic, friction, impact and contact energy, plastic deformation, the ground's motion...), each named by
    its path with dots and its columns by the scale on its second axis."""
    import h5py

    present = {name: (path, labels) for name, path, labels in SERIES if path in f}
    known = {path for path, _ in present.values()}
    steps = len(f["time"])
    found: list[str] = []

    def visit(path, obj):
        if isinstance(obj, h5py.Dataset) and path not in known and path != "time" and obj.ndim in (1, 2) \
                and obj.shape[0] == steps and obj.dtype.kind == "f" and path.split("/")[0] not in ("model", "events"):
            found.append(path)

    f.visititems(visit)
    for path in found:
        scales = f[path].dims[1] if f[path].ndim == 2 else ()
        labels = scales[0].name.lstrip("/") if len(scales) else None
        present[path.replace("/", ".")] = (path, labels)
    return present


def _simulate_table(f, wanted: list[str] | None) -> tuple[list[str], list[str], list[np.ndarray]]:
    """Header, units and columns of a simulate file's time series."""
    present = _time_series(f)
    chosen = list(present) if wanted is None else _chosen(wanted, present)
    header, units, columns = ["time"], ["s"], [f["time"][()]]
    for name in chosen:
        path, labels = present[name]
        data = f[path][()]
        unit = str(f[path].attrs.get("units", ""))
        if data.ndim == 1:
            header.append(name)
            columns.append(data)
            units.append(unit)
            continue
        names = _names(f, labels) if labels else [""] * data.shape[1]
        for j, label in enumerate(names):
            header.append(f"{name}.{label}" if label else name)
            columns.append(data[:, j])
            units.append(unit)
    return header, units, columns


def _chosen(wanted: list[str], present: dict) -> list[str]:
    """The data sets asked for, in the order asked; 'energy' stands for all its terms."""
    chosen = []
    for name in (w.strip() for w in wanted):
        names = [n for n in present if n.startswith("energy.")] if name == "energy" else [name]
        for one in names:
            if one not in present:
                raise UsageError(f"--datasets: {one!r} is not in this file; it holds {', '.join(present)}")
            chosen.append(one)
    return chosen


def members_done(f) -> int:
    """How many members a sweep file holds results for: all of them, or an interrupted sweep's members_done."""
    total = len(f["member"])
    return total if bool(f.attrs.get("complete", True)) else min(total, int(f.attrs.get("members_done", 0)))


def _sweep_table(f, wanted: list[str] | None) -> tuple[list[str], list[str], list[np.ndarray]]:
    """Header, units and columns of a sweep file: per member its parameters, initial conditions and metrics (the
    members done, for an interrupted sweep)."""
    done = members_done(f)
    header, units, columns = ["member"], ["1"], [f["member"][:done]]
    for path, ds in (f["parameters"].items() if "parameters" in f else ()):
        header.append(path)
        units.append(str(ds.attrs.get("units", "")))
        columns.append(ds[:done])
    dofs = _names(f, "dof")
    for name in ("x0", "v0") if "initial_conditions" in f and "frequency" not in f else ():
        ds = f[f"initial_conditions/{name}"]
        for j, dof in enumerate(dofs):
            header.append(f"{name}.{dof}")
            units.append("m" if name == "x0" else "m/s")
            columns.append(ds[:done, j])
    if "frequency" in f:  # a frequency response: a row per member and frequency
        return _response_table(f, wanted, header, units, columns, dofs)
    metrics = f["metrics"] if "metrics" in f else {}
    names = list(metrics) if wanted is None else _chosen(wanted, dict.fromkeys(metrics))
    for name in names:
        data = metrics[name][:done]
        unit = str(metrics[name].attrs.get("units", ""))
        for j, dof in enumerate(dofs if data.ndim == 2 else [""]):
            header.append(f"{name}.{dof}" if dof else name)
            units.append(unit)
            columns.append(data[:, j] if data.ndim == 2 else data)
    return header, units, columns


def _response_table(f, wanted, header, units, columns, dofs):
    """A frequency-response sweep: member, parameters, frequency, then amplitude, phase (...) per DOF."""
    frequency = f["frequency"][()]
    present = {name: (name, None) for name, ds in f.items()
               if getattr(ds, "ndim", 0) == 3 and ds.shape[1] == len(frequency)}
    names = list(present) if wanted is None else _chosen(wanted, present)
    S, F = len(columns[0]), len(frequency)
    columns = [np.repeat(c, F) for c in columns]
    header, units = header + ["frequency"], units + [str(f["frequency"].attrs.get("units", "rad/s"))]
    columns.append(np.tile(frequency, S))
    for name in names:
        data = f[name][()].reshape(S * F, -1)
        for j, dof in enumerate(dofs):
            header.append(f"{name}.{dof}")
            units.append(str(f[name].attrs.get("units", "")))
            columns.append(data[:, j])
    return header, units, columns


def export_csv(result: Path, out: Path | None, wanted: list[str] | None) -> tuple[Path, int, int, str | None]:
    """Write the CSV; returns its path, rows, columns and a note (an interrupted sweep's members done), or None."""
    from smdcli.io.atomic import atomic_path

    result = Path(result)
    note = None
    with open_result(result) as f:
        kind = str(f.attrs["kind"])
        if kind == "simulate":
            header, units, columns = _simulate_table(f, wanted)
        elif kind == "sweep":
            done, total = members_done(f), len(f["member"])
            if done < total:
                resume = "run the same `smd sweep` command with --resume to finish it"
                if done == 0:
                    raise UsageError(f"{result}: an interrupted sweep with no member done yet; {resume}")
                note = f"an interrupted sweep: {done} of {total} members done; {resume}"
            header, units, columns = _sweep_table(f, wanted)
        else:
            raise UsageError(f"{result}: a {kind} file; export takes simulate and sweep results")
    path = Path(out) if out is not None else result.with_suffix(".csv")
    table = np.column_stack([np.asarray(c, dtype=float) for c in columns])
    with atomic_path(path) as tmp:
        np.savetxt(tmp, table, fmt="%.17g", delimiter=",", header=f"# units: {','.join(units)}\n{','.join(header)}",
                   comments="")
    return path, table.shape[0], table.shape[1], note
