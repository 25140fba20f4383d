"""Benchmark (on demand, not in CI): the linear chains of 1,000 and 10,000 masses as whole processes, interleaved in
one script so that the machine's noise falls on both alike: `smd simulate --no-plots` of the chain from `[[mass]]`
tables and from Matrix Market files (wall.chain, wall.chain_files) against OpenSees run as an expert would (a
script of its own: the model built, Newmark average acceleration on the banded SPD system factored once, a binary
node recorder of every mass read back by numpy). Median wall times, peak memory, ratios, and each one's error: the
first mass's displacement against the dense state transition of the 1,000-mass chain (peers.dense_chain_reference),
over its peak; over these 10 s the 10,000-mass chain's first mass moves as the 1,000's to rounding.

    python benchmarks/chain_vs_opensees.py [--repeats 5] [--masses 1000 10000]

Needs openseespy (`pip install -e '.[peers]'`).
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

import wall

DT, STEPS = 0.01, 1000  # wall.chain's grid: 0..10 s on 1,001 points

# the chain as OpenSees builds it (n masses of 1 kg, k = 100 N/m and c = 0.5 N s/m on every link, 10 sin 5t on the
# first): shared with peers.py's in-process timing
CHAIN_MODEL = """ops.model("basic", "-ndm", 1, "-ndf", 1)
for i in range(n + 1):
    ops.node(i, 0.0)
ops.fix(0, 1)
for i in range(1, n + 1):
    ops.mass(i, 1.0)
ops.uniaxialMaterial("Elastic", 1, 100.0, 0.5)  # spring k and damper c on every link
for i in range(1, n + 1):
    ops.element("zeroLength", i, i - 1, i, "-mat", 1, "-dir", 1)
ops.timeSeries("Trig", 1, 0.0, 1e9, 2 * np.pi / 5.0, "-factor", 10.0)
ops.pattern("Plain", 1, 1)
ops.load(1, 1.0)
"""

OPENSEES = f"""
import sys
import numpy as np
import openseespy.opensees as ops
n, out = int(sys.argv[1]), sys.argv[2]
dt, steps = {DT}, {STEPS}
{CHAIN_MODEL}ops.constraints("Plain"); ops.numberer("RCM"); ops.system("BandSPD")
ops.algorithm("Linear", "-factorOnce"); ops.integrator("Newmark", 0.5, 0.25); ops.analysis("Transient")
ops.recorder("Node", "-binary", out, "-time", "-node", *range(1, n + 1), "-dof", 1, "disp")
ops.analyze(steps, dt)
ops.remove("recorders")
ops.wipe()
# a record: the time and every mass's displacement as doubles, then a newline byte
records = np.fromfile(out, dtype=np.uint8).reshape(steps, 8 * (n + 1) + 1)
x = records[:, :-1].copy().view("<f8")
np.save(out + ".npy", np.concatenate([[0.0], x[:, 1]]))  # the first mass, from t = 0
"""


def timed(command: list[str], env: dict) -> tuple[float, float]:
    """(wall seconds, peak resident MB) of a whole process, started by a small process of its own (peers.MEASURER:
    a child's peak memory counts that of the process it was started from, and this one holds the reference's
    matrices); exits where it fails."""
    from peers import MEASURER

    done = subprocess.run([sys.executable, "-c", MEASURER, *command], capture_output=True, text=True, env=env)
    seconds, megabytes, code = done.stdout.split()
    if int(code) != 0:
        sys.exit(f"{' '.join(command)} failed (exit {code})")
    return float(seconds), float(megabytes)


def reference_first_mass(folder: Path) -> np.ndarray:
    """The 1,000-mass chain's first mass on the grid, by the dense state transition (peers.py's reference)."""
    from peers import dense_chain_reference

    from smdcli import scenario
    from smdcli.model import build, time_grid

    path = folder / "reference.toml"
    path.write_text(wall.chain(1000, False, "every"))
    sc = scenario.load(path)
    return dense_chain_reference(build(sc), time_grid(sc.time))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--masses", type=int, nargs="+", default=[1000, 10000])
    args = parser.parse_args()
    from elastoplastic_vs_opensees import opensees_env

    ops_env = opensees_env()
    if ops_env is None:
        sys.exit("openseespy is not installed: pip install -e '.[peers]'")
    ops_env.pop("PYTHONDONTWRITEBYTECODE", None)
    import h5py

    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        reference = reference_first_mass(folder)
        peak = float(np.abs(reference).max())
        script = folder / "opensees_chain.py"
        script.write_text(OPENSEES)
        print(f"{'run':<44} {'median':>9} {'peak MB':>8} {'error':>9}   ratio to OpenSees")
        for n in args.masses:
            (folder / f"tables{n}").mkdir()
            (folder / f"files{n}").mkdir()
            tables = folder / f"tables{n}" / "chain.toml"
            tables.write_text(wall.chain(n, False, "every"))
            files = folder / f"files{n}" / "chain.toml"
            files.write_text(wall.chain_files(n, "every", str(files.parent)))
            recorded = str(folder / f"opensees{n}.bin")
            runs = {f"OpenSees {n} masses (script, BandSPD, recorder)":
                    ([sys.executable, str(script), str(n), recorded], ops_env)}
            for label, scene in (("tables", tables), ("files", files)):
                command, env = wall.as_user(["smd", "simulate", str(scene), "--no-plots", "-q", "-o",
                                             str(scene.parent / "out")])
                runs[f"smd simulate {n} masses ({label})"] = (command, env)
            for command, env in runs.values():  # once untimed: caches warm, files in the page cache
                timed(command, env)
            measured: dict[str, list[tuple[float, float]]] = {name: [] for name in runs}
            for _ in range(args.repeats):
                for name, (command, env) in runs.items():
                    measured[name].append(timed(command, env))
            errors = {}
            for name in runs:
                if name.startswith("OpenSees"):
                    x = np.load(recorded + ".npy")
                else:
                    label = "tables" if "(tables)" in name else "files"
                    with h5py.File(folder / f"{label}{n}" / "out" / "chain.h5") as f:
                        x = f["displacement"][:, 0]
                errors[name] = float(np.abs(x - reference).max()) / peak
            ops_name = next(iter(runs))
            ops_s = statistics.median(w for w, _ in measured[ops_name])
            for name, values in measured.items():
                seconds = statistics.median(w for w, _ in values)
                print(f"{name:<44} {seconds:7.2f} s {max(m for _, m in values):8.0f} {errors[name]:9.1e}   "
                      f"{seconds / ops_s:5.2f}x")
    print(f"(medians of {args.repeats}, interleaved; error: the first mass against the dense state transition, over its "
          "peak; ratio below 1: smd the faster)")


if __name__ == "__main__":
    main()
