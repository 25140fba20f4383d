"""A response-spectrum analysis: the mode shapes with their effective mass ratios, and the peak displacement of
each DOF by each combination rule.

Plot functions return a Figure; only save_figure touches disk. Must not import: commands, cli."""

from __future__ import annotations

import numpy as np

from smdcli.plots.common import _figure

SHOWN_MODES = 6


def rsa_figure(run):
    """Mode shapes (normalised to a largest entry of 1) beside the combined peak displacements per DOF."""
    from smdcli.analysis.rsa import COMBINATIONS

    a, m = run.analysis, run.analysis.modes
    fig = _figure(figsize=(10.0, 5.6), layout="constrained")
    shapes_ax, peaks_ax = fig.subplots(1, 2)
    level = np.arange(1, len(run.dofs) + 1)
    for i in range(min(SHOWN_MODES, len(m.period))):
        shape = m.shapes[:, i] / np.abs(m.shapes[:, i]).max()
        ratio = m.effective_mass[i] / m.total_mass
        shapes_ax.plot(np.concatenate([[0.0], shape]), np.concatenate([[0], level]), marker="o", ms=4,
                       label=f"mode {i + 1}: T = {m.period[i]:.3g} s, {ratio:.1%} of mass")
    shapes_ax.axvline(0.0, color="0.5", lw=0.6)
    shapes_ax.set_yticks(np.concatenate([[0], level]), ["ground", *run.dofs])
    shapes_ax.set_xlabel("Mode shape (largest entry 1)")
    shapes_ax.set_title("Modes", fontsize=10)
    fig.legend(*shapes_ax.get_legend_handles_labels(), fontsize=8, loc="outside lower center", ncol=3)
    chosen = a.combined(run.combination)["displacement"]
    top = float(np.abs(chosen).max()) or 1.0
    for j, rule in enumerate(COMBINATIONS):
        peaks = a.combined(rule)["displacement"]
        y = np.concatenate([[0], level])
        if rule == run.combination:  # on top, solid: a rule that lies on it cannot hide it
            peaks_ax.plot(np.concatenate([[0.0], peaks]), y, marker="os^"[j], ms=5, lw=2.2, zorder=4,
                          color=f"C{j}", label=f"{rule.upper()} (chosen)")
        else:  # beneath, open markers, saying how far from the chosen it is
            apart = float(np.abs(peaks - chosen).max()) / top
            peaks_ax.plot(np.concatenate([[0.0], peaks]), y, marker="os^"[j], ms=8, lw=1.0, zorder=3,
                          color=f"C{j}", mfc="none", mew=1.2, ls="--",
                          label=f"{rule.upper()} ({apart:.1%} from {run.combination.upper()} at most)")
    peaks_ax.set_yticks(np.concatenate([[0], level]), ["ground", *run.dofs])
    peaks_ax.set_xlabel("Peak displacement relative to the ground [m]")
    peaks_ax.set_title(f"Combined peaks, {a.used} modes", fontsize=10)
    peaks_ax.legend(fontsize=8, loc="lower right")
    for ax in (shapes_ax, peaks_ax):
        ax.grid(True, alpha=0.35)
    fig.suptitle(f"Response-spectrum analysis of {run.scenario.rsplit('/', 1)[-1]} under "
                 f"{run.source.path.rsplit('/', 1)[-1]}", fontsize=11)
    return fig
