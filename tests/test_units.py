"""Unit strings in every numeric field of a scenario ("25 N/mm", "3 t", "0.35 g", "2 Hz", "5 %"): converted to SI with
pint, checked against the field's dimension, in sweep values too; results stay SI.

The field units below are this test's own table (the contract docs/scenario.md states), not the reader's."""

from __future__ import annotations

import copy
import dataclasses
import math
import subprocess
import sys
import tomllib

import numpy as np
import pytest

from conftest import ROOT, SCENARIOS
from smdcli import scenario
from smdcli.errors import ScenarioError
from smdcli.scenario.units import UnitError, to_si

G = 9.80665  # standard gravity, m/s^2 (CGPM 1901)
INCH, POUND_FORCE = 0.0254, 4.4482216152605  # exact definitions, m and N


@pytest.mark.parametrize("text, unit, si", [
    ("25 N/mm", "N/m", 25e3), ("10 kN", "N", 1e4), ("3 t", "kg", 3e3), ("500 g", "kg", 0.5),
    ("0.35 g", "m/s^2", 0.35 * G), ("981 gal", "m/s^2", 9.81), ("250 mg", "m/s^2", 0.25 * G),
    ("2 Hz", "rad/s", 4 * math.pi), ("120 rpm", "rad/s", 4 * math.pi), ("3 rad/s", "rad/s", 3.0),
    (f"{4 * math.pi!r} rad/s", "Hz", 2.0), ("2 Hz", "Hz", 2.0), ("5 %", "1", 0.05), ("5%", "1", 0.05),
    ("0.05", "1", 0.05),
    ("90 deg", "rad", math.pi / 2), ("20 ms", "s", 0.02), ("2 min", "s", 120.0), ("25 mm", "m", 0.025),
    ("30 cm/s", "m/s", 0.3), ("2 kip/in", "N/m", 2e3 * POUND_FORCE / INCH), ("1.5 N s/mm", "N s/m", 1500.0),
    ("2 N s^2/m^2", "N s^2/m^2", 2.0), ("1 N/mm^3", "N/m^3", 1e9), ("-5 mm", "m", -0.005), (".5 g", "m/s^2", G / 2),
    ("1e3 N/m", "N/m", 1e3), ("3 1/mm^2", "1/m^2", 3e6),
])
def test_a_unit_string_is_its_value_in_si(text, unit, si):
    """Each against its definition: g is standard gravity on an acceleration and a gram on a mass; Hz on an
    angular frequency is cycles per second (2 Hz = 4 pi rad/s); gal is the galileo (cm/s^2)."""
    assert to_si(text, unit) == pytest.approx(si, rel=1e-15, abs=0)  # a few roundings of composed factors


@pytest.mark.parametrize("text, unit, message", [
    ("10 kg", "N/m", "expected a stiffness (force/length), found a mass"),
    ("3 t", "s", "expected a time, found a mass"),
    ("2 Hz", "s", "expected a time, found a frequency"),
    ("5 %", "N", "expected a force, found a ratio (dimensionless)"),
    ("1 J", "N", "expected a force, found an energy"),
    ("1 m/s^2", "rad/s", "expected an angular frequency, found an acceleration"),
    ("0.3 g", "N", "expected a force, found a mass"),
    ("25", "N/m", "found '25' with no unit"),
    ("ten", "N/m", "expected a stiffness (force/length) as a number or \"<number> <unit>\""),
    ("25 N/mx", "N/m", "whose unit cannot be read"),
    ("1 m**", "m", "whose unit cannot be read"),
])
def test_a_unit_of_another_dimension_is_named(text, unit, message):
    with pytest.raises(UnitError, match=None) as info:
        to_si(text, unit)
    assert message in str(info.value)


# ------------------------------------------------------------------ every field of every bundled scenario

# (table, key) -> SI unit; a table's context decides the rest (a ground motion's quantity, a damper's law)
_UNITS = {("time", k): "s" for k in ("start", "end", "step")} | {
    ("mass", "m"): "kg", ("mass", "x0"): "m", ("mass", "v0"): "m/s",
    ("spring", "k"): "N/m", ("spring", "k3"): "N/m^3", ("spring", "fy"): "N", ("spring", "hardening"): "1",
    ("spring", "alpha"): "1", ("spring", "n"): "1", ("spring", "A"): "1", ("spring", "z0"): "m",
    ("damper", "c"): "N s/m", ("friction", "force"): "N", ("friction", "static"): "N",
    ("friction", "stribeck_velocity"): "m/s", ("friction", "viscous"): "N s/m", ("friction", "regularization"): "m/s",
    ("friction", "belt_velocity"): "m/s", ("stop", "min"): "m", ("stop", "max"): "m", ("stop", "k"): "N/m",
    ("stop", "c"): "N s/m", ("stop", "restitution"): "1",
    ("system", "M"): "kg", ("system", "C"): "N s/m", ("system", "K"): "N/m", ("system", "x0"): "m",
    ("system", "v0"): "m/s", ("damping", "alpha"): "1/s", ("damping", "beta"): "s", ("damping", "zeta"): "1",
    ("damping", "omega"): "rad/s", ("damping", "modal"): "1", ("solver", "rtol"): "1", ("solver", "atol"): "m",
    ("solver", "dt"): "s", ("building", "storey_heights"): "m", ("ida", "tail"): "s", ("ida", "im_tolerance"): "1",
    ("ground_motion", "scale"): "1", ("ground_motion", "filter"): "Hz",
} | {(t, k): u for t in ("force", "ground_motion") for k, u in (
    ("t0", "s"), ("omega", "rad/s"), ("frequency", "Hz"), ("period", "s"), ("phase", "rad"), ("duration", "s"),
    ("duty", "1"), ("f0", "Hz"), ("f1", "Hz"), ("t1", "s"), ("t", "s"), ("dt", "s"))}
_GROUND = {"displacement": "m", "velocity": "m/s", "acceleration": "m/s^2"}
_NOT_MEASURES = {("force", "terms"), ("ground_motion", "filter_order"), ("time", "points"), ("ida", "runs"),
                 ("ground_motion", "channel"), ("force", "channel"), ("optimize", "starts")}
# non-SI units of each dimension, and their size in SI (exact decimal scalings, so the values agree to rounding)
_SCALED = {"s": ("ms", 1e-3), "kg": ("g", 1e-3), "m": ("mm", 1e-3), "m/s": ("mm/s", 1e-3), "N/m": ("N/mm", 1e3),
           "N s/m": ("kN s/m", 1e3), "N/m^3": ("N/mm^3", 1e9), "N": ("kN", 1e3), "1": ("%", 1e-2),
           "rad/s": ("mrad/s", 1e-3), "Hz": ("kHz", 1e3), "rad": ("mrad", 1e-3), "1/s": ("1/ms", 1e3),
           "m/s^2": ("mm/s^2", 1e-3), "N s^2/m^2": ("N s^2/mm^2", 1e6)}


def _unit_of(table: str, key: str, entry: dict) -> str | None:
    """The SI unit of one numeric field by this test's table, None for a count or a field it leaves to others."""
    if (table, key) in _NOT_MEASURES or table in ("sweep", "fit", "optimize", "expect"):
        return None
    if table == "solver" and key not in ("rtol", "atol", "dt"):
        return None  # a method's own option, read by the method
    if key in ("amplitude", "values", "shift"):
        return _GROUND[entry["quantity"]] if table == "ground_motion" else "N"
    if table == "damper" and key == "c" and entry.get("law") == "quadratic":
        return "N s^2/m^2"
    if table == "spring" and key in ("beta", "gamma"):
        return f"1/m^{entry.get('n', 1)}"
    return _UNITS[(table, key)]


def _is_numeric(value) -> bool:
    """A number, or a (nested) non-empty array of numbers."""
    if isinstance(value, list):
        return bool(value) and all(_is_numeric(v) for v in value)
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _rewritten(doc: dict, write) -> tuple[dict, int]:
    """A copy of the document with every numeric field's numbers (matrices and arrays too) replaced by write(x, unit);
    and how many were."""
    out = copy.deepcopy(doc)
    count = 0

    def numbers(value, unit):
        nonlocal count
        if isinstance(value, list):
            return [numbers(v, unit) for v in value]
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            count += 1
            return write(value, unit)
        return value

    for table, body in out.items():
        for entry in body if isinstance(body, list) else [body] if isinstance(body, dict) else []:
            if entry.get("units") is not None:
                continue  # a ground motion in g: its numbers are in the table's units key, not SI
            for key, value in list(entry.items()):
                if not _is_numeric(value):
                    continue
                unit = _unit_of(table, key, entry)
                if unit is not None:
                    entry[key] = numbers(value, unit)
    return out, count


def _same(a, b, rel: float, where: str = "") -> None:
    """Two parsed scenarios equal field by field, floats within `rel`."""
    if dataclasses.is_dataclass(a) and not isinstance(a, type):
        assert type(a) is type(b), where
        for f in dataclasses.fields(a):
            _same(getattr(a, f.name), getattr(b, f.name), rel, f"{where}.{f.name}")
    elif isinstance(a, (tuple, list)):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            _same(x, y, rel, f"{where}[{i}]")
    elif isinstance(a, float) and not isinstance(b, str):
        assert b == pytest.approx(a, rel=rel, abs=0) or (math.isnan(a) and math.isnan(b)), where
    elif isinstance(a, np.ndarray) or hasattr(a, "toarray"):
        a, b = (x.toarray() if hasattr(x, "toarray") else x for x in (a, b))
        np.testing.assert_allclose(b, a, rtol=rel, atol=0, err_msg=where)
    else:
        assert a == b, where


BUNDLED = sorted(p.name for p in SCENARIOS.glob("*.toml"))


@pytest.mark.parametrize("name", BUNDLED)
def test_every_field_of_a_bundled_scenario_takes_its_si_unit_and_a_scaled_one(name):
    """Each number of each measured field written "<x> <SI unit>" parses to the very scene; written in a scaled unit
    (mm, kN, %, kHz, ...) to the scene within the rounding of one scaling."""
    path = SCENARIOS / name
    text = path.read_text()
    doc = tomllib.loads(text)
    plain = scenario.parse_document(copy.deepcopy(doc), text, str(path))
    in_si, count = _rewritten(doc, lambda x, unit: f"{x!r} {unit}" if unit != "1" else repr(x))
    _same(plain, scenario.parse_document(in_si, text, str(path)), rel=0.0)
    scaled, _ = _rewritten(doc, lambda x, unit: f"{x / _SCALED[unit][1]!r} {_SCALED[unit][0]}"
                           if unit in _SCALED else f"{x!r} {unit}")
    _same(plain, scenario.parse_document(scaled, text, str(path)), rel=4e-16)
    assert count > 0


@pytest.mark.parametrize("name", ["three_dof_forced.toml", "shear_frame_bilinear.toml", "stick_slip_belt.toml",
                                  "vibro_impact_gap.toml", "five_storey_building.toml", "bouc_wen_benchmark.toml",
                                  "quarter_car_bump.toml", "ida_frame.toml"])
def test_every_field_refuses_a_unit_of_another_dimension_naming_itself(name):
    """One field at a time given "1 kg m" (a dimension no field has): exit-2 material naming that field's path and
    what it expected."""
    path = SCENARIOS / name
    text = path.read_text()
    doc = tomllib.loads(text)
    fields = []
    _rewritten(doc, lambda x, unit: fields.append(unit) or x)
    assert fields
    for index in range(len(fields)):
        seen = iter(range(len(fields)))
        bad, _ = _rewritten(doc, lambda x, unit: "1 kg m" if next(seen) == index else x)
        with pytest.raises(ScenarioError) as info:
            scenario.parse_document(bad, text, str(path))
        message = str(info.value)
        assert "expected " in message and "found a quantity in kg * m ('1 kg m')" in message, message


def test_the_issue_examples(tmp_path, cli):
    """k = "10 kg" is exit 2 with the issue's words, nothing written; "25 N/mm", "3 t", "0.35 g", "2 Hz", "5 %" run
    as their SI numbers."""
    bad = tmp_path / "bad.toml"
    bad.write_text('[time]\nend = 1.0\n[[mass]]\nname = "m1"\nm = 1.0\n[[spring]]\nconnects = ["ground", "m1"]\n'
                   'k = "10 kg"\n')
    result = cli("simulate", str(bad), "-o", str(tmp_path / "out"))
    assert result.exit_code == 2
    assert result.stderr.strip() == (f"smd: {bad}: spring[0].k: expected a stiffness (force/length), found a mass "
                                     f"('10 kg')")
    assert not (tmp_path / "out").exists()

    def scene(k, m, a, w, zeta):
        return (f'[time]\nend = 2.0\npoints = 201\n[[mass]]\nname = "m1"\nm = {m}\n'
                f'[[spring]]\nconnects = ["ground", "m1"]\nk = {k}\n[damping]\nmodal = {zeta}\n'
                f'[ground_motion]\nquantity = "acceleration"\ntype = "sine"\namplitude = {a}\nomega = {w}\n')

    with_units = scenario.parse(scene('"25 N/mm"', '"3 t"', '"0.35 g"', '"2 Hz"', '"5 %"'))
    plain = scenario.parse(scene(25e3, 3e3, 0.35 * G, 4 * math.pi, 0.05))
    _same(plain, dataclasses.replace(with_units, text=plain.text), rel=2e-16)


def test_a_ground_motion_in_g_by_its_units_key_or_its_amplitude_is_the_same_and_both_at_once_refused():
    base = '[time]\nend = 1.0\n[[mass]]\nname = "m1"\nm = 1.0\n[[spring]]\nconnects = ["ground", "m1"]\nk = 1.0\n' \
           '[ground_motion]\nquantity = "acceleration"\ntype = "table"\n'
    by_key = scenario.parse(base + 'units = "g"\nt = [0.0, 0.5]\nvalues = [0.0, 0.3]\nshift = 0.01\n')
    by_string = scenario.parse(base + 't = ["0 s", "500 ms"]\nvalues = [0.0, "0.3 g"]\nshift = "0.01 g"\n')
    assert by_string.ground_motion.shape.values == pytest.approx(by_key.ground_motion.shape.values, rel=2e-16)
    assert by_key.ground_motion.shape.values[1] == pytest.approx(0.31 * G, rel=2e-16)
    with pytest.raises(ScenarioError, match="values carries its own unit; leave units out"):
        scenario.parse(base + 'units = "g"\nt = [0.0, 0.5]\nvalues = [0.0, "0.3 g"]\n')


# ------------------------------------------------------------------ sweeps


_SWEEP = ('[time]\nend = 1.0\npoints = 11\n[[mass]]\nname = "m1"\nm = 2.0\n[[spring]]\nconnects = ["ground", "m1"]\n'
          'k = 20e3\n[[damper]]\nconnects = ["ground", "m1"]\nc = 30.0\n'
          '[[force]]\non = "m1"\ntype = "sine"\namplitude = 1.0\nomega = 50.0\n[sweep]\n')


@pytest.mark.parametrize("table, si", [
    ('parameter = "spring[0].k"\nvalues = "linspace(20, 30, 5) N/mm"', [np.linspace(20e3, 30e3, 5)]),
    ('parameter = "spring[0].k"\nvalues = ["20 N/mm", "25 N/mm", 30e3]', [[20e3, 25e3, 30e3]]),
    ('parameter = "spring[0].k"\nvalues = "20:30:5 kN/m"', [[20e3, 25e3, 30e3]]),
    ('parameter = "spring[0].k"\nvalues = "20, 25 N/mm"', [[20e3, 25e3]]),
    ('parameter = ["spring[0].k", "mass[0].m"]\nvalues = ["20:30:10 N/mm", ["2 kg", "3000 g"]]',
     [[20e3, 30e3], [2.0, 3.0]]),
    ('parameter = ["force[0].omega", "damper[0].c"]\nvalues = ["1, 2 Hz", "logspace(0, 1, 2) N s/mm"]',
     [[2 * math.pi, 4 * math.pi], [1e3, 1e4]]),
    ('parameter = "force[0].amplitude"\nvalues = ["1 kN", "2 kN"]', [[1e3, 2e3]]),
])
def test_sweep_values_take_a_unit_after_the_spec_or_in_each_string(table, si):
    from smdcli.sweep import read_spec

    spec = read_spec(scenario.parse(_SWEEP + table), {})
    assert len(spec.values) == len(si)
    for got, want in zip(spec.values, si):
        np.testing.assert_allclose(got, want, rtol=2e-16, atol=0)


def test_a_sweep_value_of_another_dimension_is_exit_2_naming_sweep_values(tmp_path, cli):
    path = tmp_path / "sweep.toml"
    path.write_text(_SWEEP + 'parameter = "spring[0].k"\nvalues = "linspace(20, 30, 5) kg"\n')
    result = cli("sweep", str(path), "-o", str(tmp_path / "out"), "--no-plots")
    assert result.exit_code == 2
    assert "sweep.values: expected a stiffness (force/length), found a mass" in result.stderr
    assert not (tmp_path / "out").exists()


def test_a_swept_stiffness_in_n_per_mm_gives_the_sweep_in_si(tmp_path, cli):
    """The result file's parameter values and their units attribute are SI, as the same sweep written in N/m."""
    import h5py

    results = {}
    for label, values in (("mm", '"20, 30 N/mm"'), ("si", "[20e3, 30e3]")):
        path = tmp_path / f"{label}.toml"
        path.write_text(_SWEEP + f'parameter = "spring[0].k"\nvalues = {values}\n')
        result = cli("sweep", str(path), "-o", str(tmp_path / label), "--no-plots", "-q")
        assert result.exit_code == 0, result.output
        with h5py.File(tmp_path / label / f"{label}_sweep.h5") as f:
            results[label] = (f["parameters/spring[0].k"][()], f["parameters/spring[0].k"].attrs["units"],
                              f["displacement"][()])
    np.testing.assert_array_equal(results["mm"][0], [20e3, 30e3])
    assert results["mm"][1] == results["si"][1] == "N/m"
    np.testing.assert_allclose(results["mm"][2], results["si"][2], rtol=0, atol=1e-15)


def test_a_scene_without_unit_strings_never_imports_pint(tmp_path):
    """pint's import and registry cost 0.7 s: a scene in plain SI numbers does not pay it, one with units does."""
    plain = ("import sys; from smdcli import scenario; scenario.load('scenarios/three_dof_forced.toml'); "
             "print('pint' in sys.modules)")
    result = subprocess.run([sys.executable, "-c", plain], capture_output=True, text=True, cwd=ROOT)
    assert result.stdout.strip() == "False", result.stderr
    united = "import sys; from smdcli import scenario; scenario.parse(sys.argv[1]); print('pint' in sys.modules)"
    text = '[time]\nend = 1.0\n[[mass]]\nname = "m1"\nm = "3 t"\n'
    result = subprocess.run([sys.executable, "-c", united, text], capture_output=True, text=True, cwd=ROOT)
    assert result.stdout.strip() == "True", result.stderr


def test_fit_and_optimize_bounds_take_the_parameters_units():
    """[optimize] parameters and [fit] bounds as unit strings are the parameter's SI bounds; another dimension is
    refused naming the table's entry."""
    from smdcli.sweep.spec import table_bounds

    text = (SCENARIOS / "five_storey_tmd.toml").read_text().replace(
        '"spring[5].k" = [2.0e4, 8.0e4], "damper[0].c" = [100.0, 2.0e4]',
        '"spring[5].k" = ["20 N/mm", "80 kN/m"], "damper[0].c" = [100.0, "20 kN s/m"]')
    sc = scenario.parse(text, str(SCENARIOS / "tmd.toml"))
    pairs = dict(sc.optimize)["parameters"]
    bounds = [table_bounds(sc, f"optimize.parameters.{name}", name, pair) for name, pair in pairs]
    assert bounds == [(2e4, 8e4), (100.0, 2e4)]
    with pytest.raises(ScenarioError, match=r"optimize.parameters.spring\[5\].k: expected a stiffness "
                                            r"\(force/length\), found a force"):
        table_bounds(sc, "optimize.parameters.spring[5].k", "spring[5].k", ("2 kN", "3 kN"))
    with pytest.raises(ScenarioError, match=r"expected \[lower, upper\] with lower < upper, found \[30000, 20000\]"):
        table_bounds(sc, "fit.bounds.spring[5].k", "spring[5].k", ("30 N/mm", 2e4))


def test_the_schema_takes_unit_strings_where_the_reader_does():
    """`smd schema` validates every bundled scenario written in unit strings, as an editor would check it."""
    import json

    import jsonschema
    from typer.testing import CliRunner

    from smdcli.cli import run as smd

    with CliRunner().isolation() as streams:
        assert smd(["schema"]) == 0
        validator = jsonschema.Draft202012Validator(json.loads(streams[0].getvalue().decode()))
    for name in BUNDLED:
        doc = tomllib.loads((SCENARIOS / name).read_text())
        scaled, _ = _rewritten(doc, lambda x, unit: f"{x / _SCALED[unit][1]!r} {_SCALED[unit][0]}"
                               if unit in _SCALED else f"{x!r} {unit}")
        errors = [e.message for e in validator.iter_errors(scaled)]
        assert not errors, (name, errors)


def test_a_parameter_written_with_its_unit_is_read_in_si_by_sweeps_fits_and_sensitivities(tmp_path, cli):
    """A swept or differentiated field the scenario gives as "25 N/mm": its value is 25000 N/m, and the
    sensitivity to it is the one of the same scene written in N/m."""
    import h5py

    from smdcli.sweep.family import parameter_value

    text = _SWEEP.replace("k = 20e3", 'k = "20 N/mm"').replace("m = 2.0", 'm = "2000 g"').removesuffix("[sweep]\n")
    sc = scenario.parse(text)
    doc = tomllib.loads(text)
    assert parameter_value(doc, "spring[0].k", sc) == 2e4 and parameter_value(doc, "mass[0].m", sc) == 2.0
    values = {}
    for label, body in (("units", text), ("si", _SWEEP.removesuffix("[sweep]\n"))):
        path = tmp_path / f"{label}.toml"
        path.write_text(body)
        result = cli("sensitivity", str(path), "--param", "spring[0].k", "-o", str(tmp_path / label), "--no-plots")
        assert result.exit_code == 0, result.output
        with h5py.File(tmp_path / label / f"{label}_sensitivity.h5") as f:
            values[label] = (f["value"][()], f["d_displacement"][()], f["value"].attrs["units"])
    assert values["units"][0][0] == values["si"][0][0] == 2e4
    assert list(values["units"][2]) == list(values["si"][2])
    np.testing.assert_array_equal(values["units"][1], values["si"][1])  # the very scene: the same numbers


def test_a_swept_ground_amplitude_in_g_is_in_the_tables_units():
    """With units = "g" the amplitude's numbers are in g: a sweep value "0.3 g" is 0.3 there, "2.94199 m/s^2" the
    same, and the member's acceleration is 0.3 g in SI."""
    from smdcli.sweep import read_spec
    from smdcli.sweep.family import build_family
    from smdcli.sweep.spec import parameter_units

    text = ('[time]\nend = 1.0\npoints = 11\n[[mass]]\nname = "m1"\nm = 1.0\n[[spring]]\nconnects = ["ground", "m1"]\n'
            'k = 100.0\n[ground_motion]\nquantity = "acceleration"\ntype = "sine"\nunits = "g"\namplitude = 0.5\n'
            f'omega = 3.0\n[sweep]\nparameter = "ground_motion.amplitude"\nvalues = ["0.3 g", "{0.6 * G!r} m/s^2"]\n')
    sc = scenario.parse(text)
    spec = read_spec(sc, {})
    np.testing.assert_allclose(spec.values[0], [0.3, 0.6], rtol=2e-16)
    assert parameter_units("ground_motion.amplitude", sc) == "g"
    family = build_family(sc, spec)
    amplitudes = [family.member_scenario(s).ground_motion.shape.amplitude for s in range(2)]
    np.testing.assert_allclose(amplitudes, [0.3 * G, 0.6 * G], rtol=4e-16)
