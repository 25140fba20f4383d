"""A fitted fragility curve over the data it was fitted to: the empirical fraction of collapses (each stripe's, with
its runs, or the records' collapse intensities as a stepped empirical distribution), the median and its interval.

Plot functions return a Figure; only save_figure touches disk. Must not import: commands, cli."""

from __future__ import annotations

import numpy as np

from smdcli.plots.common import _figure


def fragility_figure(f, units: str, name: str):
    """P(collapse) against intensity: the lognormal fitted, the data, theta and its 95 % interval."""
    fig = _figure(figsize=(7.0, 4.6), layout="constrained")
    ax = fig.subplots()
    top = float(max(f.im.max(), f.theta_95[1]) * 1.3)
    x = np.linspace(top / 400, top, 400)
    ax.plot(x, f.probability(x), color="C0", lw=1.6,
            label=f"lognormal: theta = {f.theta:.4g}{' ' + units if units else ''}, beta = {f.beta:.3g}")
    if f.runs is None:
        ordered = np.sort(f.im)
        ax.step(ordered, np.arange(1, len(ordered) + 1) / len(ordered), where="post", color="0.3", lw=1.0,
                label=f"collapse intensities ({len(ordered)} records)")
        ax.plot(ordered, np.zeros_like(ordered), "|", color="0.3", ms=10)
    else:
        ax.scatter(f.im, f.collapses / f.runs, s=18 + 60 * f.runs / f.runs.max(), color="C1", zorder=3,
                   label="collapse fraction per stripe (size: runs)")
    ax.axvspan(*f.theta_95, color="C0", alpha=0.12, label="theta's 95 % profile-likelihood interval")
    ax.axvline(f.theta, color="C0", lw=0.8, ls="--")
    ax.set_xlim(0, top)
    ax.set_ylim(-0.03, 1.03)
    ax.set_xlabel(f"Intensity measure{' [' + units + ']' if units else ''}")
    ax.set_ylabel("P(collapse)")
    ax.grid(True, alpha=0.35)
    ax.legend(fontsize=8, loc="lower right")
    ax.set_title(f"Fragility fitted to {name} ({f.method})", fontsize=10)
    return fig
