"""The house's shape: imports run one way, from the commands down to the scenario, with no circle, and no
module grows past what a newcomer can read."""

import ast
import subprocess
import sys
from pathlib import Path


PACKAGE = Path(__file__).resolve().parents[1] / "smdcli"

# Lowest first. A module may import its own layer and the layers below it, never one above.
LAYERS = [
    ("base", ["smdcli", "smdcli.errors", "smdcli.expression", "smdcli.result", "smdcli.interrupts",
              "smdcli.progress", "smdcli.provenance", "smdcli.resources", "smdcli.strict_json", "smdcli.text"]),
    ("elements", ["smdcli.elements"]),  # the laws: read by the scenario, used by everything that solves
    ("shapes", ["smdcli.shapes"]),  # the force shapes: likewise
    ("scenario", ["smdcli.scenario"]),
    ("model", ["smdcli.model"]),
    ("kernels", ["smdcli.kernels"]),
    ("solvers", ["smdcli.solvers"]),
    ("sweep", ["smdcli.sweep"]),
    ("analysis", ["smdcli.analysis"]),
    ("writers", ["smdcli.io", "smdcli.plots"]),
    ("commands", ["smdcli.commands"]),
    ("cli", ["smdcli.cli", "smdcli.cli_support", "smdcli.cli_files", "smdcli.cli_analyses", "smdcli.api", "smdcli.__main__"]),
]
# The one import allowed to go up: the package root hands out the Python API (load, simulate, write) on first
# use (PEP 562 __getattr__), so `import smdcli` stays as light as the version string.
LAZY_API = ("smdcli", "smdcli.api")
MAX_LINES = 450


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def layer_of(module: str) -> int:
    """The layer of a module: the most specific prefix listed (smdcli.cli_support before smdcli)."""
    best, best_len = None, -1
    for index, (_, prefixes) in enumerate(LAYERS):
        for prefix in prefixes:
            # the package root is a module of its own, not the prefix of all (else no module is ever in no layer)
            inside = module.startswith(prefix + ".") and prefix != "smdcli"
            if (module == prefix or inside) and len(prefix) > best_len:
                best, best_len = index, len(prefix)
    assert best is not None, f"{module} is in no layer: add it to LAYERS"
    return best


def imports(path: Path) -> set[str]:
    """The smd modules a file imports, at the top or inside functions."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names if a.name.startswith("smdcli")}
        elif isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("smdcli"):
            for alias in node.names:
                candidate = f"{node.module}.{alias.name}"
                found.add(candidate if candidate in MODULES else node.module)
    return found


GRAPH = {name: imports(path) for name, path in MODULES.items()}


def test_a_module_in_no_layer_is_named():
    """A new top-level module must be placed in a layer: the check fires (it once could not, every name matching
    the package root)."""
    import pytest

    with pytest.raises(AssertionError, match="smdcli.newcomer is in no layer"):
        layer_of("smdcli.newcomer")
    assert LAYERS[layer_of("smdcli.solvers.registry")][0] == "solvers"
    assert LAYERS[layer_of("smdcli.solvers.exact.linear")][0] == "solvers"
    assert LAYERS[layer_of("smdcli.solvers.exact.linear")][0] == "solvers"


def test_every_module_has_a_layer_and_a_docstring_saying_what_it_must_not_import():
    for name, path in MODULES.items():
        layer_of(name)
        doc = ast.get_docstring(ast.parse(path.read_text())) or ""
        assert doc, f"{name} has no module docstring"
        if name.count(".") >= 1 and name not in ("smdcli.__main__",) and layer_of(name) > 0:
            assert "must not import" in doc.lower() or "imports nothing" in doc.lower(), \
                f"{name}: its docstring does not say what it must not import"


def back_edges(graph: dict[str, set[str]]) -> list[str]:
    """Every import that goes up a layer."""
    return [f"{a} ({LAYERS[layer_of(a)][0]}) imports {b} ({LAYERS[layer_of(b)][0]})"
            for a, targets in graph.items() for b in sorted(targets)
            if layer_of(b) > layer_of(a) and (a, b) != LAZY_API]


def find_circle(graph: dict[str, set[str]]) -> list[str] | None:
    """An import circle, as the modules along it, or None."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for target in sorted(graph.get(node, ())):
            if target == node or target not in graph:
                continue
            if state.get(target) == 1:
                return stack[stack.index(target):] + [target]
            if target not in state:
                found = visit(target)
                if found:
                    return found
        stack.pop()
        state[node] = 2
        return None

    for name in graph:
        if name not in state:
            found = visit(name)
            if found:
                return found
    return None


def test_no_import_goes_up_a_layer():
    back = back_edges(GRAPH)
    assert not back, "back edges:\n" + "\n".join(back)


def test_no_import_circle():
    # The lazy API hook runs after the package is imported, so it closes no circle at import time.
    circle = find_circle({a: targets - {LAZY_API[1]} if a == LAZY_API[0] else targets for a, targets in GRAPH.items()})
    assert circle is None, "import circle: " + " -> ".join(circle)


def test_the_checks_catch_a_back_edge_and_a_circle():
    """The two checks above on made-up graphs: they are not vacuous."""
    assert back_edges({"smdcli.scenario.load": {"smdcli.solvers.registry"}})
    assert not back_edges({"smdcli.scenario.load": {"smdcli.elements.registry", "smdcli.errors"}})
    assert find_circle({"smdcli.sweep.a": {"smdcli.sweep.b"}, "smdcli.sweep.b": {"smdcli.sweep.c"},
                        "smdcli.sweep.c": {"smdcli.sweep.a"}}) == ["smdcli.sweep.a", "smdcli.sweep.b",
                                                                   "smdcli.sweep.c", "smdcli.sweep.a"]
    assert find_circle({"smdcli.sweep.a": {"smdcli.sweep.b"}, "smdcli.sweep.b": set()}) is None


def test_no_module_is_over_450_lines():
    long = {name: len(path.read_text().splitlines()) for name, path in MODULES.items()}
    assert all(n <= MAX_LINES for n in long.values()), {k: v for k, v in long.items() if v > MAX_LINES}


def test_every_registered_method_loads_as_a_solver_of_its_name():
    """The registry is the one table of names: each entry's class imports, and the solver carries the entry's name."""
    from smdcli.solvers.base import Solver
    from smdcli.solvers.registry import METHODS, get_solver

    assert len({m.name for m in METHODS}) == len(METHODS)
    for method in METHODS:
        solver = get_solver(method.name)
        assert isinstance(solver, Solver) and solver.name == method.name and solver.description


def test_the_scenario_and_the_step_by_step_methods_are_kept_apart():
    """No arrow from scenario/ into solvers/, none from analysis/ into the step-by-step methods (issue 54)."""
    for name, targets in GRAPH.items():
        if name.startswith("smdcli.scenario"):
            assert not {t for t in targets if t.startswith("smdcli.solvers")}, name
        if name.startswith("smdcli.analysis"):
            assert not {t for t in targets if t.startswith("smdcli.solvers.integrators")}, name


def test_help_and_scenario_loading_import_no_heavy_module():
    """`smd --help` imports none of scipy, matplotlib, h5py, numba; reading a scenario imports no solver (the help
    reads the registry's names, plain data)."""
    probe = ("import sys; from smdcli.cli import run; run(['--help']); "
             "heavy = [m for m in ('scipy', 'matplotlib', 'h5py', 'numba') if m in sys.modules]; "
             "from smdcli import scenario; scenario.load('scenarios/three_dof_forced.toml'); "
             "solvers = sorted(m for m in sys.modules if m.startswith('smdcli.solvers') "
             "and m not in ('smdcli.solvers', 'smdcli.solvers.registry')); "
             "print(heavy, solvers)")
    result = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, cwd=PACKAGE.parent)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip().splitlines()[-1] == "[] []", result.stdout


def test_a_small_linear_scene_without_plots_imports_no_scipy_numba_or_matplotlib(tmp_path):
    """`smd simulate` of a 1-DOF linear scene with --no-plots imports none of scipy (the energy balance's incidence
    matrix pulled in scipy.sparse, 0.17 s of a 1 s run, and its Van Loan exponential scipy.linalg, 0.22 s), numba,
    matplotlib, pydantic (typer's option checks, 0.14 s) or importlib.metadata (scipy's version, 20 ms): they do no
    work there."""
    probe = ("import sys; from smdcli.cli import run; "
             f"code = run(['simulate', 'scenarios/one_dof_underdamped.toml', '--no-plots', '-q', '-o', {str(tmp_path)!r}]); "
             "print(code, [m for m in ('scipy', 'numba', 'matplotlib', 'pydantic', 'importlib.metadata') "
             "if m in sys.modules])")
    result = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, cwd=PACKAGE.parent)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip().splitlines()[-1] == "0 []", result.stdout


def test_the_api_exposes_every_analysis_by_name():
    """smdcli.<name> for each analysis the API lists is the analysis module's own function, and analyses import
    nothing above them (the layers above check that)."""
    import importlib

    import smdcli
    from smdcli import api

    assert set(smdcli._ANALYSES) == set(api.ANALYSES)
    for name, (module, attribute) in api.ANALYSES.items():
        assert getattr(smdcli, name) is getattr(importlib.import_module(module), attribute), name
    assert set(smdcli._ANALYSES) <= set(smdcli.__all__)


def test_no_test_imports_the_tests_folder_as_a_package():
    """The tests import each other as the modules pytest puts on the path (`from conftest import ...`), never as
    `tests.conftest`, nor do the scripts they run: the `peers` extra's pyrotd installs a top-level package named
    `tests`, which shadows this folder (it has no __init__.py) and stopped the suite at collection once installed."""
    offenders = []
    for path in sorted(Path(__file__).resolve().parent.glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom):
                names = [node.module or ""]
            elif isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.Constant) and isinstance(node.value, str):  # a script a test runs
                names = [line.split()[1] for line in node.value.splitlines() if line.startswith(("from ", "import "))
                         and len(line.split()) > 1]
            else:
                continue
            offenders += [f"{path.name}:{node.lineno} {name}" for name in names if name.split(".")[0] == "tests"]
    assert not offenders, offenders
