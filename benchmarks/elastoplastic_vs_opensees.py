"""An elastoplastic and a bilinear 1-DOF through a 4,000-sample ground acceleration record: smd's exact
event-to-event solution against OpenSees' ElasticPP and Steel01 (Newmark average acceleration with Newton, at the
record's step and at 4 and 16 substeps a sample), on the same output grid. Prints time (median of repeats) and
error of each against a reference that is neither: smd's event-driven Radau at rtol 1e-11 (a different method,
events located on its interpolant). OpenSees' error falls with its step (it finds yield within a step), smd's
is at rounding.

    python benchmarks/elastoplastic_vs_opensees.py        (OpenSees runs where openseespy is installed:
                                                          pip install -e '.[peers]')

The record is made here as records/make_synthetic.py makes the shipped one (band-limited noise under an envelope,
seeded), 40 s at 100 Hz: 4,001 samples. The oscillator: m = 1000 kg, T = 0.5 s, 5 % damping, yield force a
quarter of the peak force the elastic oscillator reaches.
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "records"))

M, T_N, ZETA, G = 1000.0, 0.5, 0.05, 9.80665
REPEATS = 5


def record() -> tuple[np.ndarray, np.ndarray]:
    """40 s at 100 Hz of the synthetic record's recipe, in g."""
    import make_synthetic

    make_synthetic.DURATION_S = 40.0
    return make_synthetic.synthetic_record()


def scenario_text(csv: Path, fy: float, hardening: float = 0.0) -> str:
    w = float(2 * np.pi / T_N)
    fy = float(fy)
    law = f'"bilinear"\nhardening = {hardening!r}' if hardening else '"elastoplastic"'
    return f"""
[time]
end = 40.0
step = 0.01
[[mass]]
name = "m"
m = {M!r}
[[spring]]
connects = ["ground", "m"]
law = {law}
k = {M * w * w!r}
fy = {fy!r}
[[damper]]
connects = ["ground", "m"]
c = {2 * ZETA * M * w!r}
[ground_motion]
quantity = "acceleration"
type = "table"
file = "{csv}"
units = "g"
"""


def smd_runs(text: str, grid_check: bool = True):
    """(median seconds, x) of smd's exact run, and the reference x (event-driven Radau at rtol 1e-11)."""
    from smdcli import scenario
    from smdcli.model import build, time_grid
    from smdcli.solvers import solve
    from smdcli.solvers.base import Tolerances

    sc = scenario.parse(text, "benchmark.toml")
    model, grid = build(sc), time_grid(sc.time)
    times, result = [], None
    for _ in range(REPEATS):
        start = time.perf_counter()
        result = solve(model, grid, "exact", Tolerances())
        times.append(time.perf_counter() - start)
    reference = solve(model, grid, "Radau", Tolerances(rtol=1e-11, atol=1e-16))
    return statistics.median(times), result, reference.displacement[:, 0], grid


OPENSEES = r"""
import sys, time, json, statistics
import numpy as np
import openseespy.opensees as ops
t, a, m, k, c, fy, b, substeps, repeats = json.load(sys.stdin)
def run(sub):
    ops.wipe()
    ops.model("basic", "-ndm", 1, "-ndf", 1)
    ops.node(1, 0.0); ops.node(2, 0.0)
    ops.fix(1, 1)
    ops.mass(2, m)
    if b:
        ops.uniaxialMaterial("Steel01", 1, fy, k, b)
    else:
        ops.uniaxialMaterial("ElasticPP", 1, k, fy / k)
    ops.uniaxialMaterial("Elastic", 2, 0.0, c)
    ops.element("zeroLength", 1, 1, 2, "-mat", 1, 2, "-dir", 1, 1)
    ops.timeSeries("Path", 1, "-dt", t[1] - t[0], "-values", *a, "-factor", 9.80665)
    ops.pattern("UniformExcitation", 1, 1, "-accel", 1)
    ops.constraints("Plain"); ops.numberer("Plain"); ops.system("BandGeneral")
    ops.test("NormDispIncr", 1e-12, 50); ops.algorithm("Newton")
    ops.integrator("Newmark", 0.5, 0.25); ops.analysis("Transient")
    x = [0.0]
    for _ in range(len(t) - 1):
        ops.analyze(sub, (t[1] - t[0]) / sub)
        x.append(ops.nodeDisp(2, 1))
    return x
out = []
for sub in substeps:
    times = []
    for _ in range(repeats if sub == 1 else 1):
        start = time.perf_counter(); x = run(sub); times.append(time.perf_counter() - start)
    out.append({"substeps": sub, "seconds": statistics.median(times), "x": x})
print(json.dumps(out))
"""


SUBSTEPS = (1, 4, 16)


def opensees_env() -> dict | None:
    """The environment an OpenSees child needs (openseespy's bundled BLAS on LD_LIBRARY_PATH, as its wheel needs), or
    None where openseespy is not installed."""
    import importlib.util

    spec = importlib.util.find_spec("openseespylinux")
    env = dict(os.environ)
    if spec is not None and spec.submodule_search_locations:
        lib = Path(list(spec.submodule_search_locations)[0]) / "lib"
        env["LD_LIBRARY_PATH"] = f"{lib}:{env.get('LD_LIBRARY_PATH', '')}"
    elif importlib.util.find_spec("openseespy") is None:
        return None
    return env


def opensees(t, a, k, c, fy, b):
    """[(substeps, median seconds, x)] of OpenSees ElasticPP (b = 0) or Steel01 (hardening b), or None where
    openseespy is not installed. Run in a child with openseespy's bundled BLAS on LD_LIBRARY_PATH, as its wheel
    needs."""
    import json

    env = opensees_env()
    if env is None:
        return None
    done = subprocess.run([sys.executable, "-c", OPENSEES], input=json.dumps([list(t), list(a), M, k, c, fy, b, SUBSTEPS, REPEATS]),
                          capture_output=True, text=True, env=env)
    if done.returncode != 0:
        print(f"OpenSees did not run: {done.stderr.strip().splitlines()[-1] if done.stderr else done.returncode}")
        return None
    line = [x for x in done.stdout.splitlines() if x.startswith("[")][-1]
    return [(run["substeps"], run["seconds"], np.array(run["x"])) for run in json.loads(line)]


def main() -> None:
    from smdcli.analysis.spectrum import response_spectrum

    t, a = record()
    w = 2 * np.pi / T_N
    k, c = M * w * w, 2 * ZETA * M * w
    elastic = response_spectrum(t, a * G, np.array([T_N]), np.array([ZETA])).Sd[0, 0]
    fy = 0.25 * k * elastic
    print(f"1-DOF, T = {T_N} s, {ZETA:.0%} damping, fy = {fy:.4g} N (a quarter of the elastic peak force), "
          f"{len(t)} record samples; errors over the peak, against smd's event-driven Radau at rtol 1e-11")
    print(f"{'method':<44}{'median time':>13}{'history':>11}{'peak':>11}{'residual':>11}")
    for hardening, peer in ((0.0, "ElasticPP"), (0.1, "Steel01 b = 0.1")):
        with tempfile.TemporaryDirectory() as tmp:
            csv = Path(tmp) / "record.csv"
            csv.write_text("".join(f"{float(ti)!r},{float(ai)!r}\n" for ti, ai in zip(t, a)))
            seconds, result, reference, grid = smd_runs(scenario_text(csv, fy, hardening))
        peak = np.abs(reference).max()

        def row(name, sec, x):
            print(f"{name:<44}{sec * 1e3:>10.1f} ms{np.abs(x - reference).max() / peak:>11.2e}"
                  f"{abs(np.abs(x).max() - peak) / peak:>11.2e}{abs(x[-1] - reference[-1]) / peak:>11.2e}")

        law = "bilinear b = 0.1" if hardening else "elastoplastic"
        print(f"-- {law}: {len(result.nonsmooth.events)} events, peak {peak:.6g} m, residual {reference[-1]:.6g} m")
        row("smd exact, event to event", seconds, result.displacement[:, 0])
        found = opensees(t, a, k, c, fy, hardening)
        if found is None:
            print("OpenSees: not installed (pip install -e '.[peers]' to compare)")
            continue
        for substeps, ops_seconds, ops_x in found:
            row(f"OpenSees {peer}, Newmark dt {0.01 / substeps:.4g}", ops_seconds, ops_x)
        print(f"time ratio OpenSees (dt 0.01) / smd: {found[0][1] / seconds:.3g}")


if __name__ == "__main__":
    main()
