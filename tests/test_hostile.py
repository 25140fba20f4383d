"""Hostile inputs, third round: each ends in one line naming the file or option and the field (exit 2, or exit 1
where a solver genuinely fails), in well under 2 s, with nothing written, no Python warning and no traceback;
through the Python API the same input raises smd's own error with the same message."""

import time
from pathlib import Path

import h5py
import numpy as np
import pytest
from conftest import ROOT, SCENARIOS

import smdcli
from smdcli.scenario.records import MAX_ROWS

BASE = """
[time]
end = 2.0
step = 0.01
[[mass]]
name = "m1"
m = 1.0
[[spring]]
connects = ["ground", "m1"]
k = 100.0
[[damper]]
connects = ["ground", "m1"]
c = 0.5
"""


def _record(rows) -> str:
    return "\n".join(f"{float(t)!r},{float(a)!r}" for t, a in rows) + "\n"


def _ground_table(name: str, units: str = "g", extra: str = "") -> str:
    return BASE + f'[ground_motion]\nquantity = "acceleration"\ntype = "table"\nfile = "{name}"\nunits = "{units}"\n{extra}'


def _expression(expr: str, where: str = "force") -> str:
    if where == "force":
        return BASE + f'[[force]]\non = "m1"\ntype = "expression"\nexpr = "{expr}"\n'
    return BASE + f'[ground_motion]\nquantity = "{where}"\ntype = "expression"\nexpr = "{expr}"\n'


# name: (scenario text, {file: text}, what the one line must say after "smd: <file>: ")
SCENES = {
    "record_subnormal_step": (_ground_table("r.csv"), {"r.csv": _record([(0.0, 0.0), (5e-324, 1.0), (1e-323, 0.0)])},
                              "ground_motion.file: "),
    "record_overflows_in_g": (_ground_table("r.csv"), {"r.csv": _record([(0, 0), (0.01, 1e308), (0.02, 0)])},
                              "overflows double precision"),
    "record_slope_overflows": (_ground_table("r.csv", "m/s^2"),
                               {"r.csv": _record([(0, 0), (1e-10, 1.7e300), (2e-10, -1.7e300)])}, "slope"),
    "record_scaled_past_double": (_ground_table("r.csv", "m/s^2", "scale = 1e300\n"),
                                  {"r.csv": _record([(0, 0), (0.01, 1e10), (0.02, 0)])}, "ground_motion.scale"),
    "record_time_overflows": (_ground_table("r.csv"), {"r.csv": "0,0\n1e308,1\n1e309,0\n"}, "finite"),
    "square_ground_at_GHz": (BASE + '[ground_motion]\nquantity = "displacement"\ntype = "square"\namplitude = 0.01\n'
                                    'frequency = 1e9\n', {}, "ground_motion: the ground's displacement or velocity jumps"),
    "square_ground_velocity_at_GHz": (BASE + '[ground_motion]\nquantity = "velocity"\ntype = "square"\n'
                                             'amplitude = 0.01\nfrequency = 3e8\n', {}, "jumps"),
    "expression_edges_explode": (_expression("sign(sin(1e6*t))", "displacement"), {}, "limit 100000"),
    "pulse_below_time_rounding": (BASE + '[[force]]\non = "m1"\ntype = "pulse"\namplitude = 1.0\nt0 = 0.5\n'
                                         'duration = 1e-300\n', {}, "force[0].duration"),
    "integer_literal_hundreds_of_digits": (_expression("9" * 400 + "*t"), {}, "force[0].expr: the number"),
    "float_literal_past_double": (_expression("1e400*t"), {}, "force[0].expr"),
    "power_tower": (_expression("t**" * 70 + "t"), {}, "force[0].expr: expression is nested more than"),
    "functions_nested_deep": (_expression("sin(" * 80 + "t" + ")" * 80), {}, "nested more than"),
    "unary_chain": (_expression("-" * 90 + "t"), {}, "force[0].expr"),
    "derivative_explodes": (_expression("abs(sin(" * 30 + "100*t" + "))" * 30, "displacement"), {},
                            "ground_motion.expr: its derivative takes"),
    "derivative_of_a_tower": (_expression("t**" * 60 + "t", "displacement"), {}, "ground_motion.expr"),
    "rayleigh_overflows": (BASE + "[damping]\nalpha = 1e308\nbeta = 1e308\n", {}, "damping.alpha"),
    "rayleigh_zeta_overflows": (BASE.replace("k = 100.0", "k = 1e300") + "[damping]\nzeta = 1e300\n"
                                "omega = [1e300, 2e300]\n", {}, "damping.zeta"),
    "modal_overflows": (BASE + "[damping]\nmodal = 1e307\n", {}, "damping.modal"),
    "springs_sum_past_double": (BASE.replace("k = 100.0", "k = 1.7e308") +
                                '[[spring]]\nconnects = ["ground", "m1"]\nk = 1.7e308\n', {}, "spring[0].k"),
    "golden_not_hdf5": (BASE + '[[expect]]\nquantity = "golden"\nfile = "g.h5"\n', {"g.h5": "not hdf5"},
                        "expect[0].file: expected a result file of `smd simulate` as golden"),
    "golden_truncated": (BASE + '[[expect]]\nquantity = "golden"\nfile = "g.h5"\n', {"g.h5": "<truncated>"},
                         "cannot be read as HDF5"),
    "toml_duplicate_key": (BASE + '[solver]\nmethod = "auto"\nmethod = "exact"\n', {}, "line 16: invalid TOML: "
                                                                                        "Cannot overwrite a value"),
    "toml_trailing_dot": (BASE + "[solver]\nrtol = 1.0.0\n", {}, "line 15: invalid TOML"),
    "toml_unclosed_table": (BASE + "[[mass]\n", {}, "line 14: invalid TOML: Expected ']]'"),
    "toml_unterminated_string": (BASE + 'title = "abc\n', {}, "line 14: invalid TOML"),
    "many_masses": ("[time]\nend = 1.0\n" + "".join(f'[[mass]]\nname = "m{i}"\nm = 1.0\n' for i in range(60000)),
                    {}, "time.points: output grid of 1e+03 points x 60000 DOF is too large (limit 2e+07 samples)"),
}


def _write(tmp_path: Path, name: str) -> Path:
    text, files, _ = SCENES[name]
    for file, content in files.items():
        if content == "<truncated>":
            (tmp_path / file).write_bytes((ROOT / "tests" / "golden" / "two_dof_forced.h5").read_bytes()[:3000])
        else:
            (tmp_path / file).write_text(content)
    scenario = tmp_path / f"{name}.toml"
    scenario.write_text(text)
    return scenario


@pytest.mark.parametrize("name", sorted(SCENES))
def test_a_hostile_scenario_is_one_line_exit_2_from_cli_and_api(name, tmp_path, cli):
    scenario = _write(tmp_path, name)
    out = tmp_path / "out"
    out.mkdir()
    start = time.monotonic()
    result = cli("simulate", scenario, "-o", out)
    took = time.monotonic() - start
    lines = result.stderr.strip().splitlines()
    assert result.exit_code == 2, result.output
    assert len(lines) == 1 and lines[0].startswith(f"smd: {scenario}: ") and SCENES[name][2] in lines[0], lines
    assert "Traceback" not in result.output and "Warning" not in result.output
    assert not list(out.iterdir())
    assert took < 1.5, f"{took:.2f} s"
    with _no_warnings():
        with pytest.raises(smdcli.SmdError) as caught:
            smdcli.simulate(scenario)
    assert f"smd: {caught.value}" == lines[0]


class _no_warnings:
    """Python warnings in the block are recorded, and the block fails if there are any."""

    def __enter__(self):
        import warnings

        self._catcher = warnings.catch_warnings(record=True)
        self.caught = self._catcher.__enter__()
        warnings.simplefilter("always")
        return self

    def __exit__(self, *exc):
        self._catcher.__exit__(*exc)
        assert not [w for w in self.caught if issubclass(w.category, RuntimeWarning)], \
            [str(w.message) for w in self.caught]
        return False


def test_a_bom_is_accepted_in_a_scenario(tmp_path, cli):
    scenario = tmp_path / "bom.toml"
    scenario.write_bytes(("\ufeff" + BASE).encode())
    result = cli("simulate", scenario, "-o", tmp_path / "out", "--no-plots", "--quiet")
    assert result.exit_code == 0, result.output
    assert smdcli.load(scenario).masses[0].name == "m1"


@pytest.mark.parametrize("text", ["\ufeff0.0,0.0\n0.01,0.5\n0.02,0.0\n0.03,0.25\n",
                                  "Time (s),Acc (g)\n0.0,0.0\n0.01,0.5\n0.02,0.0\n0.03,0.25\n",
                                  "Time (s);Force (N)\r\n0.0;0.0\r\n0.01;0.5\r\n0.02;0.0\r\n0.03;0.25\r\n",
                                  "\ufefftime\tvalue\n# a comment\n\n0.0\t0.0\n0.01\t0.5\n0.02 0.0\n0.03   0.25\n"])
def test_byte_order_marks_and_headers_of_any_layout_are_read(text, tmp_path, cli):
    """Every sample of every layout read, none dropped, the same numbers; the first sample is at t = 0."""
    record = tmp_path / "r.csv"
    record.write_text(text)
    result = cli("spectrum", record, "-o", tmp_path, "--no-plots", "--json", "--periods", "0.5,1")
    assert result.exit_code == 0, result.output
    with h5py.File(tmp_path / "r_spectrum.h5") as f:
        np.testing.assert_array_equal(f["record/time"][()], [0.0, 0.01, 0.02, 0.03])
        np.testing.assert_allclose(f["record/acceleration"][()], np.array([0.0, 0.5, 0.0, 0.25]) * 9.80665,
                                   rtol=1e-15)


SPECTRUM_CASES = {
    "period_far_below_the_sampling": (_record([(0.01 * k, np.sin(k)) for k in range(200)]),
                                      ["--periods", "1e-9,1"], "--periods: 1e-09 s is far below"),
    "periods_of_picoseconds": (_record([(0.01 * k, np.sin(k)) for k in range(200)]),
                               ["--periods", "logspace(-12,-10,5)"], "--periods:"),
    "step_of_1e300": (_record([(0.0, 0.0), (1e300, 1.0), (2e300, 0.0), (3e300, 0.5)]), [], "--periods:"),
    "step_subnormal": (_record([(0.0, 0.0), (5e-324, 1.0), (1e-323, 0.0)]), [], "a normal double"),
    "values_overflow_in_g": (_record([(0, 0), (0.01, 1e308), (0.02, -1e308), (0.03, 0.5)]), [], "overflows"),
    "values_overflow_in_the_spectrum": (_record([(0, 1.5e308), (0.01, 1.5e308), (0.02, 1.5e308)]),
                                        ["--units", "m/s^2"], "the spectrum overflows double precision"),
    "too_many_rows": ("".join(f"{k * 0.001:.3f},0\n" for k in range(MAX_ROWS + 2000)), [], "rows"),
}


@pytest.mark.parametrize("name", sorted(SPECTRUM_CASES))
def test_a_hostile_record_is_one_line_exit_2(name, tmp_path, cli):
    text, options, says = SPECTRUM_CASES[name]
    record = tmp_path / "r.csv"
    record.write_text(text)
    out = tmp_path / "out"
    start = time.monotonic()
    result = cli("spectrum", record, "-o", out, *options)
    took = time.monotonic() - start
    lines = result.stderr.strip().splitlines()
    assert result.exit_code == 2, result.output
    assert len(lines) == 1 and says in lines[0], lines
    assert "Traceback" not in result.output and "Warning" not in result.output
    assert not out.exists() or not list(out.iterdir())
    assert took < 1.5, f"{took:.2f} s"


@pytest.mark.parametrize("address, says", [("tls://127.0.0.1:8786", "needs TLS certificates"),
                                           ("ucx://127.0.0.1:8786", "needs the UCX transport"),
                                           ("inproc://x", "inside one Python process"),
                                           ("foo://x", "is not a Dask transport"),
                                           ("127.0.0.1", "HOST:PORT"),
                                           ("tcp://127.0.0.1:1", "cannot reach a Dask scheduler there")])
def test_a_scheduler_address_smd_cannot_use_is_one_line(address, says, tmp_path, cli):
    start = time.monotonic()
    result = cli("sweep", SCENARIOS / "one_dof_regimes_sweep.toml", "--scheduler", address, "-o", tmp_path / "out",
                 "--no-plots")
    assert time.monotonic() - start < 1.5
    assert result.exit_code == 2 and result.stderr.count("\n") == 1 and says in result.stderr, result.output
    assert not (tmp_path / "out").exists()


def test_a_grid_of_members_too_large_is_refused_before_it_is_made(tmp_path, cli):
    start = time.monotonic()
    result = cli("sweep", SCENARIOS / "three_dof_forced.toml", "--param", "spring[0].k", "--values",
                 "linspace(1,2,100000)", "--param", "spring[1].k", "--values", "linspace(1,2,100000)", "-o", tmp_path)
    assert time.monotonic() - start < 1.5
    assert result.exit_code == 2 and "100000 x 100000" in result.stderr and result.stderr.count("\n") == 1


def test_the_api_checks_options_as_the_cli_does(tmp_path, cli):
    scene = SCENARIOS / "two_dof_forced.toml"
    for kwargs, flags in (({"atol": -5}, ["--atol", "-5"]), ({"rtol": 0}, ["--rtol", "0"]),
                          ({"rtol": -1}, ["--rtol", "-1"]), ({"rtol": float("nan")}, ["--rtol", "nan"]),
                          ({"method": "ode99"}, ["--method", "ode99"])):
        result = cli("simulate", scene, "-o", tmp_path / "out", *flags)
        assert result.exit_code == 2 and result.stderr.count("\n") == 1, result.output
        start = time.monotonic()
        with pytest.raises(smdcli.UsageError) as caught:
            smdcli.simulate(scene, **kwargs)
        assert time.monotonic() - start < 1.0
        assert result.stderr.strip() == f"smd: {caught.value}"
    assert not (tmp_path / "out").exists()


def test_outputs_make_their_folders_and_name_the_path_given(tmp_path, cli):
    simulated = smdcli.simulate(SCENARIOS / "two_dof_forced.toml")
    path = smdcli.write(simulated, tmp_path / "new" / "deeper" / "x.h5")
    assert path.exists()
    h5 = tmp_path / "new" / "deeper" / "x.h5"
    assert cli("export", h5, "-o", tmp_path / "exp" / "x.csv").exit_code == 0
    assert (tmp_path / "exp" / "x.csv").exists()
    assert cli("info", SCENARIOS / "two_dof_forced.toml", "--state-space", tmp_path / "ss" / "x.mat").exit_code == 0
    assert (tmp_path / "ss" / "x.mat").exists()
    blocker = tmp_path / "file"
    blocker.write_text("x")
    for args in (("export", h5, "-o", blocker / "x.csv"),
                 ("info", SCENARIOS / "two_dof_forced.toml", "--state-space", blocker / "x.npz")):
        result = cli(*args)
        assert result.exit_code == 2 and result.stderr.count("\n") == 1 and str(blocker) in result.stderr
        assert ".part" not in result.stderr and result.stdout == ""
    with pytest.raises(smdcli.UsageError) as caught:
        smdcli.write(simulated, blocker / "x.h5")
    assert str(blocker) in str(caught.value) and ".part" not in str(caught.value)
