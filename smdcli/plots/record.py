"""A processed record: acceleration (raw beneath, processed), velocity, displacement and the Husid plot with the
significant duration shaded.

Plot functions return a Figure; only save_figure touches disk. Must not import: commands, cli."""

from __future__ import annotations

from smdcli.plots.common import _figure, envelope
from smdcli.scenario.spec import STANDARD_GRAVITY as G


def record_figure(p, name: str):
    """Four panels over time sharing the time axis."""
    fig = _figure(figsize=(8.0, 9.0), layout="constrained")
    acc, vel, dis, husid = fig.subplots(4, 1, sharex=True)
    t = p.time
    processed = p.baseline != "none" or p.band is not None
    if processed:
        acc.plot(*envelope(t, p.raw / G), lw=0.6, color="0.65", label="as read")
    acc.plot(*envelope(t, p.acceleration / G), lw=0.7, color="C0", label="processed" if processed else None)
    acc.set_ylabel("Acceleration [g]")
    if processed:
        acc.legend(fontsize=8, loc="upper right")
    vel.plot(*envelope(t, p.velocity), lw=0.8, color="C1")
    vel.set_ylabel("Velocity [m/s]")
    dis.plot(*envelope(t, p.displacement), lw=0.8, color="C2")
    dis.set_ylabel("Displacement [m]")
    m = p.measures
    total = p.arias[-1]
    husid.plot(t, p.arias / total if total > 0 else p.arias, lw=1.2, color="C3")
    husid.axvspan(m.t5, m.t95, color="C3", alpha=0.12, label=f"D5-95 = {m.d5_95:.3g} s")
    husid.axvspan(m.t5, m.t75, color="C3", alpha=0.12, label=f"D5-75 = {m.d5_75:.3g} s")
    husid.set_ylabel("Husid (Arias / total)")
    husid.set_xlabel("Time t [s]")
    husid.set_ylim(-0.02, 1.02)
    husid.legend(fontsize=8, loc="lower right", title=f"Arias {m.arias:.3g} m/s", title_fontsize=8)
    for ax in (acc, vel, dis, husid):
        ax.grid(True, alpha=0.35)
    what = []
    if p.baseline != "none":
        what.append(f"{p.baseline} baseline")
    if p.band is not None:
        what.append(f"band-pass {p.band[0]:g}-{p.band[1]:g} Hz")
    fig.suptitle(f"Record {name}" + (f" ({', '.join(what)})" if what else "") +
                 f"\nPGA {m.pga / G:.3g} g, PGV {m.pgv:.3g} m/s, PGD {m.pgd:.3g} m", fontsize=10)
    return fig
