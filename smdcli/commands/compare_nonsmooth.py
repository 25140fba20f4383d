"""compare-solvers on a nonsmooth scene: the methods that take it, the smoothed laws (tanh friction, penalty
stops) that methods without event location would be run on, and the verdict on each run: diverged, a smoothed
law that changed the scene, energy created, events missed, a stick that chatters.

Must not import: cli.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from smdcli.model import Model
from smdcli.result import Result
from smdcli.solvers.registry import BY_NAME, names

NONSMOOTH_RTOLS = (1e-3, 1e-5, 1e-7, 1e-9)  # a shorter ladder, as charted in the docs (LSODA steps from Python)


def nonsmooth_defaults(model: Model) -> tuple[str, ...]:
    """The methods compared on a nonsmooth scene: those that take it (the Newmark family only with hysteretic
    springs alone), and DOP853, Radau and ode45 on its smoothed friction (/tanh) and stops (/penalty)."""
    from smdcli.solvers.events.drivers import nonsmooth_refusal

    defaults = [m for group in ("adaptive", "fixed") for m in names(compare=group, nonsmooth=True)]
    methods = [m for m in defaults if nonsmooth_refusal(m, model) is None]
    kinds = {e.kind for e in model.nonsmooth}
    rigid = any(e.kind == "stop" and e.law.rigid for e in model.nonsmooth)
    for variant, wanted in (("tanh", "friction" in kinds), ("penalty", rigid)):
        if wanted:
            methods += [f"{m}/{variant}" for m in ("ode45", "DOP853", "Radau")]
    return tuple(methods)


def refusals(model: Model, candidates, methods) -> dict[str, str]:
    """Why each candidate left out of `methods` cannot take the scene (the failure map's footnote)."""
    from smdcli.solvers.events.drivers import nonsmooth_refusal

    if not model.nonsmooth:
        return {}
    why = {m: nonsmooth_refusal(m, model) for m in candidates if m not in methods}
    return {m: cannot_represent(reason) for m, reason in why.items() if reason}


def cannot_represent(refusal: str) -> str:
    """A method's refusal of a scene as compare-solvers words it: 'cannot represent: <element>: why', naming the
    element the refusal names (or 'refused: why' where it names none)."""
    import re

    found = re.search(r"\b(?:spring|damper|friction|stop)\[\d+\]", refusal)
    return f"cannot represent: {found.group(0)}: {refusal}" if found else f"refused: {refusal}"


# A run is a failure, whatever its integrator says, where its answer is not one: an energy balance off by more
# than all the energy there was, a solution grown far past the reference's (a phase error alone is not one).
FAILED_ENERGY = 1.0
FAILED_GROWTH = 10.0
FAILED_SMOOTHED = 0.05  # a smoothed law (tanh friction, penalty stop) this far off has changed the scene


def verdict(result: Result, error: float, energy: float, growth: float, reference: Result,
            variant: str | None, allowed: float = 0.0) -> str:
    """'' for a good run, else why it failed: diverged, a smoothed law that changed the scene, energy created,
    events missed or chattering where they put the run off the reference by more than its tolerance `allowed` (an
    integrator at rtol 1e-7 that ends a ball's bouncing a flight of 1e-12 m sooner than `exact` is right)."""
    if not math.isfinite(error) or growth > FAILED_GROWTH:
        return f"diverged: error {error:.2g} of the peak, the solution {growth:.2g} times the reference's"
    if variant is not None and error > FAILED_SMOOTHED:  # no tolerance brings a smoothed law to the exact one
        return f"wrong law: the {variant} law is off the exact solution by {error:.2g} of the peak"
    if math.isfinite(energy) and energy > FAILED_ENERGY:
        return f"energy created or lost: the balance is off by {energy:.2g} of the largest energy"
    # the Newmark family return-maps its springs step by step, locating no event by design: its error is its answer
    locates = not BY_NAME[result.stats.method].return_mapping
    if variant is None and locates and reference.nonsmooth is not None and result.nonsmooth is not None \
            and error > allowed:
        mine, theirs = _counts(result.nonsmooth.events), _counts(reference.nonsmooth.events)
        fewer = {k: theirs[k] - mine.get(k, 0) for k in theirs if mine.get(k, 0) < theirs[k]}
        more = {k: mine[k] - theirs.get(k, 0) for k in mine if mine[k] > theirs.get(k, 0)}
        if fewer:
            return "missed " + ", ".join(f"{count} {kind}" for kind, count in fewer.items()) + " events"
        if more:
            return "chattered: " + ", ".join(f"{count} extra {kind}" for kind, count in more.items()) + " events"
    return ""


def _counts(events) -> dict[str, int]:
    counts: dict[str, int] = {}
    for _, _, kind in events:
        counts[kind] = counts.get(kind, 0) + 1
    return counts


def run_energy(model: Model, result: Result):
    """The run's energy balance: its own (a nonsmooth run integrates it) or from its trajectory."""
    from smdcli.analysis.energy import energy_balance

    return result.nonsmooth.balance() if result.nonsmooth is not None else energy_balance(model, result)


# The smoothed laws a nonsmooth scene is compared under: what methods without event location are run on.
VARIANTS = ("tanh", "penalty")


def split_variant(method: str) -> tuple[str | None, str]:
    """(variant, method) of a method name: 'DOP853/tanh' is DOP853 on the scene with friction smoothed."""
    base, _, variant = method.partition("/")
    return (variant or None), base


def smoothed(model: Model, variant: str, reference: Result) -> Model:
    """The scene with its friction made a tanh law (its speed scale a thousandth of the reference's peak relative
    speed) or its rigid stops made penalty springs (stiff enough to touch for a thousandth of the run, damped to
    the stop's rebound, Stop.penalty): the usual way around events, with the chattering and stiffness it brings."""
    from smdcli.elements.friction import Friction
    from smdcli.elements.stop import Stop
    from smdcli.model.nonsmooth import NonsmoothElement

    speed = float(np.abs(reference.velocity).max(initial=0.0)) or 1.0
    span = float(reference.time[-1] - reference.time[0]) or 1.0
    mass = float(np.max(np.diag(model.M)))
    changed = []
    for element in model.nonsmooth:
        law = element.law
        if variant == "tanh" and isinstance(law, Friction):
            law = Friction(law.force, law.force, viscous=law.viscous, regularization=1e-3 * speed,
                           belt_velocity=law.belt_velocity)
        elif variant == "penalty" and isinstance(law, Stop) and law.rigid:
            k = mass * (2 * math.pi / (1e-3 * span)) ** 2
            law = law.penalty(k, mass)
        changed.append(NonsmoothElement(element.path, element.kind, law, element.connects, element.row,
                                        element.belt))
    return dataclasses.replace(model, nonsmooth=tuple(changed))
