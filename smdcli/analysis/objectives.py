"""What `smd optimize` minimizes and how it is written: the objectives' kinds and units, an objective or a
constraint read against the scene's DOFs and dissipating elements, a parameter's bounds.

Must not import: io, plots, commands, cli.
"""

from __future__ import annotations

import difflib
import math
import re
from dataclasses import dataclass

from smdcli.analysis.response_measures import GROUND
from smdcli.errors import UsageError

OBJECTIVES = ("peak_receptance", "peak_transmissibility", "rms", "rms_drift", "rms_acceleration", "peak_displacement",
              "peak_drift", "peak_acceleration", "residual_displacement", "dissipated")
UNITS = {"peak_receptance": "m/N", "peak_transmissibility": "1", "rms": "m", "rms_drift": "m", "rms_acceleration": "m/s^2",
         "peak_displacement": "m", "peak_drift": "m", "peak_acceleration": "m/s^2", "residual_displacement": "m",
         "dissipated": "J"}
RMS = ("rms", "rms_drift", "rms_acceleration")  # under an input PSD: white noise, or a profile
TIME_DOMAIN = ("peak_displacement", "peak_drift", "peak_acceleration", "residual_displacement", "dissipated")
TIME_PEAK_KINDS = ("peak_displacement", "peak_drift", "peak_acceleration")  # the largest of a run's peaks in time
PEAKS = ("peak_receptance", "peak_transmissibility")  # minimized as the minimax over located peaks

@dataclass(frozen=True)
class Objective:
    """What is minimized: a kind of OBJECTIVES at one DOF."""

    kind: str
    dof: int
    text: str
    other: int = -1  # a drift's lower DOF (peak_drift:<a>-<b>: x_a - x_b), GROUND for <a>-ground
    element: str = ""  # dissipated:<element>'s damper, Coulomb contact or yielding spring (spring[i])


def read_objective(text: str, dofs: tuple[str, ...], source: str, elements: tuple[str, ...] = ()) -> Objective:
    """'kind:dof' (or dissipated:<element>) read against the scene's DOFs and the elements a dissipated energy is
    measured of (response_measures.dissipators); UsageError naming what is wrong."""
    kind, _, dof = text.partition(":")
    if kind not in OBJECTIVES:
        hint = difflib.get_close_matches(kind, OBJECTIVES, n=1)
        raise UsageError(f"--minimize {text}: unknown objective {kind!r} (" +
                         (f"did you mean {hint[0]!r}?" if hint else f"known: {', '.join(OBJECTIVES)}") + ")")
    if kind == "dissipated":
        if dof not in elements:
            raise UsageError(f"--minimize {text}: expected dissipated:<element> of {source}, a damper, a Coulomb "
                             "friction contact or a yielding spring (" + (f"it has {', '.join(elements)}" if elements else
                                                     "it has none") + ")")
        return Objective(kind, 0, text, element=dof)
    if kind in ("peak_drift", "rms_drift"):
        pairs = [(dof[:i], dof[i + 1:]) for i, c in enumerate(dof) if c == "-"]
        pair = next(((a, b) for a, b in pairs if a in dofs and (b in dofs or b == "ground")), None)
        if pair is None:
            raise UsageError(f"--minimize {text}: expected {kind}:<dof>-<dof> of two DOFs of {source}, or "
                             f"<dof>-ground (DOFs are {', '.join(dofs)})")
        return Objective(kind, dofs.index(pair[0]), text, GROUND if pair[1] == "ground" else dofs.index(pair[1]))
    if dof not in dofs:
        hint = difflib.get_close_matches(dof, dofs, n=1)
        raise UsageError(f"--minimize {text}: no DOF {dof!r} in {source} (" +
                         (f"did you mean {hint[0]!r}?" if hint else f"DOFs are {', '.join(dofs)}") + ")")
    return Objective(kind, dofs.index(dof), text)


def read_constraint(text: str, dofs: tuple[str, ...], source: str,
                    elements: tuple[str, ...] = ()) -> tuple[Objective, float]:
    """'OBJECTIVE <= VALUE' as (the measure, its limit); UsageError naming what is wrong."""
    found = re.fullmatch(r"\s*(\S+)\s*<=\s*(\S+)\s*", text)
    if not found:
        raise UsageError(f"--subject-to {text}: expected OBJECTIVE <= VALUE (rms:tmd <= 0.05)")
    try:
        limit = float(found.group(2))
    except ValueError:
        raise UsageError(f"--subject-to {text}: expected a number after <=, found {found.group(2)!r}") from None
    if not (math.isfinite(limit) and limit > 0):
        raise UsageError(f"--subject-to {text}: expected a positive finite limit, found {limit:g}")
    try:
        return read_objective(found.group(1), dofs, source, elements), limit
    except UsageError as exc:
        raise UsageError(f"--subject-to {text}: {exc.args[0].split(': ', 1)[1]}") from None


def read_bounds(text: str) -> tuple[str, float, float]:
    """'PATH=LO:HI' as (path, lo, hi); UsageError unless LO < HI are numbers."""
    found = re.fullmatch(r"\s*([^=\s]+)\s*=\s*([^:]+):(.+)", text)
    if not found:
        raise UsageError(f"--param {text}: expected PATH=LO:HI (spring[1].k=10:100), every parameter bounded")
    path, lo, hi = found.groups()
    try:
        low, high = float(lo), float(hi)
    except ValueError:
        raise UsageError(f"--param {text}: expected numbers LO:HI, found {lo!r}:{hi!r}") from None
    if not (math.isfinite(low) and math.isfinite(high) and low < high):
        raise UsageError(f"--param {text}: expected finite bounds with LO < HI, found {low:g}:{high:g}")
    return path, low, high
