"""IDA curves: each record's runs (IM against EDP, the standing runs joined, collapses marked) and the 16, 50 and
84 % fractile curves across records.

Plot functions return a Figure; only save_figure touches disk. Must not import: commands, cli."""

from __future__ import annotations

import numpy as np

from smdcli.plots.common import _figure


def ida_figure(run):
    """IM (vertical) against EDP (horizontal), the engineering convention of IDA curves."""
    fig = _figure(figsize=(7.5, 5.0), layout="constrained")
    ax = fig.subplots()
    for t in run.traces:
        standing = sorted((i, e) for i, e, c in zip(t.im, t.edp, t.collapse) if not c)
        im = [0.0] + [i for i, _ in standing]
        edp = [0.0] + [e for _, e in standing]
        ax.plot(edp, im, color="0.6", lw=0.8, marker=".", ms=3)
        if np.isfinite(t.collapse_im):
            ax.plot(edp[-1], t.collapse_im, "x", color="C3", ms=6)
    for q, style in (("im_16", ":"), ("im_50", "-"), ("im_84", ":")):
        values = run.fractiles[q]
        finite = np.isfinite(values)
        ax.plot(run.levels[finite], values[finite], style, color="C0", lw=1.8, label=f"{q[3:]} % fractile")
    ax.plot([], [], "x", color="C3", label="collapse intensity (at its last standing run's EDP)")
    ax.set_xlabel(f"{run.edp.text} [{run.edp.units}]")
    ax.set_ylabel(f"{run.im.text} [{run.im.units}]")
    ax.grid(True, alpha=0.35)
    ax.legend(fontsize=8, loc="lower right")
    ax.set_title(f"IDA of {len(run.traces)} records ({run.collapse.text})", fontsize=10)
    return fig
