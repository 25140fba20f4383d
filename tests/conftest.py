"""Shared helpers: scenarios from text, and the CLI run in-process."""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest
from typer.testing import CliRunner

from smdcli import scenario
from smdcli.model import build, time_grid

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = ROOT / "scenarios"


def sensitivity_with(sc, params: list[str], stacked_dofs: int):
    """smdcli.sensitivity with the modal path's threshold at stacked_dofs ((P + 1) n): 1 holds it on however small
    the scene, a huge one holds it off (the dense stacked system answers)."""
    import smdcli
    import smdcli.analysis.modal_sensitivity as modal_path

    saved = modal_path.STACKED_DOFS
    modal_path.STACKED_DOFS = stacked_dofs
    try:
        return smdcli.sensitivity(sc, params)
    finally:
        modal_path.STACKED_DOFS = saved


def assert_sensitivities_agree(found, reference, what: str = "") -> None:
    """Each parameter's d_displacement, d_velocity and d_acceleration of two sensitivity runs within ten times the
    sum of their stated errors, relative to the reference's largest."""
    import numpy as np

    for quantity in ("displacement", "velocity", "acceleration"):
        for i in range(len(found.parameter)):
            mine, theirs = getattr(found, f"d_{quantity}")[i], getattr(reference, f"d_{quantity}")[i]
            largest = max(float(np.abs(theirs).max()), 1e-300)
            allowed = 10 * (found.accuracy[f"d_{quantity}"][i] + reference.accuracy[f"d_{quantity}"][i]) * largest
            error = float(np.abs(mine - theirs).max())
            assert error <= allowed, (f"d_{quantity} / d {found.parameter[i]} differs by {error / largest:.3g} of its "
                                      f"largest (allowed {allowed / largest:.3g})\n{what}")


def bundled(name: str):
    """(scenario, model, grid) of a bundled scenario by stem."""
    sc = scenario.load(SCENARIOS / f"{name}.toml")
    return sc, build(sc), time_grid(sc.time)


def model_of(text: str, name: str = "test.toml"):
    """(scenario, model, grid) of scenario text."""
    sc = scenario.parse(text, name)
    return sc, build(sc), time_grid(sc.time)


def one_dof(c: float, k: float = 25.0, m: float = 1.0, x0: float = 0.1, v0: float = 0.0,
            end: float = 5.0, step: float = 0.05, law: str = "linear", extra: str = "") -> str:
    """Text of a 1-DOF scenario."""
    return f"""
[time]
end = {end!r}
step = {step!r}
[[mass]]
name = "m"
m = {m!r}
x0 = {x0!r}
v0 = {v0!r}
[[spring]]
connects = ["ground", "m"]
k = {k!r}
[[damper]]
connects = ["ground", "m"]
c = {c!r}
law = "{law}"
{extra}
"""


def chain_matrices(n: int, m: float = 1.0, k: float = 100.0, c: float = 0.5):
    """M, C, K (CSR) of an n-mass chain fixed at one end, m a mass, k and c a link: the element-form chain of
    test_large.chain() as a finite-element program would write it."""
    import numpy as np
    from scipy.sparse import diags

    def banded(value):
        main = np.full(n, 2 * value)
        main[-1] = value
        return diags([main, np.full(n - 1, -value), np.full(n - 1, -value)], [0, 1, -1]).tocsr()
    return diags(np.full(n, m)).tocsr(), banded(c), banded(k)


def chain_files(folder: Path, n: int, suffix: str = ".mtx", *, end: float = 1.0, step: float = 0.01,
                name: str = "chain") -> Path:
    """An n-mass chain as [system] with M, C, K in files of one format (.mtx, .npz or .mat) beside its scenario,
    a 10 N sine at 5 rad/s on the first DOF (x1); returns the scenario's path."""
    import scipy.io
    import scipy.sparse

    folder.mkdir(parents=True, exist_ok=True)
    for key, matrix in zip("MCK", chain_matrices(n)):
        path = folder / f"{name}_{key}{suffix}"
        if suffix == ".mtx":
            scipy.io.mmwrite(path, matrix, symmetry="symmetric")
        elif suffix == ".npz":
            scipy.sparse.save_npz(path, matrix)
        else:
            scipy.io.savemat(path, {key: matrix})
    scene = folder / f"{name}.toml"
    scene.write_text(f"[time]\nend = {end!r}\nstep = {step!r}\n[system]\n"
                     + "".join(f'{key} = "{name}_{key}{suffix}"\n' for key in "MCK")
                     + '[[force]]\non = "x1"\ntype = "sine"\namplitude = 10.0\nomega = 5.0\n')
    return scene


def five_point(f, values, i: int, relative: float = 1e-4) -> float:
    """d f / d values[i] by five-point central differences over a step of `relative` of values[i]."""
    import numpy as np

    values = np.asarray(values, dtype=float)
    h = relative * (abs(values[i]) or 1.0)
    at = {o: f(values + o * h * np.eye(len(values))[i]) for o in (-2, -1, 1, 2)}
    return (8 * (at[1] - at[-1]) - (at[2] - at[-2])) / (12 * h)


def force_block(kind: str, on: str = "m", **fields) -> str:
    """A [[force]] table in TOML text; lists and numbers written as TOML reads them."""
    lines = ["[[force]]", f'on = "{on}"', f'type = "{kind}"']
    for key, value in fields.items():
        lines.append(f"{key} = {value!r}" if not isinstance(value, str) else f'{key} = "{value}"')
    return "\n".join(lines) + "\n"


def replaced(doc, path, value):
    """A copy of a TOML document with the value at a path (keys and indices) replaced."""
    import copy

    doc = copy.deepcopy(doc)
    node = doc
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    return doc


@dataclass
class Ran:
    """What a run of `smd` printed, and its exit code."""

    exit_code: int
    stdout: str
    stderr: str
    output: str  # stdout and stderr as interleaved on a terminal


@pytest.fixture
def cli():
    """Run `smd ...` in-process exactly as the console script does (smdcli.cli.run), output captured."""
    from smdcli.cli import run as smd

    runner = CliRunner()

    def run(*args):
        with runner.isolation() as streams:
            code = smd([str(a) for a in args])
            sys.stdout.flush()
            sys.stderr.flush()
            texts = [s.getvalue().decode() if s is not None else "" for s in streams]
        stdout, stderr = texts[0], texts[1]
        return Ran(code, stdout, stderr, texts[2] if len(texts) > 2 else stdout + stderr)

    return run


def pytest_sessionstart(session):
    """Compile the kernels (or load them from numba's cache) once, before any test's clock or captured output.
    Tests run in a background job (`pytest &` in a script) inherit SIGINT ignored, and so would every `smd` they
    start; the tests that interrupt a child need it as a terminal's foreground job has it."""
    import signal

    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    from smdcli.solvers.integrators.compiled import KERNEL_FAMILIES, compile_side_by_side, warm

    # SMD_TEST_WARM: the families to warm (comma-separated; empty: erk alone, the rest compiled on first use), for
    # runs that time nothing, such as CI's regression runs under other CPU targets
    chosen = os.environ.get("SMD_TEST_WARM")
    families = KERNEL_FAMILIES if chosen is None else [family for family in chosen.split(",") if family]
    compile_side_by_side(families)
    warm(*families)




def pytest_configure(config):
    config.addinivalue_line("markers", "slow: a test of ten seconds or more, started first")


def pytest_collection_modifyitems(config, items):
    """The tests marked slow first, the rest in their order after them: pytest-xdist's workers then end on short
    tests together (started last, in file order, two 40-s tests held one worker 70 s while the other stood idle)."""
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)
