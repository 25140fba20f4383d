"""The normalized sensitivities p dx/dp of each DOF over time, one line per parameter.

Plot functions return a Figure; only save_figure touches disk. Must not import: commands, cli."""

from __future__ import annotations

import numpy as np

from smdcli.plots.common import _figure, drawn_dofs, envelope, legend_beside

MAX_PANELS = 6  # DOFs drawn, one panel each (evenly spaced beyond)


def sensitivity_figure(s):
    """One panel per DOF: p dx/dp (m) of each parameter against time, the DOF's own x faint behind."""
    picked, note = drawn_dofs(len(s.dof))
    picked = picked[np.unique(np.linspace(0, len(picked) - 1, min(len(picked), MAX_PANELS)).round().astype(int))]
    fig = _figure(figsize=(9.0, 1.0 + 2.0 * len(picked)))
    axes = np.atleast_1d(fig.subplots(len(picked), 1, sharex=True))
    for ax, i in zip(axes, picked):
        ax.plot(*envelope(s.time, s.displacement[:, i]), color="0.8", lw=1.0, label="x (nominal)")
        for p, path in enumerate(s.parameter):
            scale = s.value[p] if s.value[p] != 0 else 1.0
            ax.plot(*envelope(s.time, scale * s.d_displacement[p, :, i]), lw=1.2, color=f"C{p % 10}",
                    label=f"{path} (p = {s.value[p]:.4g})" if s.value[p] != 0 else f"{path} (per unit, p = 0)")
        ax.set_ylabel(f"{s.dof[i]}\np dx/dp [m]")
        ax.grid(True, alpha=0.3)
    axes[-1].set_xlabel("Time [s]")
    fig.suptitle(f"Sensitivities of {s.scenario.rsplit('/', 1)[-1]}: p dx/dp (the change of x per 100 % of p)"
                 + note, fontsize=10)
    height = 1.0 + 2.0 * len(picked)  # inches: half an inch above for the title, 0.45 below for the time axis
    fig.subplots_adjust(left=0.12, top=1 - 0.5 / height, bottom=0.45 / height, hspace=0.15)
    legend_beside(fig, axes[0], fontsize=8)
    return fig
