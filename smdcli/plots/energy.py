"""The energy balance of a run: where the energy went, and how far the balance is from closing.

Plot functions return a Figure; only save_figure touches disk. Must not import: commands, cli."""

from __future__ import annotations

import numpy as np

from smdcli.plots.common import _figure, _wrap, envelope
from smdcli.result import Result


def energy_figure(result: Result, title: str):
    """Kinetic, strain, dissipated and input energy against time, and |residual| over the largest energy."""
    e = result.energy
    t = result.time
    fig = _figure(figsize=(9, 6.5), layout="constrained")
    top, bottom = fig.subplots(2, 1, sharex=True, height_ratios=(2, 1))
    for name, data, style in (("kinetic", e.kinetic, "-"), ("strain", e.strain, "-"),
                              ("kinetic + strain", e.kinetic + e.strain, "-"),
                              ("dissipated (cumulative)", e.dissipated, "--"), ("input (cumulative)", e.input, "--")):
        top.plot(*envelope(t, data), style, lw=1.0, label=name)
    top.set_ylabel("energy [J]")
    top.legend(loc="best", fontsize=8)
    top.grid(alpha=0.3)
    top.set_title(_wrap(f"{title}\nenergy balance ({result.stats.method})", 90), fontsize=10)
    reached = max(float(np.max(e.kinetic + e.strain, initial=0.0)), float(np.max(np.abs(e.dissipated), initial=0.0)),
                  float(np.max(np.abs(e.input), initial=0.0)))
    relative = np.abs(e.residual) / reached if reached > 0 else np.zeros_like(e.residual)
    floor = np.finfo(float).eps  # an exact zero has no place on a log axis: drawn at machine epsilon
    bottom.semilogy(*envelope(t, np.maximum(relative, floor)), lw=1.0, color="C3")
    bottom.axhline(e.max_relative_residual, color="0.4", lw=0.8, ls=":")
    bottom.set_ylabel("|residual| / largest energy")
    bottom.set_xlabel("time [s]")
    bottom.grid(alpha=0.3, which="both")
    bottom.set_title(_wrap(f"kinetic + strain - initial + dissipated - input: at most {e.max_relative_residual:.2g} "
                           f"of the largest energy ({e.quadrature})", 110), fontsize=8)
    return fig
