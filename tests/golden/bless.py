"""Regenerate the golden outputs after an intended change: python tests/golden/bless.py [STEM ...]

For every bundled scenario (or the stems named) this runs `smd simulate` exactly as a
user would (the scenario's own method and tolerances) and stores the result here as
<stem>.h5, every STRIDE-th output time kept so that the file stays small while the
kept times still span the whole run. Scenarios with a time-domain or linear frequency
[sweep] table also get sweep/<stem>.h5 from `smd sweep`. Then run
`python -m pytest tests/test_golden.py`: it checks each new golden against an
independent reference, so a golden cannot enshrine a bug. Commit the .h5 files.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import h5py
import numpy as np

ROOT = Path(__file__).resolve().parents[2]
GOLDEN = Path(__file__).resolve().parent
SCENARIOS = ROOT / "scenarios"
MAX_KEPT = 1001  # output times kept per golden
SKIP_SWEEPS = {"duffing_frequency_response"}  # measured by simulation: ~10 s; its scene is golden through simulate


def stride_for(n_times: int) -> int:
    """Keep every stride-th time so that at most MAX_KEPT remain (first and last kept when they fall on it)."""
    return max(1, -(-(n_times - 1) // (MAX_KEPT - 1)))


def downsample(src: Path, dst: Path, stride: int) -> None:
    """Copy an smd file, keeping every stride-th sample along the time axis of every time-indexed data set."""
    with h5py.File(src, "r") as fin, h5py.File(dst, "w") as fout:
        for key, value in fin.attrs.items():
            fout.attrs[key] = value
        fout.attrs["golden_stride"] = stride

        def copy(name, obj):
            if isinstance(obj, h5py.Group):
                group = fout.require_group(name)
                for key, value in obj.attrs.items():
                    group.attrs[key] = value
                return
            data = obj[()]
            axis = next((i for i, dim in enumerate(obj.dims) if len(dim) and dim[0].name == "/time"), None)
            if name == "time":
                axis = obj.ndim - 1
            if axis is not None and stride > 1:
                data = np.take(data, np.arange(0, data.shape[axis], stride), axis=axis)
            ds = fout.create_dataset(name, data=data)
            for key, value in obj.attrs.items():
                if key not in ("DIMENSION_LIST", "REFERENCE_LIST", "CLASS", "NAME"):
                    ds.attrs[key] = value

        fin.visititems(copy)
        # Dimension scales again, by name, so a diff can say where a difference is.
        scales = [n for n in ("member", "time", "dof", "frequency") if n in fout and fout[n].ndim == 1]
        for n in scales:
            fout[n].make_scale(n)

        def attach(name, obj):
            if isinstance(obj, h5py.Dataset) and name not in scales:
                for axis, dim in enumerate(fin[name].dims):
                    if len(dim) and dim[0].name.lstrip("/") in scales:
                        obj.dims[axis].attach_scale(fout[dim[0].name.lstrip("/")])

        fout.visititems(attach)


def golden_names() -> list[str]:
    """Stems of every bundled scenario."""
    return sorted(p.stem for p in SCENARIOS.glob("*.toml"))


def sweeps() -> list[str]:
    """Stems of bundled scenarios whose [sweep] table gets a golden of its own."""
    from smdcli import scenario

    return [s for s in golden_names() if scenario.load(SCENARIOS / f"{s}.toml").sweep and s not in SKIP_SWEEPS]


def regenerate(stem: str, out: Path, kind: str = "simulate") -> Path:
    """Run the scenario through the command a user runs; the full-resolution file's path."""
    from typer.testing import CliRunner

    from smdcli.cli import app

    args = [kind, str(SCENARIOS / f"{stem}.toml"), "-o", str(out), "--no-plots", "--quiet"]
    result = CliRunner().invoke(app, args)
    if result.exit_code != 0:
        raise SystemExit(f"{kind} {stem} failed: {result.output}")
    return out / (f"{stem}.h5" if kind == "simulate" else f"{stem}_sweep.h5")


def golden_path(stem: str, kind: str) -> Path:
    """Where the golden of a scenario's simulate (or sweep) output lives."""
    return GOLDEN / f"{stem}.h5" if kind == "simulate" else GOLDEN / "sweep" / f"{stem}.h5"


def bless(stems: list[str]) -> None:
    """Write the goldens of the given scenarios."""
    sweep_stems = set(sweeps())
    with tempfile.TemporaryDirectory() as tmp:
        for stem in stems:
            for kind in ("simulate", "sweep") if stem in sweep_stems else ("simulate",):
                full = regenerate(stem, Path(tmp), kind)
                with h5py.File(full, "r") as f:
                    n_times = f["time"].shape[-1] if "time" in f else 1
                target = golden_path(stem, kind)
                target.parent.mkdir(exist_ok=True)
                downsample(full, target, stride_for(n_times))
                print(f"blessed {target.relative_to(ROOT)} ({target.stat().st_size / 1024:.0f} kB)")


if __name__ == "__main__":
    bless(sys.argv[1:] or golden_names())
