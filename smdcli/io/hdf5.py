"""HDF5 files: the header and provenance every smd file carries, and a simulate run's layout.

Must not import: commands, cli."""

from __future__ import annotations

import hashlib
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from smdcli import __version__, provenance
from smdcli.io.atomic import atomic_path
from smdcli.model import Model
from smdcli.model.accuracy import (acceleration_accuracy, derived_accuracy, evaluation_accuracy, loaded_force,
                                   matrix_accuracy, modes_accuracy)
from smdcli.model.nonsmooth import initial_stiffness
from smdcli.result import Result
from smdcli.scenario import Scenario

SCHEMA_VERSION = 1
TIME_ACCURACY = float(np.finfo(float).eps)  # each output time is a decimal start + k*step rounded once


LARGE_VALUES = 2 ** 20  # values of a data set from which its zero columns are left unwritten (8 MB)
CHUNK_VALUES = 2 ** 17  # values in a chunk of such a data set (1 MB)
ATTRIBUTE_MODES = 256  # the most modes (or nonlinear elements) also listed as attributes: beyond, data sets only


def write_header(f, scenario: Scenario, kind: str) -> None:
    """The root attributes every smd file carries, and the provenance to run it again from the file alone."""
    write_provenance(f, kind)
    f.attrs["title"] = scenario.title
    f.attrs["scenario"] = scenario.text
    f.attrs["scenario_path"] = str(scenario.path)
    tables = [force for force in scenario.forces if force.file]
    if tables:  # the files a table force read, copied: the scenario text alone no longer says what they held
        group = f.create_group("provenance/table_files")
        for force in tables:
            ds = group.create_dataset(force.path, data=force.file_text)
            ds.attrs["file"] = force.file
            ds.attrs["format"] = force.file_format or "csv"
            if force.file_units:
                ds.attrs["units_in_file"] = force.file_units
            ds.attrs["sha256"] = hashlib.sha256(force.file_text.encode()).hexdigest()
    if scenario.system is not None and scenario.system.files:  # the matrices are /model's; where they came from
        group = f.create_group("provenance/matrix_files")
        for key, path, sha256 in scenario.system.files:  # hashed as read: what the run was built from
            group.attrs[f"{key}_file"] = path
            group.attrs[f"{key}_sha256"] = sha256


def write_provenance(f, kind: str) -> None:
    """The root attributes of every smd file, scenario or not: versions, kind, time, command line, machine."""
    import platform

    import h5py

    f.attrs["smd_version"] = __version__
    f.attrs["schema_version"] = SCHEMA_VERSION
    f.attrs["kind"] = kind
    f.attrs["created"] = datetime.now(timezone.utc).isoformat(timespec="seconds")
    f.attrs["command_line"] = provenance.command_line()
    f.attrs["python_version"] = platform.python_version()
    f.attrs["numpy_version"] = np.__version__
    f.attrs["scipy_version"] = provenance.scipy_version()
    f.attrs["h5py_version"] = h5py.__version__
    f.attrs["machine"] = f"{platform.system()} {platform.machine()}"


def axis(group, name: str, values):
    """A dimension scale named `name` in group: strings (DOF or element names) or numbers, one per position."""
    values = list(values) if not isinstance(values, np.ndarray) else values
    ds = _strings(group, name, values) if len(values) and isinstance(values[0], str) else \
        group.create_dataset(name, data=np.asarray(values))
    ds.make_scale(name)
    return ds


def with_scales(ds, *scales):
    """Attach one dimension scale per axis (None leaves an axis bare); returns the data set."""
    for axis, scale in enumerate(scales):
        if scale is not None:
            ds.dims[axis].attach_scale(scale)
    return ds


def write_simulation(path: Path, scenario: Scenario, model: Model, result: Result, checks: list | None = None) -> None:
    """Write one simulate run in the layout of DESIGN.md; checks are the [[expect]] verdicts as plain data."""
    import h5py

    with atomic_path(path) as tmp, h5py.File(tmp, "w") as f:
        write_header(f, scenario, "simulate")

        time = f.create_dataset("time", data=result.time)
        time.attrs["units"] = "s"
        time.make_scale("time")
        stated(time, TIME_ACCURACY)
        dof = axis(f, "dof", result.dofs)
        accuracy = {"displacement": result.stats.stated_accuracy, "velocity": result.stats.stated_accuracy,
                    "acceleration": float(acceleration_accuracy(
                        model.M, model.C, model.K, result.stats.stated_accuracy, result.displacement,
                        result.velocity, result.acceleration, result.force)[0]),
                    "force": evaluation_accuracy(loaded_force(model), result.time) if model.is_forced else 0.0}
        for name, data, units in (
            ("displacement", result.displacement, "m"),
            ("velocity", result.velocity, "m/s"),
            ("acceleration", result.acceleration, "m/s^2"),
            ("force", result.force, "N"),
        ):
            ds = _mostly_zero_columns(f, name, data)
            ds.attrs["units"] = units
            ds.dims[0].attach_scale(time)
            ds.dims[1].attach_scale(dof)
            stated(ds, accuracy[name])

        if result.ground is not None:
            _write_ground(f, scenario, model, result, time, dof, accuracy)
        if result.elements is not None or result.energy is not None:
            accuracy = derived_accuracy(model, result)
            if result.elements is not None:
                _write_elements(f, result.elements, time, dof)
            if result.energy is not None:
                _write_energy(f, result.energy, time)
            for name, value in accuracy.items():
                path = f"elements/{name}" if name in ("spring_force", "damper_force", "reaction", "friction_force",
                                                       "stop_force") or name.startswith("internal/") \
                    else f"energy/{name}"
                if path in f:  # a [system] scene has no element forces
                    stated(f[path], value, result.energy.largest if path.startswith("energy/") else None)
            if "elements/added_damping_force" in f:  # C_damping v: the velocity's accuracy, through a product
                stated(f["elements/added_damping_force"], result.stats.stated_accuracy * (model.n + 2))
        if result.nonsmooth is not None:
            _write_events(f, result.nonsmooth)
        if result.storeys is not None:
            _write_storeys(f, result.storeys, time, result, derived_accuracy(model, result))
        if checks:
            _write_expect(f, checks)

        solver = f.create_group("solver")
        for key, value in result.stats.as_attrs().items():
            solver.attrs[key] = value
        if result.t_failed is not None:
            solver.attrs["t_failed"] = result.t_failed

        group = f.create_group("model")
        write_matrices(group, model, dof)
        modes_stated = modes_accuracy(model)
        modes = group.create_group("modes")
        m = model.modes
        if model.n <= ATTRIBUTE_MODES:  # as attributes too for small models (HDF5 caps an object's header at 64 KB)
            modes.attrs["natural_frequencies_rad_s"] = m.natural_frequencies
            modes.attrs["damping_ratios"] = m.damping_ratios
            modes.attrs["regimes"] = np.array(m.regimes, dtype=object).astype(str).tolist()
        if not model.is_sparse:  # a sparse scene's spread of decay rates would need all its modes
            modes.attrs["stiffness_ratio"] = model.stiffness_ratio
        mode = axis(modes, "mode", np.arange(1, len(m.natural_frequencies) + 1))
        if model.is_sparse:
            modes.attrs["lowest"] = len(m.natural_frequencies)
            modes.attrs["description"] = (f"the lowest {len(m.natural_frequencies)} of {model.n} modes (a sparse "
                                          "scene's: shift-invert Lanczos), damping ratios from diag(Phi^T C Phi)")
        with_scales(_strings(modes, "regimes", [str(r) for r in m.regimes]), mode)
        for name, data, units in (("natural_frequencies_rad_s", m.natural_frequencies, "rad/s"),
                                  ("damping_ratios", m.damping_ratios, "1")):
            ds = with_scales(modes.create_dataset(name, data=data), mode)
            ds.attrs["units"] = units
            stated(ds, modes_stated[name])
        shapes = with_scales(modes.create_dataset("shapes", data=m.shapes), dof, mode)
        shapes.attrs["units"] = "1"
        shapes.attrs["normalization"] = "mass-normalized (shapes^T M shapes = I), largest entry of each column positive"
        stated(shapes, modes_stated["shapes"])
        eigen = with_scales(modes.create_dataset("eigenvalues", data=np.stack([m.eigenvalues.real, m.eigenvalues.imag],
                                                                               axis=1)),
                             axis(modes, "eigenvalue", np.arange(1, len(m.eigenvalues) + 1)),
                             axis(modes, "part", ["real", "imag"]))
        eigen.attrs["units"] = "1/s"
        eigen.attrs["columns"] = ["real", "imag"]
        stated(eigen, modes_stated["eigenvalues"])
        if model.nonlinear_paths:
            if len(model.nonlinear_paths) <= ATTRIBUTE_MODES:
                group.attrs["nonlinear_elements"] = list(model.nonlinear_paths)
            with_scales(_strings(group, "nonlinear_elements", list(model.nonlinear_paths)),
                        axis(group, "nonlinear_element", np.arange(1, len(model.nonlinear_paths) + 1)))


def _write_ground(f, scenario: Scenario, model: Model, result: Result, time, dof, accuracy: dict) -> None:
    """Absolute displacement, velocity and acceleration beside the relative ones, and the support's own motion."""
    f.attrs["relative_to_ground"] = 1
    spec = scenario.ground_motion
    ground = _ground_accuracy(model, result)
    for name, units in (("displacement", "m"), ("velocity", "m/s"), ("acceleration", "m/s^2")):
        absolute = result.absolute(name)
        ds = with_scales(f.create_dataset(f"absolute_{name}", data=absolute), time, dof)
        ds.attrs["units"] = units
        ds.attrs["description"] = f"{name} in the fixed frame: the relative {name} plus the ground's"
        f[name].attrs["description"] = f"{name} relative to the moving ground"
        # the two parts' errors add: each part's accuracy times its own peak, over the sum's peak
        parts = accuracy[name] * _peak(getattr(result, name)) + ground[name] * _peak(getattr(result.ground, name))
        stated(ds, parts / _peak(absolute) if _peak(absolute) > 0 else 0.0)
    group = f.create_group("ground")
    group.attrs["quantity"] = spec.quantity
    group.attrs["type"] = spec.shape.type
    group.attrs["units_given"] = spec.units
    group.attrs["jumps"] = len(model.ground.jumps)
    for name, units in (("displacement", "m"), ("velocity", "m/s"), ("acceleration", "m/s^2")):
        ds = with_scales(group.create_dataset(name, data=getattr(result.ground, name)), time)
        ds.attrs["units"] = units
        stated(ds, ground[name])
        ds.attrs["description"] = ("as given" if name == spec.quantity else
                                   "derived exactly" if spec.quantity == "displacement" or
                                   (spec.quantity == "velocity" and name == "acceleration") else
                                   "integrated from rest at the start")
    if spec.shape.file:
        file = group.create_dataset("file_text", data=spec.shape.file_text)
        file.attrs["file"] = spec.shape.file
        file.attrs["format"] = spec.shape.file_format or "csv"
        file.attrs["units_in_file"] = spec.units
        file.attrs["sha256"] = hashlib.sha256(spec.shape.file_text.encode()).hexdigest()


def _mostly_zero_columns(f, name: str, data: np.ndarray):
    """A large (N, n) data set whose columns are mostly zero stored in chunks of columns, those of zeros never written
    (read as the fill value, 0): the 10,000-mass chain's applied force (80 MB, one column not zero), and its x, v, a
    and element forces beyond the masses the Taylor series' wave reached. Small or mostly nonzero ones written whole."""
    nonzero = np.flatnonzero(np.any(data != 0, axis=0)) if data.size >= LARGE_VALUES else None
    if nonzero is None or len(nonzero) > data.shape[1] // 2:
        return f.create_dataset(name, data=data)
    columns = min(data.shape[1], 64)
    ds = f.create_dataset(name, shape=data.shape, dtype=data.dtype, fillvalue=0.0,
                          chunks=(min(data.shape[0], max(1, CHUNK_VALUES // columns)), columns))
    for block in np.unique(nonzero // columns):  # whole chunks of columns, each written once
        span = slice(block * columns, min((block + 1) * columns, data.shape[1]))
        ds[:, span] = data[:, span]
    return ds


def _ground_accuracy(model: Model, result: Result) -> dict[str, float]:
    """The ground's displacement, velocity and acceleration: evaluated from their signals where given or derived,
    integrated from rest (with that run's stated accuracy) otherwise."""
    g, history = model.ground, result.ground
    signals = {"displacement": g.given if g.quantity == "displacement" else None,
               "velocity": g.velocity, "acceleration": g.acceleration}
    return {name: evaluation_accuracy(signal.value, result.time) if signal is not None
            else (history.integrated_accuracy if name != "acceleration" else 0.0)
            for name, signal in signals.items()}


def _peak(data: np.ndarray) -> float:
    return float(np.max(np.abs(data), initial=0.0))


def stated(ds, accuracy: float, scale: float | None = None) -> None:
    """A data set's stated accuracy: each entry's error is at most accuracy times its largest magnitude, or times
    `scale` (in the data set's units) where one is given; inf where the data are not determined to any digit."""
    ds.attrs["stated_accuracy"] = float(accuracy)
    if scale is not None:
        ds.attrs["accuracy_scale"] = float(scale)


def _write_events(f, history) -> None:
    """/events: time (s), element and kind of every event, on an `event` axis."""
    group = f.create_group("events")
    group.attrs["kinds"] = "yield, unload, stick, slip, contact, impact, separation, rest"
    event = axis(group, "event", np.arange(len(history.events)))
    times = with_scales(group.create_dataset("time", data=np.array([t for t, _, _ in history.events], dtype=float)),
                         event)
    times.attrs["units"] = "s"
    stated(times, 4 * float(np.finfo(float).eps))  # located to rounding on the flow (the exact path)
    for name, index in (("element", 1), ("kind", 2)):
        with_scales(_strings(group, name, [e[index] for e in history.events]), event)


def _write_elements(f, elements, time, dof) -> None:
    """/elements: spring_force and damper_force (time x element, tension positive), named scales, the reaction."""
    group = f.create_group("elements")
    group.attrs["sign"] = "tension positive: an element connecting [a, b] pushes a by +T and b by -T"
    tables = (("spring", elements.spring, elements.spring_names, elements.spring_connects),
              ("damper", elements.damper, elements.damper_names, elements.damper_connects))
    for kind, forces, names, connects in tables if elements.element_form else ():
        scale = _strings(group, kind, names)
        scale.make_scale(kind)
        ds = with_scales(_mostly_zero_columns(group, f"{kind}_force", forces), time, scale)
        ds.attrs["units"] = "N"
        with_scales(_strings(group, f"{kind}_connects", [f"{a} {b}" for a, b in connects]), scale)
    if not elements.element_form:
        group.attrs["note"] = "a [system] scene has no elements: only the reaction is given"
    for kind, forces, names, connects in (("friction", elements.friction, elements.friction_names,
                                           elements.friction_connects),
                                          ("stop", elements.stop, elements.stop_names, elements.stop_connects)):
        if forces is None or not names:
            continue
        scale = _strings(group, kind, names)
        scale.make_scale(kind)
        ds = with_scales(group.create_dataset(f"{kind}_force", data=forces), time, scale)
        ds.attrs["units"] = "N"
        ds.attrs["description"] = ("the contact's friction force, tension positive (stuck: the force that holds it)"
                                   if kind == "friction" else "the stop's contact force (0 while free), tension "
                                   "positive: a stop pushing its ends apart is negative")
        with_scales(_strings(group, f"{kind}_connects", [f"{a} {b}" for a, b in connects]), scale)
    if elements.internal:
        internal = group.create_group("internal")
        internal.attrs["description"] = ("each hysteretic spring's internal variable: plastic_deformation (m) of an "
                                         "elastoplastic or bilinear spring, z (m) of a Bouc-Wen one")
        for name, values in elements.internal.items():
            ds = with_scales(internal.create_dataset(name, data=values), time)
            ds.attrs["units"] = "m"
    support = axis(group, "support", ["ground"])  # (time, 1): the one support the reaction acts on
    reaction = with_scales(group.create_dataset("reaction", data=elements.reaction[:, None]), time, support)
    reaction.attrs["units"] = "N"
    reaction.attrs["description"] = elements.reaction_meaning
    if elements.added_damping is not None:
        ds = with_scales(group.create_dataset("added_damping_force", data=elements.added_damping), time, dof)
        ds.attrs["units"] = "N"
        ds.attrs["description"] = "-C_damping x' on each DOF: the force of the [damping] table, not an element's"


def _write_storeys(f, storeys, time, result, derived: dict) -> None:
    """/storeys: drift, drift ratio and shear histories (time x storey), their located peaks, the residual drift; each
    stated as accurate as the displacements (twice, a difference of two) and the element forces it sums."""
    group = f.create_group("storeys")
    names = _strings(group, "storey", storeys.names)
    names.make_scale("storey")
    height = group.create_dataset("height", data=storeys.heights)
    height.dims[0].attach_scale(names)
    height.attrs["units"] = "m"
    stated(height, 0.0)
    largest = float(np.abs(result.displacement).max(initial=0.0))
    drift = (2 * result.stats.stated_accuracy, largest)
    ratio = (drift[0], largest / float(storeys.heights.min()))
    # a storey sums at most every element: each kind's stated error (relative to its largest force) times that
    # force times how many there are, in N
    forces = [derived[f"{kind}_force"] * float(np.abs(values).max(initial=0.0)) * values.shape[1]
              for kind, values in (("spring", result.elements.spring), ("damper", result.elements.damper),
                                   ("friction", result.elements.friction), ("stop", result.elements.stop))
              if values is not None and values.size and f"{kind}_force" in derived]
    shear = (sum(forces), 1.0)
    for name, data, units, meaning, accuracy in (
            ("drift", storeys.drift, "m", "the storey's mass less the one below (the ground's 0)", drift),
            ("drift_ratio", storeys.drift_ratio, "1", "drift over the storey's height", ratio),
            ("shear", storeys.shear, "N", "tension of the elements joining the storey's levels, positive pulling "
                                          "the upper mass down", shear)):
        ds = with_scales(group.create_dataset(name, data=data), time, names)
        ds.attrs["units"], ds.attrs["description"] = units, meaning
        stated(ds, *accuracy)
    # a located peak is vouched for no closer than what locating it moved it from the largest sample
    moved_drift = float(np.max(storeys.peak_drift - np.abs(storeys.drift).max(axis=0), initial=0.0)) / largest \
        if largest > 0 else 0.0
    moved_shear = float(np.max(storeys.peak_shear - np.abs(storeys.shear).max(axis=0), initial=0.0))
    for name, data, units, meaning, accuracy in (
            ("peak_drift", storeys.peak_drift, "m", "largest |drift|, located between samples",
             (drift[0] + moved_drift, drift[1])),
            ("peak_drift_ratio", storeys.peak_drift_ratio, "1", "largest |drift| over the height, located",
             (ratio[0] + moved_drift, ratio[1])),
            ("peak_shear", storeys.peak_shear, "N", "largest |shear|: located where the storey's elements are "
                                                     "linear springs and dampers, else the samples' (see located)",
             (shear[0] + moved_shear, 1.0)),
            ("residual_drift", storeys.residual_drift, "m", "the drift at the run's end", drift)):
        ds = group.create_dataset(name, data=data)
        ds.dims[0].attach_scale(names)
        ds.attrs["units"], ds.attrs["description"] = units, meaning
        stated(ds, *accuracy)
    group["peak_drift"].attrs["time"] = storeys.peak_drift_time
    group["peak_shear"].attrs["time"] = storeys.peak_shear_time
    group["peak_shear"].attrs["located"] = storeys.shear_located


def _write_energy(f, energy, time) -> None:
    """/energy: kinetic, strain, dissipated, input, residual (J) and the balance's max_relative_residual."""

    group = f.create_group("energy")
    group.attrs["max_relative_residual"] = energy.max_relative_residual
    group.attrs["quadrature"] = energy.quadrature
    group.attrs["balance"] = "residual = kinetic + strain - (kinetic + strain)[0] + dissipated - input"
    for name in energy.terms:
        ds = with_scales(group.create_dataset(name, data=getattr(energy, name)), time)
        ds.attrs["units"] = "J"


def _write_expect(f, checks: list) -> None:
    """/expect: a subgroup per check (expect/0, ...) with its quantity, measured value, bounds and verdict."""
    group = f.create_group("expect")
    group.attrs["passed"] = int(all(check["passed"] for check in checks))
    group.attrs["failed"] = sum(not check["passed"] for check in checks)
    for index, check in enumerate(checks):
        one = group.create_group(str(index))
        for key, value in check.items():
            one.attrs[key] = float("nan") if value is None and key in ("min", "max") else \
                ("" if value is None else value)


def write_matrices(group, model_or_family, dof, member=None) -> None:
    """M, C, K with units and stated accuracies, their axes named by the DOF scale (and the member scale for a
    family)."""
    accuracy = matrix_accuracy(model_or_family if member is None else model_or_family.base)
    names = list(dof.asstr()[()])  # rows and columns need their own names: a dimension appears once per array
    rows, columns = axis(group, "dof_row", names), axis(group, "dof_col", names)
    base = model_or_family if member is None else model_or_family.base
    for name, units in (("M", "kg"), ("C", "N s/m"), ("K", "N/m")):
        matrix = getattr(model_or_family, name)
        if name == "K" and base.nonsmooth:  # the scene at rest, as info and /model/modes take it
            matrix = base.initial_K if member is None else np.stack([initial_stiffness(k, base.nonsmooth)
                                                                     for k in matrix])
        if not isinstance(matrix, np.ndarray):
            stated(_sparse_matrix(group, name, matrix, units, names), accuracy[name])
            continue
        ds = group.create_dataset(name, data=matrix)
        ds.attrs["units"] = units
        if name == "K" and base.nonsmooth:
            ds.attrs["description"] = ("at rest: every hysteretic spring at its elastic stiffness k (a bilinear "
                                       "spring's b k after it yields is in /elements)")
        axes = (rows, columns) if member is None else (member, rows, columns)
        with_scales(ds, *axes)
        stated(ds, accuracy[name])


def _sparse_matrix(group, name: str, matrix, units: str, names: list[str]):
    """A sparse scene's matrix as its nonzero entries (coordinate form, rows sorted, 0-based), a group of
    row, column and value on an `entry` scale with attrs shape and units: what scipy's
    coo_matrix((value, (row, column)), shape) and MATLAB's sparse(row + 1, column + 1, value, n, n) read, in
    O(nnz) (a 10,000-mass chain's K: 30,000 entries, not 10^8). read_matrix() gives it back."""
    coo = matrix.tocoo()
    order = np.lexsort((coo.col, coo.row))
    sparse = group.create_group(name)
    sparse.attrs.update(units=units, shape=np.array(matrix.shape, dtype=np.int64), format="coordinate",
                        description=f"{name}[row[i], column[i]] = value[i], 0-based, every other entry 0; rows and "
                                    f"columns in the order of /dof ({names[0]}...)")
    entry = axis(sparse, "entry", np.arange(coo.nnz, dtype=np.int64))
    for part, values in (("row", coo.row[order]), ("column", coo.col[order]), ("value", coo.data[order])):
        with_scales(sparse.create_dataset(part, data=values.astype(np.int64 if part != "value" else float)), entry)
    sparse["value"].attrs["units"] = units
    return sparse["value"]


def read_matrix(node):
    """/model/M, C or K as written: a dense array, or a sparse scene's coordinate group as a scipy CSR matrix."""
    if not hasattr(node, "keys"):
        return node[()]
    from scipy.sparse import coo_matrix

    shape = tuple(int(d) for d in node.attrs["shape"])
    return coo_matrix((node["value"][()], (node["row"][()], node["column"][()])), shape=shape).tocsr()


def _strings(f, name: str, values):
    """A data set of UTF-8 strings."""
    import h5py

    return f.create_dataset(name, data=np.array(list(values), dtype=object), dtype=h5py.string_dtype("utf-8"))
