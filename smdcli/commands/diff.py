"""smd diff: compare two smd result files data set by data set, within tolerances.

Every data set of either file is compared (or those named): numbers within
atol + rtol * max(|a|, |b|) (NaN equal to NaN), strings and integers exactly. A
difference is reported with its largest size, where it is (the coordinates of the
data set's dimension scales: time, DOF, member, frequency) and how many samples
differ. Run metadata (the creation time, wall times, the smd version, the /run
group) never makes files differ. A different scenario (by the SHA-256 of its text)
or solver is named, but only data decide the exit code: 0 same, 1 different,
2 a file unreadable, not an smd file, or (without --allow-failed) from a failed run.

Must not import: cli.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from smdcli.errors import UsageError

DEFAULT_RTOL = 1e-9
DEFAULT_ATOL = 0.0
# --tolerance stated: data sets without a stated accuracy (matrices, modes, forces) are a few roundings deep.
STATED_OTHER_RTOL = 1e-9
STATED_OTHER_ATOL = 1e-12  # times the data set's peak
RUN_METADATA = frozenset({"created", "wall_time_s", "smd_version"})  # attribute or data set names
RUN_METADATA_GROUPS = ("run",)


@dataclass
class DatasetDiff:
    """How one data set differs (or that it does not)."""

    name: str
    status: str  # "same", "different", "only in A", "only in B", "shape", "type"
    shape: tuple = ()
    other_shape: tuple = ()
    count: int = 0
    total: int = 0
    largest: float = 0.0
    relative: float = 0.0
    where: dict = field(default_factory=dict)
    values: tuple = ()


@dataclass
class Report:
    """All that differs between two files."""

    a: str
    b: str
    rtol: float
    atol: float
    datasets: list[DatasetDiff]
    notes: list[str]

    @property
    def differs(self) -> bool:
        """True when any compared data set differs."""
        return any(d.status != "same" for d in self.datasets)


def open_result(path: Path):
    """An smd result file open for reading; UsageError (exit 2) for a missing, unreadable or foreign file."""
    import h5py

    path = Path(path)
    if not path.exists():
        raise UsageError(f"{path}: no such file")
    if path.is_dir():
        raise UsageError(f"{path}: is a directory, expected an smd .h5 file")
    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        raise UsageError(f"{path}: not a readable HDF5 file ({str(exc).split('(')[0].strip() or 'unreadable'})") from None
    if "smd_version" not in f.attrs or "kind" not in f.attrs:
        f.close()
        raise UsageError(f"{path}: an HDF5 file, but not one smd wrote (no smd_version and kind attributes)")
    return f


def _datasets(f) -> dict:
    import h5py

    found = {}

    def visit(name, obj):
        parts = name.split("/")
        if isinstance(obj, h5py.Dataset) and parts[0] not in RUN_METADATA_GROUPS and parts[-1] not in RUN_METADATA:
            found[name] = obj

    f.visititems(visit)
    return found


def _failed(f) -> str | None:
    """Why the run of a file counts as failed, or None."""
    if "solver" in f and not bool(f["solver"].attrs.get("success", True)):
        return f"its run failed ({f['solver'].attrs.get('message', '')})"
    if "success" in f and f.attrs.get("kind") == "sweep" and not np.all(f["success"][()]):
        return f"{int((~f['success'][()].astype(bool)).sum())} of its members failed"
    return None  # a comparison records its failed runs as results


def _text(value) -> str:
    return value.decode() if isinstance(value, bytes) else str(value)


def _where(ds, index: tuple) -> dict:
    """Coordinates of an index from the data set's dimension scales (or the bare index)."""
    where = {}
    for axis, i in enumerate(index):
        scales = ds.dims[axis] if axis < len(ds.dims) else []
        if len(scales):
            scale = scales[0]
            key = scale.name.rsplit("/", 1)[-1]
            value = scale[i] if scale.ndim == 1 and i < scale.shape[0] else i
            where[key] = _text(value) if isinstance(value, bytes) else (value.item() if hasattr(value, "item") else value)
        else:
            where[f"axis{axis}"] = int(i)
    return where


def stated_accuracy(ds) -> float | None:
    """The accuracy a data set's run vouches for, relative to its peak or to its `accuracy_scale` (its
    `stated_accuracy` attribute; inf where the data are not determined), or None where it states none."""
    value = ds.attrs.get("stated_accuracy")
    if value is None:
        return None
    value = float(np.max(value))
    return None if np.isnan(value) else value


def _stated_bound(ds, data: np.ndarray) -> float | None:
    """The largest error a data set vouches for, in its units: stated accuracy times its accuracy_scale or peak."""
    accuracy = stated_accuracy(ds)
    if accuracy is None:
        return None
    if accuracy == np.inf:
        return np.inf
    scale = ds.attrs.get("accuracy_scale")
    if scale is None:
        with np.errstate(invalid="ignore"):
            finite = np.abs(data[np.isfinite(data)])
        scale = float(finite.max()) if finite.size else 0.0
    return accuracy * float(scale)


def _stated_tolerances(da, db, a, b) -> tuple[float, float]:
    """rtol, atol for --tolerance stated: the sum of the errors the two files vouch for, else rounding."""
    bounds = (_stated_bound(da, a), _stated_bound(db, b))
    if None not in bounds:
        return 0.0, bounds[0] + bounds[1]
    with np.errstate(invalid="ignore"):
        finite = [np.abs(x[np.isfinite(x)]) for x in (a, b)]
    peak = max((float(x.max()) for x in finite if x.size), default=0.0)
    return STATED_OTHER_RTOL, STATED_OTHER_ATOL * peak


def _compare(name: str, da, db, rtol: float | None, atol: float | None) -> DatasetDiff:
    """rtol None: the stated tolerances of the two data sets."""
    a, b = da[()], db[()]
    shape_a, shape_b = np.shape(a), np.shape(b)
    if shape_a != shape_b:
        return DatasetDiff(name, "shape", shape_a, shape_b)
    numeric = all(np.issubdtype(np.asarray(x).dtype, np.number) or np.asarray(x).dtype == bool for x in (a, b))
    if not numeric:
        count = int(np.sum(np.asarray(a, dtype=object) != np.asarray(b, dtype=object)))
        return DatasetDiff(name, "different" if count else "same", shape_a, shape_b, count, int(np.size(a)))
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    if rtol is None:
        rtol, atol = _stated_tolerances(da, db, a, b)
    with np.errstate(invalid="ignore", over="ignore"):
        gap = np.abs(a - b)
        both_nan = np.isnan(a) & np.isnan(b)
        same_inf = np.isinf(a) & (a == b)
        gap = np.where(both_nan | same_inf, 0.0, gap)
        gap = np.where(np.isnan(gap), np.inf, gap)  # NaN on one side only
        bound = atol + rtol * np.maximum(np.abs(a), np.abs(b))
        bad = gap > np.where(np.isfinite(bound) | (atol == np.inf), bound, 0.0)
    count = int(bad.sum())
    if not count:
        return DatasetDiff(name, "same", shape_a, shape_b, 0, int(a.size))
    flat = int(np.argmax(np.where(bad, gap, -1.0)))
    index = np.unravel_index(flat, a.shape) if a.ndim else ()
    scale = max(abs(a[index]), abs(b[index]))
    return DatasetDiff(name, "different", shape_a, shape_b, count, int(a.size), float(gap[index]),
                       float(gap[index] / scale) if scale > 0 else float("inf"), _where(da, index),
                       (float(a[index]), float(b[index])))


def _scenario_hash(f) -> str:
    return hashlib.sha256(_text(f.attrs.get("scenario", "")).encode()).hexdigest()


def diff(path_a: Path, path_b: Path, rtol: float | None = DEFAULT_RTOL, atol: float | None = DEFAULT_ATOL,
         names: list[str] | None = None, allow_failed: bool = False, stated: bool = False) -> Report:
    """Compare two smd files; UsageError (exit 2) for a file that cannot be compared.

    stated: each data set within what the two runs vouch for (their `stated_accuracy` times the peak),
    data sets without one within rounding (rtol 1e-9, atol 1e-12 of the peak); rtol and atol are then unused."""
    if stated:
        rtol = atol = None
    elif rtol < 0 or atol < 0:
        raise UsageError("--rtol and --atol must be >= 0")
    with open_result(path_a) as fa, open_result(path_b) as fb:
        notes = []
        for path, f in ((path_a, fa), (path_b, fb)):
            why = _failed(f)
            if why and not allow_failed:
                raise UsageError(f"{path}: {why}; compare it anyway with --allow-failed")
            if why:
                notes.append(f"{path}: {why}")
        kinds = (_text(fa.attrs["kind"]), _text(fb.attrs["kind"]))
        if kinds[0] != kinds[1]:
            notes.append(f"different kinds of file: {kinds[0]} vs {kinds[1]}")
        ha, hb = _scenario_hash(fa), _scenario_hash(fb)
        if ha != hb:
            notes.append(f"different scenario (sha256 {ha[:12]} vs {hb[:12]})")
        for key in ("method", "rtol", "atol", "dt"):
            va = fa["solver"].attrs.get(key) if "solver" in fa else None
            vb = fb["solver"].attrs.get(key) if "solver" in fb else None
            if va is not None and vb is not None and _text(va) != _text(vb) and \
                    not (isinstance(va, float) and np.isnan(va) and np.isnan(vb)):
                notes.append(f"different solver {key}: {_text(va)} vs {_text(vb)}")
        sets_a, sets_b = _datasets(fa), _datasets(fb)
        if names:
            wanted = [n.strip().lstrip("/") for n in names if n.strip()]
            unknown = [n for n in wanted if n not in sets_a and n not in sets_b]
            if unknown:
                raise UsageError(f"--datasets: {unknown[0]!r} is in neither file; they hold "
                                 f"{', '.join(sorted(set(sets_a) | set(sets_b))[:12])}")
        else:
            wanted = sorted(set(sets_a) | set(sets_b))
        results = []
        for name in wanted:
            if name not in sets_b:
                results.append(DatasetDiff(name, "only in A", np.shape(sets_a[name])))
            elif name not in sets_a:
                results.append(DatasetDiff(name, "only in B", (), np.shape(sets_b[name])))
            else:
                results.append(_compare(name, sets_a[name], sets_b[name], rtol, atol))
        return Report(str(path_a), str(path_b), rtol, atol, results, notes)


def format_report(report: Report) -> str:
    """Lines for the terminal: a verdict, then one line per differing data set and per note."""
    bad = [d for d in report.datasets if d.status != "same"]
    within = "within the accuracy each run states" if report.rtol is None else \
        f"rtol {report.rtol:g}, atol {report.atol:g}"
    head = (f"{report.a} vs {report.b}: " + (f"{len(bad)} of {len(report.datasets)} data sets differ"
                                              if bad else f"all {len(report.datasets)} data sets agree")
            + f" ({within})")
    lines = [head]
    for d in bad:
        label = "different time grids: " if d.name == "time" else ""
        if d.status == "only in A":
            lines.append(f"  /{d.name}: only in {report.a}")
        elif d.status == "only in B":
            lines.append(f"  /{d.name}: only in {report.b}")
        elif d.status == "shape":
            lines.append(f"  /{d.name}: {label}different shapes {d.shape} vs {d.other_shape}")
        elif d.largest:
            where = ", ".join(f"{k} = {v:.6g}" if isinstance(v, float) else f"{k} = {v}" for k, v in d.where.items())
            lines.append(f"  /{d.name} {d.shape}: {label}{d.count} of {d.total} samples differ; largest |a - b| = "
                         f"{d.largest:.3g} (relative {d.relative:.2g}: {d.values[0]:.10g} vs {d.values[1]:.10g})"
                         + (f" at {where}" if where else ""))
        else:
            lines.append(f"  /{d.name} {d.shape}: {d.count} of {d.total} entries differ")
    lines += [f"  note: {n}" for n in report.notes]
    return "\n".join(lines)


def as_dict(report: Report) -> dict:
    """The report as plain data (for --json)."""
    return {"a": report.a, "b": report.b, "tolerance": "stated" if report.rtol is None else "given",
            "rtol": report.rtol, "atol": report.atol, "differ": report.differs, "status": "different" if report.differs
            else "same", "exit_code": 1 if report.differs else 0,
            "notes": report.notes,
            "datasets": [{"name": d.name, "status": d.status, "shape": list(d.shape), "other_shape": list(d.other_shape),
                          "count": d.count, "total": d.total, "largest": d.largest, "relative": d.relative,
                          "where": d.where, "values": list(d.values)} for d in report.datasets]}
