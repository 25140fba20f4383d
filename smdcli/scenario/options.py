"""The [solver] table's form (the method's name and options are checked against the solvers' registry where a run is
set up: smdcli.solvers.run), the [sweep] table and [[expect]] checks.

Must not import: solvers, model, or any layer above."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from smdcli.errors import ScenarioError
from smdcli.scenario.reader import _kind, _Table

from smdcli.scenario.spec import EXPECT_QUANTITIES, EXPECT_UNITS, ExpectSpec, SolverSpec
SOLVER_KEYS = ("method", "rtol", "atol", "dt")  # and a method's own options, which the registry knows


def unknown_solver_key(file: str, key: str, known: tuple[str, ...]) -> ScenarioError:
    """A [solver] key that neither the table nor any method reads, with the key it most likely means."""
    return _Table(file, "solver", {key: None}).unknown(key, known)


def _read_solver(t: _Table) -> SolverSpec:
    method = t.string("method", "auto")
    rtol = t.number("rtol", 1e-6, positive=True)
    atol = t.number("atol", 1e-9, positive=True)
    dt = t.number("dt", None, positive=True)
    options = []
    for key in t.data:
        if key in SOLVER_KEYS:
            continue
        value = t.raw(key)
        if isinstance(value, bool) or not isinstance(value, (int, float, str)):
            raise t.fail(key, f"expected a number or a string, found {_kind(value)}")
        if isinstance(value, str) and value.strip()[:1] in tuple("0123456789+-."):  # a number as a string ("25 %")
            value = t._check_number(key, value, None, False, "1")  # a method's own options are ratios
        options.append((key, value))
    return SolverSpec(method=method, rtol=rtol, atol=atol, dt=dt, options=tuple(options))


def _bounds_pair(entry: Any) -> bool:
    """[lower, upper]: numbers with lower < upper, or unit strings (the command converts them with the parameter's unit
    and checks their order)."""
    if not (isinstance(entry, list) and len(entry) == 2 and all(
            isinstance(v, (int, float, str)) and not isinstance(v, bool) for v in entry)):
        return False
    return any(isinstance(v, str) for v in entry) or entry[0] < entry[1]


def _number_or_text(value: Any) -> float | str:
    return value if isinstance(value, str) else float(value)


FIT_KEYS = ("data", "parameters", "bounds", "channels", "weights")


def _read_fit(t: _Table) -> tuple[tuple[str, Any], ...]:
    """[fit]'s keys, their types checked: `smd fit` reads the paths, channels and the data file, and names this
    file in its errors."""
    items = []
    for key in FIT_KEYS:
        if not t.has(key):
            continue
        value = t.raw(key)
        if key == "data":
            if not isinstance(value, str) or not value:
                raise t.fail(key, f"expected a file name, found {_kind(value)}")
        elif key in ("parameters", "channels"):
            value = [value] if isinstance(value, str) else value
            if not isinstance(value, list) or not value or not all(isinstance(v, str) for v in value):
                raise t.fail(key, f"expected a string or an array of strings, found {_kind(value)}")
            value = tuple(value)
        else:  # bounds = { "path" = [lo, hi] }, weights = { "channel" = w }
            if not isinstance(value, dict):
                raise t.fail(key, f"expected a table, found {_kind(value)}")
            for name, entry in value.items():
                pair = key == "bounds"
                good = _bounds_pair(entry) if pair else (isinstance(entry, (int, float)) and not isinstance(entry, bool)
                                                         and entry > 0)
                if not good:
                    raise ScenarioError(t.file, f"fit.{key}.{name}", ("expected [lower, upper] with lower < upper"
                                                                        if pair else "expected a number > 0")
                                        + f", found {entry!r}")
            value = tuple((name, tuple(_number_or_text(v) for v in entry) if key == "bounds" else float(entry))
                          for name, entry in value.items())
        items.append((key, value))
    t.finish(FIT_KEYS)
    return tuple(items)


OPTIMIZE_KEYS = ("parameters", "minimize", "subject_to", "starts", "input", "input_psd", "psd_units")


def _read_optimize(t: _Table) -> tuple[tuple[str, Any], ...]:
    """[optimize]'s keys, their types checked (`smd optimize` reads the paths, objectives and DOFs themselves, and
    names this file in its errors): parameters = { "path" = [lo, hi] }, minimize = "OBJECTIVE", subject_to = a
    string or strings 'OBJECTIVE <= VALUE', starts = N, input = "DOF", input_psd = "FILE" or "white:LEVEL",
    psd_units = "g" or "m/s^2"."""
    items = []
    for key in OPTIMIZE_KEYS:
        if not t.has(key):
            continue
        value = t.raw(key)
        if key == "parameters":
            if not isinstance(value, dict) or not value:
                raise t.fail(key, f"expected a table of path = [lower, upper], found {_kind(value)}")
            for name, entry in value.items():
                if not _bounds_pair(entry):
                    raise ScenarioError(t.file, f"optimize.parameters.{name}",
                                        f"expected [lower, upper] with lower < upper, found {entry!r}")
            value = tuple((name, tuple(_number_or_text(v) for v in entry)) for name, entry in value.items())
        elif key == "subject_to":
            value = [value] if isinstance(value, str) else value
            if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
                raise t.fail(key, f"expected a string or an array of strings, found {_kind(value)}")
            value = tuple(value)
        elif key == "starts":
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise t.fail(key, f"expected a whole number >= 1, found {value!r}")
        elif not isinstance(value, str) or not value:
            raise t.fail(key, f"expected a string, found {_kind(value)}")
        items.append((key, value))
    t.finish(OPTIMIZE_KEYS)
    return tuple(items)


SWEEP_KEYS = ("parameter", "values", "labels", "ic", "frequency", "normalized", "input", "direction",
              "measure", "quantity", "metric", "method")


def _read_sweep(t: _Table) -> tuple[tuple[str, Any], ...]:
    # Types only: the sweep command reads the contents and names this file in its errors.
    items = []
    for key in SWEEP_KEYS:
        if not t.has(key):
            continue
        value = t.raw(key)
        if key in ("normalized", "measure"):
            if not isinstance(value, bool):
                raise t.fail(key, f"expected true or false, found {_kind(value)}")
        elif key in ("parameter", "labels", "ic"):
            if isinstance(value, str) and key == "parameter":
                value = [value]
            if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
                raise t.fail(key, f"expected a string or an array of strings, found {_kind(value)}")
            value = tuple(value)
        elif key == "values":
            value = _sweep_values(t, value)
        elif key == "frequency":
            if isinstance(value, list):
                value = t.numbers(key, unit="rad/s")
            elif not isinstance(value, str):
                raise t.fail(key, f"expected an array of numbers or a range string, found {_kind(value)}")
        elif not isinstance(value, str):
            raise t.fail(key, f"expected a string, found {_kind(value)}")
        items.append((key, value))
    t.finish(SWEEP_KEYS)
    return tuple(items)


def _sweep_values(t: _Table, value: Any) -> tuple:
    """One value spec (a range string or an array of numbers and unit strings), or an array of such specs (one per
    parameter); unit strings stay strings: the sweep converts them with its parameter's unit."""
    def one(v, where):
        if isinstance(v, str):
            return v
        if isinstance(v, list) and all(isinstance(x, (int, float, str)) and not isinstance(x, bool) for x in v):
            return tuple(x if isinstance(x, str) else t._check_number(f"{where}[{i}]", x, None, False, "1")
                         for i, x in enumerate(v))
        raise t.fail(where, f"expected an array of numbers or a range string, found {_kind(v)}")

    if isinstance(value, list) and value and all(isinstance(v, (list, str)) for v in value):
        return tuple(one(v, f"values[{i}]") for i, v in enumerate(value))
    return (one(value, "values"),)


EXPECT_KEYS = ("quantity", "dof", "mode", "min", "max", "file", "rtol", "atol")
_PER_DOF = ("peak_displacement", "rms_displacement", "settling_time")


def _read_expect(t: _Table, index: int, dofs: tuple[str, ...], scenario_file: str) -> ExpectSpec:
    """One [[expect]] table: which quantity, of which DOF or mode, within which bounds (or which golden file)."""
    quantity = t.string("quantity", choices=EXPECT_QUANTITIES)
    allowed = ("quantity",) + (("dof",) if quantity in _PER_DOF else ("mode",) if quantity == "natural_frequency"
                               else ("file", "rtol", "atol") if quantity == "golden" else ()) \
        + (() if quantity == "golden" else ("min", "max"))
    for key in EXPECT_KEYS:
        if t.has(key) and key not in allowed:
            raise t.fail(key, f"does not apply to quantity {quantity!r} (it takes {', '.join(allowed[1:])})")
    dof = t.string("dof") if quantity in _PER_DOF else None
    if dof is not None and dof not in dofs:
        raise t.fail("dof", f"expected one of the DOFs {', '.join(map(repr, dofs))}, found {dof!r}")
    mode = t.integer("mode", 1, minimum=1) if quantity == "natural_frequency" else 1
    if mode > len(dofs):
        raise t.fail("mode", f"expected a mode from 1 to {len(dofs)}, found {mode}")
    low, high = (t.number(key, None, unit=EXPECT_UNITS[quantity]) for key in ("min", "max"))
    if quantity != "golden" and low is None and high is None:
        raise t.fail(None, "expected min, max or both")
    if low is not None and high is not None and low > high:
        raise t.fail("min", f"expected min <= max, found min {low:g} > max {high:g}")
    file = None
    if quantity == "golden":
        name = t.string("file")
        file = str(Path(name) if Path(name).is_absolute() else Path(scenario_file).parent / name)
        if not Path(file).is_file():
            raise t.fail("file", f"expected a golden result file, found no file at {file!r}")
        problem = _golden_problem(file)
        if problem:
            raise t.fail("file", f"expected a result file of `smd simulate` as golden, found {file!r}: {problem}")
    rtol = t.number("rtol", 1e-9, minimum=0.0) if quantity == "golden" else 1e-9
    atol = t.number("atol", 0.0, minimum=0.0, unit="1") if quantity == "golden" else 0.0
    t.finish(EXPECT_KEYS)
    return ExpectSpec(index, quantity, dof, mode, low, high, file, rtol, atol)


HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"


def _golden_problem(file: str) -> str | None:
    """Why a file cannot serve as a golden (not HDF5, not smd's, not a simulate result), or None."""
    try:
        with open(file, "rb") as f:
            head = f.read(len(HDF5_SIGNATURE))
    except OSError as exc:
        return f"cannot be read ({exc.strerror})"
    if head != HDF5_SIGNATURE:
        return "it is not an HDF5 file"
    import h5py

    try:
        with h5py.File(file, "r") as f:
            if "smd_version" not in f.attrs or "kind" not in f.attrs:
                return "an HDF5 file, but not one smd wrote"
            kind = f.attrs["kind"]
            kind = kind.decode() if isinstance(kind, bytes) else str(kind)
            if kind != "simulate":
                return f"an smd {kind} file"
            missing = [name for name in ("time", "displacement") if name not in f]
            if missing:
                return f"it has no {missing[0]} data set"
    except Exception as exc:  # h5py raises OSError, KeyError or RuntimeError for damaged files
        return f"it cannot be read as HDF5 ({str(exc).split('(')[0].strip() or type(exc).__name__})"
    return None


IDA_KEYS = ("records", "im", "edp", "collapse", "runs", "im_tolerance", "tail")


def _read_ida(t: _Table) -> tuple[tuple[str, Any], ...]:
    """[ida]'s keys, their types checked (`smd ida` reads the records, IM, EDP and collapse rule itself): records =
    a folder, file or list of them (relative to the scenario), im, edp, collapse strings, runs a whole number,
    im_tolerance and tail numbers."""
    items = []
    for key in IDA_KEYS:
        if not t.has(key):
            continue
        value = t.raw(key)
        if key == "records":
            value = [value] if isinstance(value, str) else value
            if not isinstance(value, list) or not value or not all(isinstance(v, str) for v in value):
                raise t.fail(key, f"expected a folder or file, or an array of them, found {_kind(value)}")
            base = Path(t.file).parent
            value = tuple(str(v if Path(v).is_absolute() else base / v) for v in value)
        elif key in ("im", "edp", "collapse"):
            if not isinstance(value, str):
                raise t.fail(key, f"expected a string, found {_kind(value)}")
        elif key == "runs":
            value = t.integer(key, minimum=0)
        else:
            value = t.number(key, positive=True)
        items.append((key, value))
    t.finish(IDA_KEYS)
    return tuple(items)
