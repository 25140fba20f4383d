"""Random vibration: the input PSD and the response acceleration PSD of each DOF (log-log), with RMS values.

Plot functions return a Figure; only save_figure touches disk. Must not import: commands, cli."""

from __future__ import annotations

import numpy as np

from smdcli.plots.common import _figure
from smdcli.scenario.spec import STANDARD_GRAVITY as G

SHOWN = 8  # DOFs drawn (the first ones)


def psd_figure(run):
    """Acceleration PSDs (g^2/Hz for a support input) above, displacement PSDs beneath."""
    fig = _figure(figsize=(8.0, 8.0), layout="constrained")
    top, bottom = fig.subplots(2, 1, sharex=True)
    groups = np.array(run.groups)
    scale = G**2 if run.support else 1.0
    unit = "g" if run.support else "m/s^2"
    if run.support:
        top.plot(run.frequency, run.input_psd / scale, color="0.3", lw=1.0, ls="--", label="input (support)")
    accel = np.flatnonzero(groups == "acceleration")[:SHOWN]
    displacement = np.flatnonzero(groups == "displacement")[:SHOWN]
    for i, (a, d) in enumerate(zip(accel, displacement)):
        color = f"C{i % 10}"
        top.plot(run.frequency, run.response_psd[:, a] / scale, color=color, lw=1.3,
                 label=f"{run.names[a]}: {run.rms[a] / (G if run.support else 1.0):.3g} {unit} RMS")
        bottom.plot(run.frequency, run.response_psd[:, d], color=color, lw=1.3,
                    label=f"{run.names[d]}: {run.rms[d]:.3g} m RMS")
    top.set_ylabel(f"Acceleration PSD [{unit}²/Hz]" + (" (absolute)" if run.support else ""))
    bottom.set_ylabel("Displacement PSD [m²/Hz]")
    bottom.set_xlabel("Frequency [Hz]")
    for ax in (top, bottom):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8, loc="lower left")
        positive = [line.get_ydata() for line in ax.get_lines()]
        values = np.concatenate([v[v > 0] for v in positive]) if positive else np.array([1.0])
        ax.set_ylim(max(values.min(), values.max() * 1e-12), values.max() * 3)
    what = "support acceleration" if run.support else f"force on {run.on}"
    fig.suptitle(f"Random vibration of {run.scenario.rsplit('/', 1)[-1]}: {what}" +
                 (" (white noise)" if run.white is not None else ""), fontsize=11)
    return fig
