"""The run's own physics, checked along its solution: every dissipated energy (damping, hysteretic, friction,
impact) never decreases, every law keeps its own rules (a stuck contact within its breakaway force, a yield
surface never passed, a rigid stop never passed: Law.excess), and the energy balance closes within what the run
states. A run that breaks one is 'suspect': the reasons go to the summary, the notes and the file.

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math

import numpy as np

from smdcli.model import Model
from smdcli.result import Result, finite_peak

SLACK = 10.0  # times the run's stated accuracy: what a check allows beyond it
FLOOR = 1e-12  # relative: rounding of the sums the checks read
# The energy balance of an integrator is a second integral beside the motion (powers integrated under its own error
# control): DOP853 at rtol 1e-12 on a quadratic damper closes it to 5e-10 where its trajectory is good to 1e-11
ENERGY_SLACK = 10.0
DISSIPATED = ("dissipated", "hysteretic", "friction", "impact")


def static_work(model: Model, result: Result) -> float:
    """The energy the scene's loads would store statically, F^2 / k (the largest load on the stiffest spring, the
    ground's as M a_g): the scale against which a run that barely moves is judged (a block held by friction the whole
    run has energies of 1e-18 J, all rounding, whose ratios to each other say nothing)."""
    loads = [finite_peak(result.force)] if model.is_forced else []  # no temporary of the force's size
    if result.ground is not None:
        loads.append(float(np.max(np.abs(result.ground.acceleration), initial=0.0)
                           * np.max(np.abs(model.M.diagonal()), initial=0.0)))  # dense or sparse: never made dense
    stiffness = float(np.max(np.abs(model.initial_K.diagonal()), initial=0.0))
    load = max(loads, default=0.0)
    return load * load / stiffness if stiffness > 0 and math.isfinite(load) else 0.0


def allowance(result: Result) -> float:
    """The relative departure a check allows: SLACK times the run's stated accuracy, at least rounding."""
    stated = result.stats.stated_accuracy
    return max(SLACK * stated, FLOOR) if math.isfinite(stated) else 1e-6


def suspicions(model: Model, result: Result) -> tuple[str, ...]:
    """Why the run's numbers break its own physics, one line a reason; () where they hold."""
    if not result.success or result.energy is None:
        return ()
    with np.errstate(all="ignore"):  # a scene at the edge of double precision: judged by the figures, not warned
        return _suspicions(model, result)


def _suspicions(model: Model, result: Result) -> tuple[str, ...]:
    allowed = allowance(result)
    reasons = []
    energy, time = result.energy, result.time
    largest = max(energy.largest, static_work(model, result))
    booked_freely = {element.law.dissipation(element.law.start(0.0, 0.0), 0.0, 0.0, 0.0)[0]
                     for element in model.nonsmooth if not element.law.dissipation_never_decreases}
    for name in DISSIPATED:
        series = getattr(energy, name)
        if series is None or not len(series) or name in booked_freely:  # the law's own bookkeeping gives back
            continue
        fall = np.maximum.accumulate(series) - series
        worst = int(np.argmax(fall))
        if fall[worst] > allowed * largest:
            reasons.append(f"the {'damping' if name == 'dissipated' else name} energy decreases by "
                           f"{fall[worst]:.3g} J by t = {time[worst]:.6g} s ({fall[worst] / largest:.2g} of the "
                           "largest energy): an element creates energy")
    off = float(np.max(np.abs(energy.residual), initial=0.0)) / largest if largest > 0 else 0.0
    if off > max(ENERGY_SLACK * allowed, 1e-9):
        reasons.append(f"the energy balance is off by {off:.2g} of the largest energy, beyond the "
                       f"{ENERGY_SLACK * allowed:.2g} the run states")
    if result.nonsmooth is not None:
        history = result.nonsmooth
        for element in model.nonsmooth:
            if element.path not in history.paths:
                continue
            d = result.displacement @ element.row
            rate = result.velocity @ element.row + element.belt
            found = element.law.excess(d, rate, history.tension[:, history.paths.index(element.path)])
            if found is None:
                continue
            over, scale, rule = found
            worst = int(np.argmax(over))
            if over[worst] > allowed * scale:
                reasons.append(f"{element.path}: {rule}, but is past it by {over[worst]:.3g} at t = {time[worst]:.6g} s")
    return tuple(reasons)
