"""The normalized sensitivities p dx/dp of each DOF over time, one line per parameter.

Plot functions return a Figure; only save_figure touches disk. Must not import: commands, cli."""

from __future__ import annotations

import numpy as np

from smdcli.plots.common import _figure, envelope, legend_beside

MAX_PANELS = 6  # DOFs drawn, one panel each (beyond, those of the largest sensitivities)


def _panels(s) -> tuple[np.ndarray, str]:
    """The DOFs drawn, in their order, and a note for the title: every one up to MAX_PANELS, else those whose
    largest |p dx/dp| is largest (evenly spaced DOFs of a long chain are mostly masses the motion never reached:
    flat panels of rounding)."""
    n = len(s.dof)
    if n <= MAX_PANELS:
        return np.arange(n), ""
    scales = np.where(np.asarray(s.value) != 0, np.abs(s.value), 1.0)
    largest = np.nan_to_num(np.abs(s.d_displacement).max(axis=1) * scales[:, None]).max(axis=0)  # (n,)
    picked = np.sort(np.argsort(-largest, kind="stable")[:MAX_PANELS])
    return picked, (f"\n({len(picked)} of {n} DOFs drawn: those of the largest sensitivities; the HDF5 file holds "
                    "every one)")


def sensitivity_figure(s):
    """One panel per DOF: p dx/dp (m) of each parameter against time, the DOF's own x faint behind."""
    picked, note = _panels(s)
    fig = _figure(figsize=(9.0, 1.0 + 2.0 * len(picked)))
    axes = np.atleast_1d(fig.subplots(len(picked), 1, sharex=True))
    for ax, i in zip(axes, picked):
        ax.plot(*envelope(s.time, s.displacement[:, i]), color="0.8", lw=1.0, label="x (nominal)")
        for p, path in enumerate(s.parameter):
            scale = s.value[p] if s.value[p] != 0 else 1.0
            label = f"{path} (p = {s.value[p]:.4g})" if s.value[p] != 0 else f"{path} (per unit, p = 0)"
            undefined = np.isnan(s.d_displacement[p, :, i])
            if undefined.any():  # nan, no line: the notes say why
                label += ": no derivative" if undefined.all() else \
                    f": no derivative from {s.time[np.argmax(undefined)]:.4g} s"
            ax.plot(*envelope(s.time, scale * s.d_displacement[p, :, i]), lw=1.2, color=f"C{p % 10}", label=label)
        ax.set_ylabel(f"{s.dof[i]}\np dx/dp [m]")
        ax.grid(True, alpha=0.3)
    axes[-1].set_xlabel("Time [s]")
    fig.suptitle(f"Sensitivities of {s.scenario.rsplit('/', 1)[-1]}: p dx/dp (the change of x per 100 % of p)"
                 + note, fontsize=10)
    height = 1.0 + 2.0 * len(picked)  # inches: half an inch above for the title (its note a line more), 0.45 below
    fig.subplots_adjust(left=0.12, top=1 - (0.7 if note else 0.5) / height, bottom=0.45 / height, hspace=0.15)
    legend_beside(fig, axes[0], fontsize=8)
    return fig
