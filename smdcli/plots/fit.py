"""Each fitted channel, measured against the model at the estimate, its residual beneath.

Plot functions return a Figure; only save_figure touches disk. Must not import: commands, cli."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from smdcli.plots.common import _figure, _wrap, envelope
from smdcli.analysis.fit_data import SI_UNITS, quantity_of

MAX_CHANNELS = 8  # panels drawn (the first ones); the file holds every channel


def fit_figure(run):
    """Two rows per channel: measured (grey) and fitted (colour) over time, then their difference."""
    channels = [(test, fitted, c) for test, fitted in zip(run.tests, run.fitted) for c in test.channels]
    shown = channels[:MAX_CHANNELS]
    fig = _figure(figsize=(9.0, 1.2 + 2.6 * len(shown)))
    axes = np.atleast_1d(fig.subplots(2 * len(shown), 1, sharex=False,
                                      gridspec_kw={"height_ratios": [3, 1] * len(shown)}))
    several = len(run.tests) > 1
    for k, (test, fitted, channel) in enumerate(shown):
        top, bottom = axes[2 * k], axes[2 * k + 1]
        t = test.measured.time
        unit = SI_UNITS[quantity_of(channel)]
        name = f"{Path(test.scenario.path).stem}: {channel}" if several else channel
        # the measured line wide and pale beneath the fitted one: where they agree it shows as its halo
        top.plot(*envelope(t, test.measured.channels[channel]), color="0.7", lw=3.0, label="measured")
        top.plot(*envelope(t, fitted[channel]), color=f"C{k % 10}", lw=0.8, label="fitted")
        top.set_ylabel(f"{name}\n[{unit}]", fontsize=8)
        if k == 0:  # above the first panel, over no line (a dense record leaves no corner free): grey measured,
            # the channel's colour fitted, in every panel
            top.legend(fontsize=8, loc="lower right", bbox_to_anchor=(1.0, 1.0), ncol=2, frameon=False,
                       borderaxespad=0.1)
        residual = fitted[channel] - test.measured.channels[channel]
        bottom.plot(*envelope(t, residual), color="C3", lw=0.8)
        bottom.set_ylabel("residual", fontsize=8)
        for ax in (top, bottom):
            ax.grid(True, alpha=0.3)
            ax.tick_params(labelsize=8)
    axes[-1].set_xlabel("Time [s]")
    estimates = ", ".join(f"{p} = {v:.5g}" for p, v in zip(run.parameter[:4], run.estimate[:4]))
    more = f" (+{len(run.parameter) - 4} more)" if len(run.parameter) > 4 else ""
    fig.suptitle(_wrap(f"Fit: {estimates}{more}; RMS weighted residual {run.rms_residual:.3g}"
                       + ("" if run.converged else " (NOT CONVERGED)")
                       + (f" (leaves {100 * run.unexplained:.0f} % of the data unexplained)" if run.warning else ""),
                       100), fontsize=10)
    height = 1.2 + 2.6 * len(shown)
    fig.subplots_adjust(left=0.14, right=0.97, top=1 - 0.7 / height, bottom=0.5 / height, hspace=0.35)
    return fig
