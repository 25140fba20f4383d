"""A family's figures: overlays, metrics and heat maps, frequency responses.

Plot functions return a Figure; only save_figure touches disk. Must not import: commands, cli."""

from __future__ import annotations

import math

import numpy as np

from smdcli.plots.common import _figure, _wrap, envelope
from smdcli.sweep.spec import parameter_label, parameter_units

# ------------------------------------------------------------------ sweeps

MAX_LEGEND = 12  # beyond this many members, a colour bar replaces the legend
QUANTITY_LABELS = {"displacement": "Displacement x [m]", "velocity": "Velocity v [m/s]",
                   "acceleration": "Acceleration a [m/s²]", "force": "Applied force F [N]"}
METRIC_LABELS = {"peak_displacement": "peak |x| [m]", "rms_displacement": "RMS x [m]",
                 "settling_time": "settling time to 2 % [s]", "peak_ground_force": "peak force to ground [N]"}
_STYLES = ("-", "-.", ":", "--")


def _member_colors(count: int):
    """A colour per member: the cycle for a legend's worth, a colour map beyond."""
    if count <= MAX_LEGEND:
        return [f"C{i % 10}" for i in range(count)], None
    from matplotlib import colormaps

    cmap = colormaps["viridis"]
    return [cmap(i / max(count - 1, 1)) for i in range(count)], cmap


def overlay_figure(family, traces: dict, dofs, quantity: str, title: str, solved: str):
    """One panel per DOF, one line per member drawn (traces: member -> (time, quantity (N, n), success)), with a
    legend (or a colour bar for many)."""
    S, n = len(family), len(dofs)
    colors, cmap = _member_colors(S)
    height = 2.2 + 2.6 * n
    # Right of the panels (6.3 in wide): the colour bar in 1.26 in, or the legend as wide as its longest label
    # (8 pt text, ~0.6 em a character, at least 1.8 in), so that no label is cut at the figure's edge.
    longest = max((len(family.labels[s]) for s in traces), default=0)
    legend = 1.26 if cmap is not None else max(1.8, 0.45 + 0.6 * 8 / 72 * longest)
    width = 0.9 + 6.3 + legend
    fig = _figure(figsize=(width, height))
    axes = np.atleast_1d(fig.subplots(n, 1, sharex=True, squeeze=False)[:, 0])
    fig.subplots_adjust(left=0.9 / width, right=1 - legend / width, top=1 - 0.75 / height, bottom=0.55 / height,
                        hspace=0.12)
    drawn = sorted(traces)
    # Two parameters under a colour map: colour is the first; the second, where it takes few values, the line style
    second = family.values[:, 1] if cmap is not None and family.values.shape[1] == 2 else None
    levels = sorted(set(second.tolist())) if second is not None else []
    styled = 0 < len(levels) <= len(_STYLES)
    for j, ax in enumerate(axes):
        for s in drawn:
            t, data, success = traces[s]
            ok = np.isfinite(t)
            style = _STYLES[s % len(_STYLES)] if cmap is None else \
                _STYLES[levels.index(second[s])] if styled else "-"
            ax.plot(*envelope(t[ok], data[ok, j]), style, lw=1.4 if cmap is None else 0.8, color=colors[s],
                    label=family.labels[s])
            if not success:
                ax.plot(t[ok][-1], data[ok, j][-1], "x", color=colors[s], ms=8)
        ax.set_ylabel(f"{dofs[j]}: {QUANTITY_LABELS[quantity]}", fontsize=9)
        ax.grid(True, alpha=0.4)
    axes[-1].set_xlabel("Time t [s]")
    if cmap is None:
        axes[0].legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    else:
        _colorbar(fig, axes, cmap, family)
        if styled:
            from matplotlib.lines import Line2D

            name = family.spec.parameters[1]
            keys = [Line2D([], [], ls=style, color="0.3", lw=1.0) for style in _STYLES[:len(levels)]]
            units = parameter_units(name, family.scenario)
            axes[0].legend(keys, [f"{name} = {level:g} {units}".strip() for level in levels], loc="upper right",
                           fontsize=7, framealpha=0.85, title="line style", title_fontsize=7)
        elif second is not None:
            solved += f"; colour: {family.spec.parameters[0]} ({family.spec.parameters[1]}, {len(levels)} values, " \
                      "is not told apart: see the heat map)"
    shown = f" ({len(drawn)} of them drawn, evenly spaced)" if len(drawn) < S else ""
    fig.suptitle(_wrap(f"{title}\n{S} runs{shown}: {solved}", 100), fontsize=10)
    return fig


def _colorbar(fig, axes, cmap, family):
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize

    values = family.values[:, 0] if family.values.shape[1] else np.arange(len(family))
    mappable = ScalarMappable(norm=Normalize(values.min(), values.max()), cmap=cmap)
    bar = fig.colorbar(mappable, ax=list(axes), fraction=0.04, pad=0.02)
    bar.set_label(parameter_label(family.spec.parameters[0], family.scenario) if family.spec.parameters else "member")


def metric_figure(family, values: np.ndarray, metric: str, dofs, title: str):
    """A metric per DOF: against the parameter (one parameter) or as a heat map over the grid (two)."""
    n = values.shape[1]
    params = family.spec.parameters
    if len(params) == 2:
        # constrained layout: the labels of the grid's axes and colour bars get the room they take
        fig = _figure(figsize=(5.2 * min(n, 3), 4.6 * math.ceil(n / 3)), layout="constrained")
        axes = np.atleast_1d(fig.subplots(math.ceil(n / 3), min(n, 3), squeeze=False).ravel())
        a, b = family.spec.values
        for j in range(n):
            ax = axes[j]
            grid = values[:, j].reshape(len(a), len(b)).T
            mesh = ax.pcolormesh(a, b, grid, shading="nearest", cmap="viridis")
            fig.colorbar(mesh, ax=ax).set_label(METRIC_LABELS[metric])
            ax.set_xlabel(parameter_label(params[0], family.scenario))
            ax.set_ylabel(parameter_label(params[1], family.scenario))
            ax.set_title(str(dofs[j]), fontsize=9)
        for ax in axes[n:]:
            ax.set_visible(False)
    else:
        fig = _figure(figsize=(8, 5))
        ax = fig.subplots()
        fig.subplots_adjust(left=0.12, right=0.95, top=0.86, bottom=0.12)
        x = family.values[:, 0] if params else np.arange(len(family))
        order = np.argsort(x, kind="stable")
        finite = values[np.isfinite(values)]
        top = finite.max() * 1.05 if finite.size else 1.0
        for j in range(n):
            ax.plot(x[order], values[order, j], "o-", ms=4, lw=1.2, label=str(dofs[j]), color=f"C{j}")
            missing = ~np.isfinite(values[:, j])
            if missing.any():
                ax.plot(x[missing], np.full(missing.sum(), top), "x", ms=8, mew=2, color=f"C{j}")
        if (~np.isfinite(values)).any():  # its own legend entry: not a value, a verdict
            ax.plot([], [], "x", ms=8, mew=2, color="0.3",
                    label="not settled by the end of the run" if metric == "settling_time" else "no value")
        ax.set_xlabel(parameter_label(params[0], family.scenario) if params else "member")
        ax.set_ylabel(METRIC_LABELS[metric])
        ax.grid(True, alpha=0.4)
        ax.legend(fontsize=8, loc="best")
    fig.suptitle(f"{title}\n{METRIC_LABELS[metric]} of every run", fontsize=10)
    return fig


def frequency_figure(family, response, title: str, unit: str = "rad/s", normalized: bool = False):
    """Amplitude (log) and phase lag against frequency: one line per member and DOF, resonance peaks marked.

    Normalized (1-DOF): X K / F0 and theta against r = omega / omega_n, as the book's Figures 9-9 and 9-10.
    Measured responses (nonlinear, or on request) are drawn as markers, up sweeps and down sweeps apart.
    """
    S, F, n = response.amplitude.shape
    colors, cmap = _member_colors(S * n if S == 1 else S)
    fig = _figure(figsize=(9.5, 8))
    ax_a, ax_p = fig.subplots(2, 1, sharex=True)
    fig.subplots_adjust(left=0.1, right=0.95 if cmap is None else 0.86, top=0.88, bottom=0.08, hspace=0.08)
    k = family.K[:, 0, 0] if normalized and not response.ground else np.ones(S)  # amplitude scale: X K / F0, or m/N
    # the x axis per member: r = omega / omega_n, or the frequency in the unit it was given in
    per = np.sqrt(family.K[:, 0, 0] / family.M[:, 0, 0]) if normalized else \
        np.full(S, 2 * math.pi if unit == "Hz" else 1.0)
    markers = {"up": "^", "down": "v"}
    # A measured response's two sweeps in colours of their own, so the branches of a jump tell apart.
    direction_colors = {"up": "tab:red", "down": "tab:blue"}
    for s in range(S):
        for j in range(n):
            color = colors[s] if S > 1 else colors[j]
            label = family.labels[s] if n == 1 else (f"{response.dofs[j]}" if S == 1 else f"{family.labels[s]}: {response.dofs[j]}")
            style = _STYLES[(s if S > 1 else j) % len(_STYLES)] if cmap is None else "-"
            x = response.omega / per[s]
            if response.exact:
                with np.errstate(all="ignore"):
                    ax_a.plot(x, response.amplitude[s, :, j] * k[s], style, color=color, lw=1.4, label=label)
                    ax_p.plot(x, response.phase[s, :, j], style, color=color, lw=1.4)
            for direction, (amp, lag) in response.measured.items():
                if response.exact:  # markers over the exact lines, labelled once
                    tag = f"simulated, sweep {direction}" if s == 0 and j == 0 else None
                else:
                    tag = f"sweep {direction}" + (f": {label}" if S > 1 or n > 1 else "")
                shade = direction_colors[direction] if S * n == 1 else color
                ax_a.plot(x, amp[s, :, j] * k[s], markers[direction], color=shade, ms=4, mfc="none",
                          ls="-" if not response.exact else "none", lw=0.8, label=tag)
                ax_p.plot(x, lag[s, :, j], markers[direction], color=shade, ms=4, mfc="none",
                          ls="-" if not response.exact else "none", lw=0.8)
    if response.ground:  # the force through the support, one dashed line per member
        for s in range(S):
            with np.errstate(all="ignore"):
                ax_a.plot(response.omega / per[s], response.force_transmissibility[s], "--",
                          color=colors[s] if S > 1 else "0.35", lw=0.9, alpha=0.75,
                          label="force |F_T| / (k_g U)" if s == 0 else None)
        ax_a.axhline(1.0, color="0.6", lw=0.8)
    exact_peaks = [p for p in response.peaks if "direction" not in p]  # measured maxima are listed, not marked
    for peak in exact_peaks:
        s = peak["member"]
        w = peak["omega"] / per[s]
        if math.isfinite(peak["amplitude"]):
            ax_a.plot(w, peak["amplitude"] * k[s], "o", color="k", ms=5, mfc="none")
        else:
            ax_a.axvline(w, color="0.5", ls=":", lw=1)
    if any(math.isfinite(p["amplitude"]) for p in exact_peaks):
        ax_a.plot([], [], "o", color="k", mfc="none", label="resonance peak")
    if any(not math.isfinite(p["amplitude"]) for p in exact_peaks):
        ax_a.plot([], [], ":", color="0.5", label="undamped: unbounded")
    ax_a.set_yscale("log")
    if normalized:
        ax_a.set_ylabel("Transmissibility |X / U| [1]" if response.ground else "Normalized amplitude X K / F₀ [1]")
        ax_p.set_xlabel("Frequency ratio r = ω / ωₙ [1]")
    else:
        ax_a.set_ylabel("Transmissibility |X / U| [1]" if response.ground else
                        f"Amplitude per unit force on {response.input_dof} [m/N]")
        ax_p.set_xlabel(f"{'Ground' if response.ground else 'Forcing'} frequency {'f' if unit == 'Hz' else 'ω'} "
                        f"[{unit}]")
    finite = response.amplitude[np.isfinite(response.amplitude) & (response.amplitude > 0)]
    measured = [a[np.isfinite(a) & (a > 0)] for a, _ in response.measured.values()]
    pool = np.concatenate([finite] + measured) * k.max()
    if pool.size:
        ax_a.set_ylim(max(pool.min() / 2, pool.max() * 1e-6), pool.max() * 2)
    ax_p.set_ylabel("Phase lag θ [rad]")
    every_phase = np.concatenate([np.ravel(response.phase)] + [np.ravel(p) for _, p in response.measured.values()])
    finite_phase = every_phase[np.isfinite(every_phase)]
    low = min(0.0, float(finite_phase.min(initial=0.0)))
    high = max(math.pi, float(finite_phase.max(initial=0.0)))  # a lag of n DOFs reaches n pi: every one labelled
    steps = range(math.floor(low / (math.pi / 2) + 1e-9), math.ceil(high / (math.pi / 2) - 1e-9) + 1)
    ax_p.set_yticks([i * math.pi / 2 for i in steps])
    ax_p.set_yticklabels([_half_pi(i) for i in steps])
    for ax in (ax_a, ax_p):
        ax.grid(True, which="both", alpha=0.35)
    if cmap is None:
        ax_a.legend(loc="upper right", fontsize=8, framealpha=0.85)
    else:
        _colorbar(fig, [ax_a, ax_p], cmap, family)
    kind = ("exact transmissibility under harmonic ground displacement" if response.ground else
            "exact receptance (K - ω²M + iωC)⁻¹" if response.exact else "measured by simulation to steady state")
    extra = f"; measured vs exact: {response.difference:.1e} of the peak" if response.difference is not None else ""
    fig.suptitle(f"{title}\nfrequency response, {kind}{extra}", fontsize=10)
    return fig


def _half_pi(i: int) -> str:
    """i pi / 2 written as a reader writes it: 0, π/2, π, 3π/2, 2π, -π/2 ..."""
    if i == 0:
        return "0"
    sign = "-" if i < 0 else ""
    i = abs(i)
    if i % 2 == 0:
        return f"{sign}{'' if i == 2 else i // 2}π"
    return f"{sign}{'' if i == 1 else i}π/2"
