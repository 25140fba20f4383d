"""A response spectrum on tripartite axes: pseudo-velocity against period, log-log, with guide lines of constant
displacement and constant acceleration labelled along the frame, the record beneath.

Plot functions return a Figure; only save_figure touches disk. Must not import: commands, cli."""

from __future__ import annotations

import math

import numpy as np

from smdcli.plots.common import _figure, envelope
from smdcli.scenario.spec import STANDARD_GRAVITY as G  # guide lines of constant Sa are labelled in g, as engineers read them


def _decades(low: float, high: float) -> list[float]:
    """The powers of ten in [low, high]; where fewer than four are, 1, 2 and 5 times them (a narrow frame's guide
    lines near its curve, not only the decades beyond it)."""
    exponents = range(math.floor(math.log10(low)), math.ceil(math.log10(high)) + 1)
    values = [v for v in (10.0**e for e in exponents) if low <= v <= high]
    if len(values) < 4:
        values = [v for v in (m * 10.0**e for e in exponents for m in (1.0, 2.0, 5.0)) if low <= v <= high]
    return values


def spectrum_figure(spectrum, record, title: str):
    """Sv against T per damping ratio on tripartite axes, and the record's acceleration in g beneath."""
    fig = _figure(figsize=(8.0, 8.4))
    ax, rec = fig.subplots(2, 1, height_ratios=[3.2, 1.0])
    fig.subplots_adjust(left=0.11, right=0.97, top=0.92, bottom=0.07, hspace=0.32)
    T = spectrum.period
    Sv = spectrum.Sv
    positive = Sv[Sv > 0]
    v_low = float(positive.min()) / 1.5 if len(positive) else 1e-3
    v_high = float(Sv.max()) * 1.8 if len(positive) else 1.0
    t_low, t_high = float(T.min()), float(T.max())
    if t_high < 1.5 * t_low:  # one period, or a narrow band: a frame wide enough to read
        t_low, t_high = t_low / 1.5, t_high * 1.5
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlim(t_low, t_high)
    ax.set_ylim(v_low, v_high)
    # Constant Sd: Sv = 2 pi Sd / T (slope -1), labelled where it meets the bottom; constant Sa: Sv = Sa T / (2 pi)
    # (slope +1), labelled where it meets the top. One line a decade, text turned along the line as drawn.
    span = np.array([t_low, t_high])
    sd_values = _decades(v_low * t_low / (2 * math.pi), v_high * t_high / (2 * math.pi))
    sa_values = _decades(2 * math.pi * v_low / t_high / G, 2 * math.pi * v_high / t_low / G)

    def angle(slope: int) -> float:
        (x0, y0), (x1, y1) = ax.transData.transform([(t_low, v_low), (t_low * 10, v_low * 10.0**slope)])
        return math.degrees(math.atan2(y1 - y0, x1 - x0))

    placed = []  # the guide labels' boxes so far

    def label(text: str, exit_t: float, entry_t: float, v_at, slope: int) -> None:
        """Inside the frame where the line leaves it through the bottom (Sd) or top (Sa), else where it enters."""
        # along the line inside the frame, from where it leaves (or enters) toward the other end: the first spot
        # where the label is whole and on no other label
        first, last = max(min(exit_t, entry_t), t_low), min(max(exit_t, entry_t), t_high)
        if not first < last:
            return
        spots = np.geomspace(first, last, 12)
        for t in spots[::-1] if exit_t < t_high else spots:  # from the exit where it is in the frame
            t = float(t)
            shown = ax.text(t, v_at(t), text, fontsize=7, color="0.35", rotation=angle(slope), rotation_mode="anchor",
                            ha="center", va="bottom", clip_on=True)
            box = shown.get_window_extent(fig.canvas.get_renderer())
            inside = ax.get_window_extent().padded(-2)
            if inside.contains(*box.p0) and inside.contains(*box.p1) and not any(box.overlaps(b) for b in placed):
                placed.append(box)
                return
            shown.remove()  # a label the frame would cut, or on another label: the next spot along the line

    for sd in sd_values:
        ax.plot(span, 2 * math.pi * sd / span, color="0.6", lw=0.6, ls="--", zorder=1)
        label(f"Sd {sd:g} m", 2 * math.pi * sd / v_low, 2 * math.pi * sd / v_high,
              lambda t, sd=sd: 2 * math.pi * sd / t, -1)
    for sa in sa_values:
        ax.plot(span, sa * G * span / (2 * math.pi), color="0.6", lw=0.6, ls=":", zorder=1)
        label(f"Sa {sa:g} g", 2 * math.pi * v_high / (sa * G), 2 * math.pi * v_low / (sa * G),
              lambda t, sa=sa: sa * G * t / (2 * math.pi), 1)
    for i, zeta in enumerate(spectrum.damping):
        ax.plot(T, Sv[i], lw=1.6, color=f"C{i % 10}", label=f"ζ = {zeta:g}", zorder=3,
                marker="o" if len(T) < 8 else None, ms=4)
    ax.set_xlabel("Period T [s]")
    ax.set_ylabel("Pseudo-spectral velocity Sv = (2π/T) Sd [m/s]")
    ax.grid(True, which="major", alpha=0.35)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(0.0, 0.88), framealpha=0.9, title="dashed: Sd, dotted: Sa",
              title_fontsize=7)
    rec.plot(*envelope(record.time, record.acceleration / G), lw=0.7, color="0.2")
    rec.set_xlabel("Time t [s]")
    rec.set_ylabel("Ground acc. [g]")
    rec.grid(True, alpha=0.35)
    fig.suptitle(title, fontsize=11)
    return fig


def shock_spectrum_figure(srs, record, title: str):
    """Maximax, positive and negative absolute acceleration in g against natural frequency (log-log) per Q, the
    record beneath."""
    fig = _figure(figsize=(8.0, 7.6))
    ax, rec = fig.subplots(2, 1, height_ratios=[3.0, 1.0])
    fig.subplots_adjust(left=0.11, right=0.97, top=0.92, bottom=0.08, hspace=0.32)
    f = srs.frequency
    for i, q in enumerate(srs.q):
        color = f"C{i % 10}"
        ax.plot(f, srs.maximax[i] / G, lw=1.8, color=color, label=f"Q = {q:g}: maximax")
        ax.plot(f, srs.positive[i] / G, lw=0.9, ls="--", color=color, label="positive")
        ax.plot(f, -srs.negative[i] / G, lw=0.9, ls=":", color=color, label="negative (magnitude)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("Natural frequency [Hz]")
    ax.set_ylabel("Peak absolute acceleration [g]")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, loc="lower left", framealpha=0.9)
    rec.plot(*envelope(record.time, record.acceleration / G), lw=0.8, color="0.2")
    rec.set_xlabel("Time t [s]")
    rec.set_ylabel("Base acc. [g]")
    rec.grid(True, alpha=0.35)
    fig.suptitle(title, fontsize=11)
    return fig


def inelastic_figure(x, title: str):
    """Constant ductility: Cy against T per target beside the elastic Sa / g (mu = 1), and Ry beneath; constant
    strength: the ductility demand per Cy, and Ry beneath. At the first damping ratio."""
    fig = _figure(figsize=(8.0, 8.0), layout="constrained")
    top, bottom = fig.subplots(2, 1, sharex=True)
    T = x.period
    for k, target in enumerate(x.targets):
        color = f"C{k % 10}"
        if x.kind == "ductility":
            top.plot(T, x.Cy[k, 0], color=color, lw=1.5, label=f"μ = {target:g}")
        else:
            top.plot(T, x.ductility[k, 0], color=color, lw=1.5, label=f"Cy = {target:g}")
        bottom.plot(T, x.Ry[k, 0], color=color, lw=1.2)
    if x.kind == "ductility":
        top.plot(T, x.elastic_Sa[0] / G, color="0.2", lw=0.9, ls="--", label="elastic Sa / g")
        top.set_ylabel("Yield strength coefficient Cy = fy / (m g)")
    else:
        top.set_yscale("log")
        top.set_ylabel("Ductility demand μ")
    bottom.set_ylabel("Strength reduction Ry = f0 / fy")
    bottom.set_xlabel("Period T [s]")
    for ax in (top, bottom):
        ax.set_xscale("log")
        ax.grid(True, which="both", alpha=0.3)
    law = "bilinear, b = %g" % x.hardening if x.hardening else "elastoplastic"
    top.legend(fontsize=8, title=f"{law}, ζ = {x.damping[0]:g}", title_fontsize=8)
    fig.suptitle(title, fontsize=11)
    return fig
