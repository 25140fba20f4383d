"""Every category of bad input: exit 2, one line naming file and field, no traceback, nothing written."""


import pytest

VALID = """
[time]
end = 1.0
step = 0.1
[[mass]]
name = "m1"
m = 1.0
[[mass]]
name = "m2"
m = 2.0
[[spring]]
connects = ["ground", "m1"]
k = 10.0
[[spring]]
connects = ["m1", "m2"]
k = 5.0
[[damper]]
connects = ["ground", "m1"]
c = 0.5
[[force]]
on = "m1"
type = "sine"
amplitude = 1.0
omega = 2.0
"""

MATRIX = """
[time]
end = 1.0
[system]
dofs = ["a", "b"]
M = [[1.0, 0.0], [0.0, 1.0]]
K = [[2.0, -1.0], [-1.0, 2.0]]
"""


def edit(text, old, new):
    assert old in text
    return text.replace(old, new, 1)


def with_force(kind, fields):
    """VALID with its sine force replaced by one of another type."""
    return edit(edit(VALID, 'type = "sine"', f'type = "{kind}"'), "amplitude = 1.0\nomega = 2.0", fields)


CASES = {
    "syntax": (edit(VALID, "end = 1.0", "end = = 1.0"), "line 3"),
    "unknown_key": (edit(VALID, "m = 1.0", "m = 1.0\ncolour = 'red'"), "mass[0].colour: unknown key"),
    "misspelled": (edit(VALID, "amplitude = 1.0", "amplitud = 1.0"), "did you mean 'amplitude'"),
    "wrong_type": (edit(VALID, "k = 10.0", 'k = "ten"'), "spring[0].k: expected a number, found string"),
    "missing_end": (edit(VALID, "end = 1.0", ""), "time.end: required field is missing"),
    "no_time": (edit(edit(VALID, "[time]", ""), "end = 1.0\nstep = 0.1", ""), "time: required table is missing"),
    "zero_mass": (edit(VALID, "m = 1.0", "m = 0.0"), "mass[0].m: expected a number > 0"),
    "negative_mass": (edit(VALID, "m = 2.0", "m = -2.0"), "mass[1].m: expected a number > 0"),
    "negative_k": (edit(VALID, "k = 5.0", "k = -5.0"), "spring[1].k: expected a number >= 0"),
    "nan": (edit(VALID, "c = 0.5", "c = nan"), "damper[0].c: expected a finite number"),
    "inf": (edit(VALID, "amplitude = 1.0", "amplitude = inf"), "force[0].amplitude: expected a finite number"),
    "unknown_node": (edit(VALID, '["m1", "m2"]', '["m1", "m3"]'), "spring[1].connects: unknown node 'm3'"),
    "ground_to_ground": (edit(VALID, '["ground", "m1"]', '["ground", "ground"]'), "ground to ground"),
    "self_loop": (edit(VALID, '["m1", "m2"]', '["m2", "m2"]'), "'m2' to itself"),
    "duplicate_mass": (edit(VALID, 'name = "m2"', 'name = "m1"'), "mass[1].name: duplicate name"),
    "reserved_name": (edit(VALID, 'name = "m2"', 'name = "ground"'), "reserved"),
    "force_unknown_dof": (edit(VALID, 'on = "m1"', 'on = "m9"'), "force[0].on: unknown DOF 'm9'"),
    "omega_and_frequency": (edit(VALID, "omega = 2.0", "omega = 2.0\nfrequency = 1.0"), "exactly one of omega or frequency"),
    "unknown_force_type": (edit(VALID, 'type = "sine"', 'type = "sinus"'), "did you mean 'sine'"),
    "end_before_start": (edit(VALID, "end = 1.0", "end = 1.0\nstart = 2.0"), "time.end: expected a time after start"),
    "zero_step": (edit(VALID, "step = 0.1", "step = 0.0"), "time.step: expected a number > 0"),
    "negative_step": (edit(VALID, "step = 0.1", "step = -0.1"), "time.step: expected a number > 0"),
    "grid_too_large": (edit(VALID, "step = 0.1", "step = 1e-12"), "too large"),
    "step_and_points": (edit(VALID, "step = 0.1", "step = 0.1\npoints = 11"), "either step or points"),
    "unknown_method": (VALID + '[solver]\nmethod = "ode99"\n', "solver.method: unknown method"),
    "option_of_other_method": (VALID + "[solver]\nmethod = \"hht\"\nbeta = 0.3\n", "solver.beta: applies to method 'newmark' only"),
    "option_out_of_range": (VALID + "[solver]\nmethod = \"hht\"\nalpha = 0.5\n", "solver.alpha: expected a number in"),
    "negative_rtol": (VALID + "[solver]\nrtol = -1e-6\n", "solver.rtol: expected a number > 0"),
    "expression_import": (with_force("expression", "expr = \"__import__('os')\""), "force[0].expr: call of '__import__'"),
    "expression_attribute": (with_force("expression", 'expr = "t.real"'), "force[0].expr: attribute access"),
    "expression_overflow": (with_force("expression", 'expr = "9**9**9"'), "force[0]: force is not finite"),
    "table_missing_file": (with_force("table", 'file = "nope.csv"'), "force[0].file: "),
    "table_not_increasing": (with_force("table", "t = [0.0, 1.0, 0.5]\nvalues = [1.0, 2.0, 3.0]"), "force[0].t[2]: expected strictly increasing"),
    "table_length_mismatch": (with_force("table", "t = [0.0, 1.0]\nvalues = [1.0]"), "force[0].values: expected 2 numbers"),
    "cubic_without_k3": (edit(VALID, "k = 5.0", 'k = 5.0\nlaw = "cubic"'), "spring[1].k3: required field is missing"),
    "mixed_forms": (MATRIX + '[[mass]]\nname = "z"\nm = 1.0\n', "mass: cannot be combined with [system]"),
    "matrix_not_square": (edit(MATRIX, "[0.0, 1.0]]\nK", "[0.0, 1.0, 3.0]]\nK"), "system.M[1]: expected 2 numbers"),
    "matrix_not_symmetric": (edit(MATRIX, "[[2.0, -1.0], [-1.0, 2.0]]", "[[2.0, -1.0], [-1.5, 2.0]]"), "system.K: expected a symmetric"),
    "mass_matrix_singular": (edit(MATRIX, "[[1.0, 0.0], [0.0, 1.0]]", "[[1.0, 0.0], [0.0, 0.0]]"), "system.M: expected a symmetric positive definite"),
    "x0_length": (MATRIX + "x0 = [1.0]\n", "system.x0: expected 2 numbers"),
    "empty": ("", "is empty"),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_bad_scenario_exit_2_one_line_nothing_written(case, tmp_path, cli):
    text, expected = CASES[case]
    scenario = tmp_path / f"{case}.toml"
    scenario.write_text(text)
    out = tmp_path / "out"
    out.mkdir()
    keep = out / f"{case}.h5"
    keep.write_bytes(b"an earlier result")
    result = cli("simulate", scenario, "-o", out)
    assert result.exit_code == 2, result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert str(scenario) in lines[0]
    assert expected in lines[0]
    assert "Traceback" not in result.output
    assert sorted(p.name for p in out.iterdir()) == [keep.name]
    assert keep.read_bytes() == b"an earlier result"


def test_not_utf8_directory_and_missing_file(tmp_path, cli):
    bad = tmp_path / "latin1.toml"
    bad.write_bytes('title = "caf\xe9"\n'.encode("latin-1"))
    for path, expected in [(bad, "is not UTF-8"), (tmp_path, "is a directory"), (tmp_path / "none.toml", "no such file")]:
        result = cli("simulate", path, "-o", tmp_path / "out")
        assert result.exit_code == 2
        assert expected in result.stderr
        assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


def test_unwritable_output_folder(tmp_path, cli):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    scenario = tmp_path / "ok.toml"
    scenario.write_text(VALID)
    result = cli("simulate", scenario, "-o", blocker / "sub")
    assert result.exit_code == 2
    assert "cannot create output folder" in result.stderr
