"""HDF5 layout of a sweep: members on a leading axis, the grid's axes, stacked results or a frequency response.

Must not import: commands, cli."""

from __future__ import annotations

from contextlib import suppress
from pathlib import Path

import numpy as np

from smdcli.io.atomic import atomic_path
from smdcli.io.hdf5 import TIME_ACCURACY, _strings, with_scales, axis, stated, write_header, write_matrices
from smdcli.model.accuracy import EPS, evaluation_accuracy
from smdcli.sweep.spec import METRIC_UNITS, SETTLING_BAND, STOREY_METRICS, parameter_units


def write_sweep(path: Path, family, response, run: dict | None = None) -> None:
    """Write a frequency response sweep: members on a leading axis (a dimension scale), the swept values, the
    response. Time-domain sweeps stream through SweepFile."""
    import h5py

    with atomic_path(path) as tmp, h5py.File(tmp, "w") as f:
        member, dof = _write_family(f, family)
        _write_run(f, run)
        _write_response(f, response, member, dof, family, family.spec.normalized)


def _write_family(f, family):
    """What every sweep file holds before any result: header, members and labels, the swept values and grid, DOFs,
    initial conditions and matrices. Returns the member and DOF scales."""
    write_header(f, family.scenario, "sweep")
    spec = family.spec
    f.attrs["sweep_kind"] = spec.kind
    f.attrs["parameters"] = list(spec.parameters)
    f.attrs["grid_shape"] = list(family.shape)
    S = len(family)
    member = axis(f, "member", np.arange(S))
    _strings(f, "label", family.labels).dims[0].attach_scale(member)
    params = f.create_group("parameters")
    grid = f.create_group("grid") if spec.parameters else None
    if grid is not None:
        grid.attrs["grid_shape"] = list(family.shape)
        grid.attrs["order"] = "C: the last parameter varies fastest along member"
    for i, name in enumerate(spec.parameters):
        ds = params.create_dataset(name, data=family.values[:, i])
        ds.attrs["units"] = parameter_units(name, family.scenario)
        ds.dims[0].attach_scale(member)
        stated(ds, INPUT_ACCURACY * len(family))
        # The grid's own axis: member reshapes to grid_shape, and these are its coordinates.
        coordinates = axis(grid, name, np.asarray(spec.values[i], dtype=float))
        coordinates.attrs["units"] = parameter_units(name, family.scenario)
        coordinates.attrs["axis"] = i
        stated(coordinates, INPUT_ACCURACY * len(family))
    dof = axis(f, "dof", family.base.dofs)
    initial = f.create_group("initial_conditions")
    for name in ("x0", "v0"):
        ds = initial.create_dataset(name, data=getattr(family, name))
        ds.dims[0].attach_scale(member)
        ds.dims[1].attach_scale(dof)
        stated(ds, INPUT_ACCURACY)
    model = f.create_group("model")
    write_matrices(model, family, dof, member)
    return member, dof


def _write_run(f, run: dict | None) -> None:
    group = f.require_group("run")
    for key, value in (run or {}).items():
        group.attrs[key] = value


INPUT_ACCURACY = 4 * EPS  # numbers parsed from the scenario or a values spec (linspace...): a rounding or two each
ESTIMATE_ACCURACY = 0.5  # an error estimate is an estimate: good to within half its size, not to its digits
HISTORY_UNITS = {"displacement": "m", "velocity": "m/s", "acceleration": "m/s^2", "force": "N"}
CHUNK_BYTES = 1 << 20  # an HDF5 chunk of a growing data set: about 1 MB


class IncompatiblePartial(ValueError):
    """A partial file that is not the sweep asked for (another scenario, grid, method or --keep)."""


class DamagedPartial(Exception):
    """A partial file that cannot be read back whole: a run killed (SIGKILL, power loss) while HDF5 wrote its
    structure leaves one. Nothing in it can be trusted, so the sweep starts over."""


class SweepFile:
    """A time-domain sweep written as its members finish: the family first, then each chunk's rows appended to
    resizable, chunked data sets, flushed, and counted in the root attribute members_done; the root attribute
    complete turns true with the last member. Histories are stored uncompressed (float64 histories shrink ~20 % under
    gzip at 20x the write time); the per-member sets (metrics, status) are compressed."""

    def __init__(self, f, members: int):
        self.f = f
        self.members = members

    @classmethod
    def create(cls, path: Path, family, keep: str, grid, length: int, identity: str) -> SweepFile:
        """A new file at path holding the family and empty growing data sets."""
        import h5py

        f = None
        try:
            f = h5py.File(path, "w")
            member, dof = _write_family(f, family)
            f.attrs["keep"] = keep
            f.attrs["sweep_identity"] = identity
            f.attrs["members_done"] = 0
            f.attrs["complete"] = False
            n = family.base.n
            sample = None
            if grid is not None:
                time = f.create_dataset("time", data=grid)
                time.make_scale("time")
            else:  # each member's own times: (member, sample)
                sample = axis(f, "sample", np.arange(length))
                time = with_scales(_growing(f, "time", (length,), float), member, sample)
            time.attrs["units"] = "s"
            stated(time, TIME_ACCURACY)
            if keep == "full":
                for name, units in HISTORY_UNITS.items():
                    ds = _growing(f, name, (length, n), float)
                    ds.attrs["units"] = units
                    with_scales(ds, member, time if grid is not None else sample, dof)
                base = family.base
                if grid is not None:  # the applied force is evaluated; members differ in it only by its numbers
                    stated(f["force"], evaluation_accuracy(base.applied_force, grid) if base.is_forced else 0.0)
            _growing(f, "success", (), bool, compressed=True).dims[0].attach_scale(member)
            for name in ("message", "method"):
                _growing(f, name, (), h5py.string_dtype("utf-8"), compressed=True).dims[0].attach_scale(member)
            ds = _growing(f, "stated_accuracy", (), float, compressed=True)
            ds.attrs["units"] = "1"
            ds.attrs["meaning"] = "each member's vouched error, relative to its peak"
            ds.dims[0].attach_scale(member)
            stated(ds, ESTIMATE_ACCURACY)
            group = f.create_group("metrics")
            group.attrs["settling_band"] = SETTLING_BAND
            for name, units in METRIC_UNITS.items():
                if name in STOREY_METRICS and family.scenario.building is None:
                    continue  # a storey's measure: only a scene with [building] has storeys
                ds = _growing(group, name, (n,), float, compressed=True)
                ds.attrs["units"] = units
                with_scales(ds, member, dof)
            f.flush()
        except BaseException:  # cut before it could record any member: nothing to resume
            if f is not None:
                f.close()
            path.unlink(missing_ok=True)
            raise
        return cls(f, len(family))

    @classmethod
    def resume(cls, path: Path, family, keep: str, identity: str) -> SweepFile:
        """An interrupted sweep's file, ready to take the members after its members_done (rows past it, written
        when the run was cut, are dropped)."""
        import h5py

        f = None
        try:
            f = h5py.File(path, "r+")
            found = f.attrs["sweep_identity"]  # none: the file was cut as it began, read below as damage
            if found != identity:
                kept = f.attrs.get("keep")
                f.close()
                why = f" (it keeps {kept}, not {keep})" if kept and kept != keep else ""
                raise IncompatiblePartial(f"{path}: is from a different sweep (scenario, members, grid, method or "
                                          f"--keep differ){why}; run without --resume to start over")
            sweep = cls(f, len(family))
            done = sweep.done
            for ds in sweep._growing_sets():
                if ds.shape[0] < done:  # a ValueError as h5py's own: read below as damage
                    raise ValueError(f"{ds.name} holds {ds.shape[0]} members, fewer than the {done} it says are done")
                ds.resize(done, axis=0)
            return sweep
        except IncompatiblePartial:
            raise
        except Exception as exc:  # h5py raises OSError, RuntimeError, KeyError or ValueError for a damaged file
            if f is not None:
                with suppress(Exception):
                    f.close()
            why = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            raise DamagedPartial(f"{path} could not be read back ({why}); the sweep started over") from None

    @property
    def done(self) -> int:
        """Members written so far."""
        return int(self.f.attrs["members_done"])

    def _growing_sets(self) -> list:
        """The per-member data sets: those whose first axis is unlimited."""
        import h5py

        found = []
        self.f.visititems(lambda _, obj: found.append(obj) if isinstance(obj, h5py.Dataset) and obj.maxshape
                          and obj.maxshape[0] is None else None)
        return found

    def append(self, chunk) -> None:
        """Rows of the next chunk of members, flushed, and members_done moved past them."""
        f, start, stop = self.f, chunk.start, chunk.start + len(chunk)
        if start != self.done:
            raise ValueError(f"chunk starts at member {start}, the file is at {self.done}")
        rows = {"success": chunk.success, "message": np.array(chunk.messages, dtype=object),
                "method": np.array(chunk.methods, dtype=object), "stated_accuracy": chunk.stated}
        rows.update({f"metrics/{name}": values for name, values in chunk.metrics.items()})
        if chunk.histories is not None:
            rows.update(chunk.histories)
        if chunk.time is not None:
            rows["time"] = chunk.time
        for name, data in rows.items():
            ds = f[name]
            ds.resize(stop, axis=0)
            ds[start:stop] = data
        stated = float(np.nanmax(chunk.stated, initial=0.0))
        worst = {name: stated for name in ("displacement", "velocity")}
        worst["acceleration"] = chunk.acceleration_stated
        worst.update({f"metrics/{m}": stated for m in METRIC_UNITS if m != "settling_time"})
        worst["metrics/settling_time"] = chunk.settling_error  # in seconds: its accuracy_scale is 1 s
        for name, value in worst.items():  # the worst member's so far, relative to the peak
            if name in f:
                f[name].attrs["stated_accuracy"] = max(float(f[name].attrs.get("stated_accuracy", 0.0)), value)
        f["metrics/settling_time"].attrs["accuracy_scale"] = 1.0
        f.attrs["members_done"] = stop
        f.flush()

    def finish(self, run: dict) -> None:
        """Mark the file complete, with the run's description."""
        if self.done != self.members:
            raise ValueError(f"{self.done} of {self.members} members written")
        _write_run(self.f, run)
        self.f.attrs["complete"] = True
        self.f.flush()

    def close(self) -> None:
        """Close the file (complete or not: an incomplete one is what --resume finishes)."""
        self.f.close()


def _growing(group, name: str, row: tuple, dtype, compressed: bool = False):
    """A data set growing along its first axis (members), chunked to about CHUNK_BYTES."""
    import h5py

    itemsize = 16 if h5py.check_string_dtype(np.dtype(dtype)) else np.dtype(dtype).itemsize
    per_member = itemsize * int(np.prod(row, dtype=np.int64))
    rows = max(1, CHUNK_BYTES // per_member)
    options = {"compression": "gzip", "compression_opts": 1, "shuffle": True} if compressed else {}
    return group.create_dataset(name, shape=(0,) + row, maxshape=(None,) + row, chunks=(rows,) + row, dtype=dtype,
                                **options)


def _write_response(f, response, member, dof, family, normalized: bool) -> None:
    freq = f.create_dataset("frequency", data=response.omega)
    freq.attrs["units"] = "rad/s"
    freq.make_scale("frequency")
    f.attrs["input_dof"] = response.input_dof
    f.attrs["response"] = "exact receptance" if response.exact else "measured by simulation to steady state"

    def stacked(group, name, data, units):
        ds = group.create_dataset(name, data=data)
        ds.attrs["units"] = units
        ds.dims[0].attach_scale(member)
        ds.dims[1].attach_scale(freq)
        ds.dims[2].attach_scale(dof)
        return ds

    if response.ground:
        f.attrs["response"] = "exact transmissibility under harmonic ground displacement"
        ds = stacked(f, "amplitude", response.amplitude, "1")
        ds.attrs["description"] = "displacement transmissibility |X / U|: absolute amplitude over the ground's"
        stacked(f, "phase", response.phase, "rad").attrs["description"] = "lag of X behind the ground displacement"
        ds = f.create_dataset("force_transmissibility", data=response.force_transmissibility)
        ds.attrs["units"] = "1"
        ds.attrs["description"] = "|force through the elements to ground| / (k_g |U|), k_g = 1^T K 1"
        ds.dims[0].attach_scale(member)
        ds.dims[1].attach_scale(freq)
    elif response.exact:
        stacked(f, "amplitude", response.amplitude, "m/N")
        stacked(f, "phase", response.phase, "rad")
    if normalized:  # the book's Equation (9-34) axes, 1 DOF: X K / F0 against r = omega / omega_n
        k = family.K[:, 0, 0]
        ratio = f.create_dataset("frequency_ratio", data=response.omega[None, :] / np.sqrt(k / family.M[:, 0, 0])[:, None])
        ratio.dims[0].attach_scale(member)
        ratio.dims[1].attach_scale(freq)
        if response.exact and not response.ground:
            stacked(f, "normalized_amplitude", response.amplitude * k[:, None, None], "1")
    for direction, (amp, lag) in response.measured.items():
        group = f.create_group(f"measured/{direction}")
        stated(stacked(group, "amplitude", amp, "m/N"), response.accuracy["measured"])
        stated(stacked(group, "phase", lag, "rad"), response.accuracy["measured"])
        ds = group.create_dataset("steady", data=response.steady[direction])
        ds.dims[0].attach_scale(member)
        ds.dims[1].attach_scale(freq)
    if response.difference is not None:
        f["measured"].attrs["max_difference_from_exact"] = response.difference
    peaks = f.create_group("peaks")
    peak = axis(peaks, "peak", np.arange(len(response.peaks)))
    # member_index and dof_name, not member and dof: a variable named as a dimension would be read as its coordinate
    with_scales(peaks.create_dataset("member_index", data=np.array([p["member"] for p in response.peaks],
                                                                    dtype=int)), peak)
    with_scales(_strings(peaks, "dof_name", [p["dof"] for p in response.peaks]), peak)
    ds = with_scales(peaks.create_dataset("omega", data=np.array([p["omega"] for p in response.peaks], dtype=float)),
                      peak)
    ds.attrs["units"] = "rad/s"
    with_scales(peaks.create_dataset("amplitude", data=np.array([p["amplitude"] for p in response.peaks],
                                                                 dtype=float)), peak)
    for name, value in response.accuracy.items():  # the exact data sets': amplitudes, phases, peaks
        if name in f:
            stated(f[name], value)
    with_scales(_strings(peaks, "source", [f"measured, sweep {p['direction']}" if "direction" in p else "exact"
                                            for p in response.peaks]), peak)
