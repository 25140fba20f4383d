"""Time a whole smd command as a user runs it: median, fastest and slowest wall time of a few runs, and the peak
memory of the slowest-memory run, after one untimed run (unless --repeats 1). `{out}` in the command is a fresh temporary folder for each run; `{chain}` a
scenario of an n-mass chain written for the run (`--chain n`, see chain()).

    python benchmarks/wall.py [--repeats 3] -- smd sweep scenarios/x.toml --no-plots -o {out}
    python benchmarks/wall.py --chain 1000 --damper end -- smd simulate {chain} --no-plots -o {out}
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time


def chain(n: int, cubic: bool, damper: str) -> str:
    """An n-mass chain fixed at one end (1 kg, 100 N/m each), 10 s on 1,001 points, a harmonic force on the first
    mass; the first spring cubic with `cubic`; a 0.5 N s/m damper on every spring (`every`, classical damping) or
    at the free end only (`end`)."""
    lines = ["[time]", "end = 10.0", "step = 0.01"]
    for i in range(n):
        lines += ["[[mass]]", f'name = "m{i}"', "m = 1.0"]
    for i in range(n):
        left = "ground" if i == 0 else f"m{i - 1}"
        lines += ["[[spring]]", f'connects = ["{left}", "m{i}"]', "k = 100.0"]
        if i == 0 and cubic:
            lines += ['law = "cubic"', "k3 = 1000.0"]
        if damper == "every" or (damper == "end" and i == n - 1):
            lines += ["[[damper]]", f'connects = ["{left}", "m{i}"]', "c = 0.5"]
    lines += ["[[force]]", 'on = "m0"', 'type = "sine"', "amplitude = 10.0", "omega = 5.0"]
    return "\n".join(lines) + "\n"


def chain_files(n: int, damper: str, folder: str) -> str:
    """The same chain as [system] with its M, C and K in Matrix Market files beside the scenario (as a finite-element
    program would write them, docs/scenario.md#matrices-from-files): the scenario's text."""
    import numpy as np
    import scipy.io
    from scipy.sparse import diags

    def links(value, every):
        weights = np.full(n, value) if every else np.eye(1, n, n - 1).ravel() * value  # link i: mass i-1 to i
        main = weights + np.append(weights[1:], 0.0)
        return diags([main, -weights[1:], -weights[1:]], [0, 1, -1]).tocoo()
    for key, matrix in (("M", diags(np.ones(n)).tocoo()), ("K", links(100.0, True)),
                        ("C", links(0.5, damper == "every"))):
        scipy.io.mmwrite(os.path.join(folder, f"chain_{key}.mtx"), matrix, symmetry="symmetric")
    return ("[time]\nend = 10.0\nstep = 0.01\n[system]\n" + "".join(f'{key} = "chain_{key}.mtx"\n' for key in "MCK")
            + '[[force]]\non = "x1"\ntype = "sine"\namplitude = 10.0\nomega = 5.0\n')


def as_user(command: list[str]) -> tuple[list[str], dict[str, str]]:
    """(command, environment) as a user's machine runs it: `smd` as this Python's smdcli, with Python's bytecode
    cache (a PYTHONDONTWRITEBYTECODE=1 shell recompiles smd's 70 modules on every start, 0.12 s, where numpy's and
    h5py's came compiled by pip)."""
    if command[0] == "smd":
        command = [sys.executable, "-m", "smdcli", *command[1:]]
    return command, {key: value for key, value in os.environ.items() if key != "PYTHONDONTWRITEBYTECODE"}


def run_once(words: list[str], scene) -> tuple[float, float]:
    """(wall seconds, peak resident MB) of one run; exits with the command's code where it fails. scene: the chain's
    text, or (n, damper) for the chain in matrix files (written untimed)."""
    with tempfile.TemporaryDirectory() as out:
        command = [w.replace("{out}", out) for w in words]
        if scene is not None:
            path = os.path.join(out, "chain.toml")
            with open(path, "w") as f:
                f.write(chain_files(*scene, out) if isinstance(scene, tuple) else scene)
            command = [w.replace("{chain}", path) for w in command]
        command, env = as_user(command)
        start = time.perf_counter()
        child = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env)
        _, status, usage = os.wait4(child.pid, 0)
        seconds = time.perf_counter() - start
        code = os.waitstatus_to_exitcode(status)
        if code != 0:
            sys.exit(f"{' '.join(command)} exited {code}: {child.stderr.read().decode()[-400:]}")
        return seconds, usage.ru_maxrss / 1024


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--chain", type=int, default=0, help="write an n-mass chain for {chain}")
    parser.add_argument("--cubic", action="store_true", help="the chain's first spring cubic")
    parser.add_argument("--damper", choices=["every", "end"], default="every", help="the chain's dampers")
    parser.add_argument("--files", action="store_true", help="the chain as [system] M, C, K in .mtx files")
    parser.add_argument("command", nargs="+")
    args = parser.parse_args()
    if args.files and args.cubic:
        sys.exit("--files writes the linear chain's matrices; a cubic spring needs [[spring]] tables")
    scene = ((args.chain, args.damper) if args.files else chain(args.chain, args.cubic, args.damper)) if args.chain \
        else None
    if args.repeats > 1:  # a first run untimed: kernels compiled into numba's cache, files in the page cache
        run_once(args.command, scene)
    runs = [run_once(args.command, scene) for _ in range(args.repeats)]
    walls = [w for w, _ in runs]
    print(f"wall {statistics.median(walls):.2f} s median of {args.repeats} (fastest {min(walls):.2f} s, slowest "
          f"{max(walls):.2f} s), peak memory {max(m for _, m in runs):.0f} MB")


if __name__ == "__main__":
    main()
