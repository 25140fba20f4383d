"""Where smd sensitivity declines a scene, in one line before any work: a law whose sensitivities are not built, a
stacked system past what its dense exponential takes, a modal run past memory.

Must not import: io, plots, commands, cli.
"""

from __future__ import annotations

from smdcli.errors import UsageError
from smdcli.model import Model
from smdcli.resources import fits
from smdcli.scenario import Scenario

MAX_SIZE = 3000  # DOFs of the stacked system, (P + 1) n: its dense exponential's memory and time
MODAL_COPIES = 36  # the modal path's working memory, in (P + 1) N n numbers (a 1000-mass chain's, P = 3: 1.2 GB)


def refuse(sc: Scenario, params: list[str], base: Model) -> None:
    """UsageError where the scene's sensitivities are not given: a law whose sensitivities are not built, more stacked
    DOFs than MAX_SIZE where the modal path may not take them (refuse_large says so for the rest, once it knows)."""
    if not base.is_linear:
        from smdcli.analysis.event_sensitivity import event_refusal
        from smdcli.analysis.smooth_sensitivity import smooth_refusal

        refusal = event_refusal(base) if base.is_piecewise_linear else smooth_refusal(base)
        if refusal:
            raise UsageError(f"{sc.path}: {refusal}")
    if (len(params) + 1) * base.n > MAX_SIZE:
        from smdcli.analysis.modal_sensitivity import may_serve

        if not may_serve(base):
            refuse_large(sc, len(params), base.n)


def refuse_large(sc: Scenario, P: int, n: int, N: int | None = None) -> None:
    """UsageError where P parameters of an n-DOF scene stack more than MAX_SIZE DOFs: always without N (the dense
    path), with N only where the modal path's N samples would not fit in memory."""
    from smdcli.text import plural

    if (P + 1) * n <= MAX_SIZE:
        return
    if N is None:
        raise UsageError(f"{sc.path}: {plural(P, 'parameter')} of a {n}-DOF scene stack {(P + 1) * n} DOFs; smd "
                         f"sensitivity takes at most {MAX_SIZE} (beyond, a classically damped scene in modal "
                         "coordinates)")
    needed = MODAL_COPIES * 8.0 * (P + 1) * N * n
    if not fits(needed):
        raise UsageError(f"{sc.path}: {plural(P, 'parameter')} of a {n}-DOF scene on {N} samples need about "
                         f"{needed / 2**30:.1f} GB in modal coordinates, more than half of this machine's memory")
