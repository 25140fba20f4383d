"""Where smd sensitivity declines a scene, in one line: a law whose sensitivities are not built (before any work), a
stacked system past what its dense exponential takes, a modal run past memory (once the model's derivatives say
which path takes it).

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
    DOFs than MAX_SIZE where the modal path may not take them (the rest: too_many_dofs, once it is known)."""
    if base.is_piecewise_linear:  # a smooth scene, or events beside smooth terms (mixed_sensitivity.py): all taken
        from smdcli.analysis.event_sensitivity import event_refusal

        if refusal := event_refusal(base):
            raise UsageError(f"{sc.path}: {refusal}")
    if (len(params) + 1) * base.n > MAX_SIZE:
        from smdcli.analysis.modal_sensitivity import may_serve

        if not may_serve(base):
            too_many_dofs(sc, len(params), base.n)


def too_many_dofs(sc: Scenario, P: int, n: int) -> None:
    """UsageError where P parameters of an n-DOF scene stack more DOFs than the dense exponential takes (MAX_SIZE)."""
    if (P + 1) * n > MAX_SIZE:
        from smdcli.text import plural

        raise UsageError(f"{sc.path}: {plural(P, 'parameter')} of a {n}-DOF scene stack {(P + 1) * n} DOFs; smd "
                         f"sensitivity takes at most {MAX_SIZE} (beyond, a classically damped scene in modal "
                         "coordinates)")


def too_much_memory(sc: Scenario, P: int, n: int, N: int) -> None:
    """UsageError where a modal run past MAX_SIZE stacked DOFs, on N samples, would not fit in memory."""
    needed = MODAL_COPIES * 8.0 * (P + 1) * N * n
    if (P + 1) * n > MAX_SIZE and not fits(needed):
        from smdcli.text import plural

        raise UsageError(f"{sc.path}: {plural(P, 'parameter')} of a {n}-DOF scene on {N} samples need about "
                         f"{needed / 2**30:.1f} GB in modal coordinates, more than half of this machine's memory")
