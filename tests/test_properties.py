"""Property-based tests of the loader: random TOML documents, and random values put into valid ones,
give either a model or a ScenarioError, never another exception."""

import tomllib

import tomli_w
from conftest import SCENARIOS, replaced
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from smdcli import scenario
from smdcli.errors import ScenarioError
from smdcli.model import build, time_grid

KEYS = ["title", "time", "end", "start", "step", "points", "mass", "name", "m", "x0", "v0", "spring", "damper",
        "connects", "k", "c", "law", "k3", "force", "on", "type", "amplitude", "omega", "frequency", "period",
        "phase", "t0", "duration", "duty", "terms", "f0", "f1", "t1", "t", "values", "file", "interpolation",
        "expr", "solver", "method", "rtol", "atol", "dt", "system", "dofs", "M", "C", "K", "sweep", "parameter",
        "ground", "m1", "m2", "sine", "cubic", "quadratic", "auto", "RK45", "newmark", "beta", "alpha"]
NUMBERS = st.one_of(st.integers(-10**6, 10**6), st.floats(allow_nan=True, allow_infinity=True),
                    st.sampled_from([0, 1, -1, 1e-300, 1e300, 0.5, 25.0, 2.5]))
SCALARS = st.one_of(NUMBERS, st.booleans(), st.sampled_from(KEYS), st.text(max_size=12))
VALUES = st.recursive(SCALARS, lambda inner: st.one_of(st.lists(inner, max_size=4),
                                                        st.dictionaries(st.sampled_from(KEYS), inner, max_size=5)),
                      max_leaves=25)
DOCUMENTS = st.dictionaries(st.sampled_from(KEYS), VALUES, max_size=8)
SETTINGS = settings(max_examples=int(__import__("os").environ.get("SMD_HYPOTHESIS_EXAMPLES", 300)), deadline=None, suppress_health_check=[HealthCheck.too_slow])


def load_fully(text: str) -> None:
    """What simulate does before solving: parse, assemble, make the grid. A refusal is one line naming the file; a
    scene that loads is one the solvers can take: an increasing finite grid, finite matrices, M symmetric (to
    rounding) and positive definite."""
    import numpy as np

    try:
        sc = scenario.parse(text, "random.toml")
        model = build(sc)
        grid = time_grid(sc.time)
    except ScenarioError as exc:
        line = str(exc)
        assert line.startswith("random.toml") and "\n" not in line, line
        return
    assert len(grid) >= 2 and np.isfinite(grid).all() and np.all(np.diff(grid) > 0)
    dense = model.dense()
    for matrix in (dense.M, dense.C, dense.K):
        assert np.isfinite(matrix).all()
    size = float(np.abs(dense.M).max())
    assert np.abs(dense.M - dense.M.T).max() <= 1e-12 * max(size, 1.0)  # symmetric as the reader checks it
    assert np.linalg.eigvalsh(dense.M).min() > 0


def dumps(doc) -> str | None:
    try:
        return tomli_w.dumps(doc)
    except (TypeError, ValueError):  # e.g. arrays mixing tables and values, not TOML
        return None


@SETTINGS
@given(DOCUMENTS)
def test_random_documents_load_or_raise_scenario_error(doc):
    text = dumps(doc)
    if text is not None:
        load_fully(text)


@SETTINGS
@given(st.text(max_size=300))
def test_random_text_loads_or_raises_scenario_error(text):
    load_fully(text)


BUNDLED = {p.stem: tomllib.loads(p.read_text()) for p in sorted(SCENARIOS.glob("*.toml"))}


def leaves(node, path=()):
    """Paths to every value in a document (tables and arrays included)."""
    yield path
    if isinstance(node, dict):
        for key, value in node.items():
            yield from leaves(value, path + (key,))
    elif isinstance(node, list):
        for i, value in enumerate(node):
            yield from leaves(value, path + (i,))


@SETTINGS
@given(st.sampled_from(sorted(BUNDLED)), st.data(), VALUES)
def test_random_values_in_valid_documents_load_or_raise_scenario_error(stem, data, value):
    doc = BUNDLED[stem]
    paths = [p for p in leaves(doc) if p]
    path = data.draw(st.sampled_from(paths))
    text = dumps(replaced(doc, path, value))
    if text is not None:
        load_fully(text)


@SETTINGS
@given(st.sampled_from(sorted(BUNDLED)), st.data(), st.floats(allow_nan=True, allow_infinity=True))
def test_random_numbers_in_valid_documents_load_or_raise_scenario_error(stem, data, number):
    doc = BUNDLED[stem]
    paths = [p for p in leaves(doc) if p and isinstance(_get(doc, p), (int, float)) and not isinstance(_get(doc, p), bool)]
    path = data.draw(st.sampled_from(paths))
    text = dumps(replaced(doc, path, number))
    if text is not None:
        load_fully(text)


def _get(doc, path):
    for key in path:
        doc = doc[key]
    return doc


FAST = [s for s in sorted(BUNDLED) if s.startswith(("one_dof", "ic_", "two_dof_forced", "three_dof_matrix_free"))
        and s != "one_dof_nonlinear_stiff"]


@settings(max_examples=int(__import__("os").environ.get("SMD_HYPOTHESIS_EXAMPLES", 300)) // 3, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(st.sampled_from(FAST), st.data(), st.one_of(st.floats(allow_nan=False, allow_infinity=False),
                                                  st.sampled_from([1e-300, 1e-30, 1e30, 1e300, 5e-324])))
def test_any_number_a_valid_scene_accepts_solves_or_fails_cleanly(tmp_path, stem, data, number):
    """Past the loader: a scene that validates is solved, or its solver fails (exit 1); nothing else."""
    from smdcli.errors import SmdError
    from smdcli.commands.simulate import Options, simulate

    doc = BUNDLED[stem]
    paths = [p for p in leaves(doc) if p and isinstance(_get(doc, p), (int, float)) and not isinstance(_get(doc, p), bool)]
    path = data.draw(st.sampled_from(paths))
    text = dumps(replaced(doc, path, number))
    if text is None:
        return
    source = tmp_path / f"{stem}.toml"
    source.write_text(text)
    try:
        simulate(source, tmp_path / "out", Options(plots=False))
    except SmdError as exc:
        assert exc.exit_code in (1, 2)


# Lines of TOML, plain and not: what scenarios hold, and what the plain reader must hand to tomllib (escapes, literal
# and multi-line strings, dotted and quoted keys, inline tables, underscores, leading zeros, CRLF, control characters,
# duplicates, mixed and nested arrays, out-of-range integers, a missing value, text that is not TOML at all).
PLAIN_LINES = st.sampled_from([
    "[[mass]]", "[[ mass ]]", "[time]", "[ time ]", "[solver]", "[time]", "[[spring]]", "", "   ", "# comment",
    'name = "m1"', "m = 1.0", "m = 1", "m = +2", "m = -0.0", "k = 1e3", "k = 2.5E-03", "k = 0", "x0 = 1.5  # m",
    'connects = ["ground", "m1"]', 'connects = [ "m1" , "m2", ]', "values = [1, 2.5, -3e2]", "values = []",
    "values = [1,2,]", "flag = true", "flag = false", 'law = "cubic"', 'title = "a\tb"', "name = \"m\u00e9\"",
    'text = "\\u001b"', "text = 'literal'", 'text = """multi"""', "a.b = 1", '"quoted" = 1', "t = {a = 1}",
    "n = 1_000", "n = 01", "n = 1.", "n = .5", "n = inf", "n = nan", "n = 0x10", "n = 99999999999999999999",
    "n = 999999999999999999", 'mix = [1, "a"]', "nested = [[1], [2]]", "bools = [true]", "m =", "= 1",
    "m = 1 2", "[[mass]", "[mass]]", "[a.b]", "d = 1979-05-27", "c = 1 # \x01", "m = 1.0\r", "end = 10.0",
    "step = 0.01", "m = 1.0e+00", "k = -1E5", "x = [ ]", 'x = ["a""b"]', "x = [1 2]", "x = [,]",
    "x = [1, [2]]", "\x7f = 1", "m\t=\t3"])


@SETTINGS
@given(st.lists(PLAIN_LINES, max_size=12), st.booleans())
def test_the_plain_toml_reader_reads_what_tomllib_reads_or_hands_the_text_over(lines, final_newline):
    """Where the plain reader gives a document it is tomllib's, to the type of every value; where tomllib refuses a
    text, the plain reader gives None (tomllib's message is the user's)."""
    from smdcli.scenario.plain_toml import loads_plain

    text = "\n".join(lines) + ("\n" if final_newline else "")
    plain = loads_plain(text)
    try:
        expected = tomllib.loads(text)
    except tomllib.TOMLDecodeError:
        assert plain is None, text
        return
    if plain is not None:
        assert plain == expected and _types(plain) == _types(expected), text


def _types(node):
    """The document's shape with each value's type, so that 1 and 1.0 (equal in Python) differ."""
    if isinstance(node, dict):
        return {key: _types(value) for key, value in node.items()}
    if isinstance(node, list):
        return [_types(value) for value in node]
    return type(node).__name__


def test_the_plain_toml_reader_reads_every_bundled_plain_scenario_as_tomllib_does():
    from smdcli.scenario.plain_toml import loads_plain

    read = 0
    for path in sorted(SCENARIOS.glob("*.toml")):
        text = path.read_text()
        plain = loads_plain(text)
        if plain is not None:
            read += 1
            assert plain == tomllib.loads(text) and _types(plain) == _types(tomllib.loads(text)), path.name
    assert read >= 30  # most are plain: 39 of 43 when this was written
