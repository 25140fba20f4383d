"""The energy an element dissipates over a run, dissipated:<element>'s measure, with its exact gradient in the
parameters (from the run's sensitivities): a damper's (linear or quadratic) or a Coulomb contact's power integrated
by Gauss-Legendre on each output step's quintic (split at events on the exact flow), a yielding spring's plastic
work summed exactly from its plastic deformation at the event run's events.

Must not import: io, plots, commands, cli.
"""

from __future__ import annotations

import numpy as np

from smdcli.errors import UsageError

YIELDING = ("elastoplastic", "bilinear")  # springs whose dissipated energy is their plastic work
PLASTIC = {"plastic+": 1.0, "plastic-": -1.0}  # a yielding spring's modes, by the sign of its yield force


def dissipated(s, name: str) -> tuple[float, np.ndarray]:
    """The energy a damper, a Coulomb friction contact or a yielding spring (_plastic_work) dissipates over a run, J,
    and its gradient from the run's sensitivities s: the integral of its power (a damper's c w^2, c |w|^3 if quadratic; a contact's F |w| + c_v w^2
    while it slips, nothing while it sticks; w the rate across it) by Gauss-Legendre on the quintic Hermite
    interpolant of each output step, as the energy balance integrates (hermite_rule.hermite_slopes); the gradient the
    same sum differentiated, the rate's derivative from the sensitivities' own quintics. On a scene solved event
    to event a step holding an event (where the quintic does not hold) is split at its events, each piece's Gauss
    nodes read on the exact flow."""
    if any(e.path == name and e.law.name in YIELDING for e in s.model.nonsmooth):
        return _plastic_work(s, name)
    row, belt, coefficients = _dissipator(s.model, name)
    dbelt = np.array([d.of(lambda m: _dissipator(m, name)[1]) for d in s.derivatives])
    w, quadrature = _rates(row, s.time, s.displacement, s.velocity, s.acceleration)
    dw, _ = _rates(row, s.time, s.d_displacement, s.d_velocity, s.d_acceleration)
    if len(s.event_times) and s.exact_state_at is not None:
        w, dw, quadrature = _across_events(s, row, w, dw, quadrature)
    w, dw = w + belt, dw + dbelt[:, None, None]
    magnitude = np.abs(w)
    # the power's parts, each a coefficient times a function of w: (coefficient, f(w), f'(w))
    parts = {"linear": (w * w, 2 * w), "quadratic": (magnitude ** 3, 3 * magnitude * w),
             "coulomb": (magnitude, np.sign(w))}
    value, gradient = 0.0, np.zeros(len(s.derivatives))
    for kind, coefficient in coefficients.items():
        f, slope = parts[kind]
        dc = np.array([d.of(lambda m, kind=kind: _dissipator(m, name)[2][kind]) for d in s.derivatives])
        unit = float((f * quadrature).sum())
        value += coefficient * unit
        gradient += dc * unit + coefficient * (slope[None] * dw * quadrature).sum(axis=(1, 2))
    return value, gradient


def _plastic_work(s, name: str) -> tuple[float, np.ndarray]:
    """A yielding spring's plastic work over a run, J, and its gradient: its core's yield force times the total
    variation of its plastic deformation, which is constant while the spring is elastic and monotone while it yields,
    so that its values at the event run's checkpoints (a yielding state holds the value it yielded from) and at the
    run's end sum it exactly. Each value's derivative is the one the run carries for it, set at its moved event; the
    end's, while yielding, is that of d(T) -+ fy/k at the fixed time."""
    if not s.law_states:
        raise UsageError(f"dissipated:{name}: needs the scene's event-to-event sensitivities")
    index = next(i for i, e in enumerate(s.model.nonsmooth) if e.path == name)
    element, core = s.model.nonsmooth[index], s.model.nonsmooth[index].law.core
    dfy, dk = (np.array([d.of(lambda m, key=key: getattr(m.nonsmooth[index].law.core, key)) for d in s.derivatives])
               for key in ("fy", "k"))
    values = [states[index].internal["dp"] for _, states, _ in s.law_states]
    slopes = [dq[index]["dp"] for _, _, dq in s.law_states]
    last = s.law_states[-1][1][index]
    values.append(element.law.plastic_deformation(last, float(element.row @ s.displacement[-1])))
    if last.mode in PLASTIC:
        slopes.append(s.d_displacement[:, -1] @ element.row
                      - PLASTIC[last.mode] * (dfy / core.k - core.fy * dk / core.k ** 2))
    else:
        slopes.append(slopes[-1])
    steps, moved = np.diff(values), np.diff(np.array(slopes, dtype=float), axis=0)
    variation = float(np.abs(steps).sum())
    return core.fy * variation, dfy * variation + core.fy * (np.sign(steps) @ moved)


def dissipators(model) -> tuple[str, ...]:
    """The elements dissipated:<element> measures: every damper, Coulomb friction contact and yielding spring."""
    return tuple(e.name for e in model.elements if e.kind == "damper") + tuple(
        e.path for e in model.nonsmooth if e.kind == "friction" and e.law.piecewise_linear
        or e.kind == "spring" and e.law.name in YIELDING)


def _dissipator(model, name: str) -> tuple[np.ndarray, float, dict[str, float]]:
    """(row, belt, {power's part: coefficient}) of a damper or a Coulomb contact: w = row . v + belt."""
    for e in model.elements:
        if e.name == name:
            row = np.zeros(model.n)
            if e.b >= 0:
                row[e.b] += 1.0
            if e.a >= 0:
                row[e.a] -= 1.0
            return row, 0.0, {"quadratic" if e.law == "quadratic" else "linear": e.coef}
    e = next(e for e in model.nonsmooth if e.path == name)
    return np.asarray(e.row, dtype=float), float(e.belt), {"coulomb": e.law.force, "linear": e.law.viscous}


def _across_events(s, row, w, dw, quadrature):
    """w, dw and the weights with each output step that holds an event (or ends or starts at one) split at its
    events: the pieces' Gauss nodes appended as steps of their own (the step's own zeroed), their states and
    sensitivities read on the exact flow (s.exact_state_at)."""
    from smdcli.analysis.energy import GAUSS_POINTS

    time, n = s.time, s.displacement.shape[1]
    events = np.asarray(s.event_times, dtype=float)
    steps = np.unique(np.concatenate([np.searchsorted(time, events, side="right") - 1,
                                      np.searchsorted(time, events, side="left") - 1]))
    steps = steps[(steps >= 0) & (steps < len(time) - 1)]
    nodes, weights = np.polynomial.legendre.leggauss(GAUSS_POINTS)
    extra_w, extra_dw, extra_q = [], [], []
    for k in steps:
        cuts = np.concatenate([[time[k]], events[(events > time[k]) & (events < time[k + 1])], [time[k + 1]]])
        for a, b in zip(cuts[:-1], cuts[1:]):
            if b <= a:
                continue
            at = a + 0.5 * (nodes + 1) * (b - a)
            states = [s.exact_state_at(float(t)) for t in at]
            extra_w.append([z[n:2 * n] @ row for z, _ in states])
            extra_dw.append(np.array([S[:, n:2 * n] @ row for _, S in states]).T)
            extra_q.append(0.5 * weights * (b - a))
    quadrature = quadrature.copy()
    quadrature[steps] = 0.0
    if not extra_w:
        return w, dw, quadrature
    return (np.concatenate([w, np.array(extra_w)]), np.concatenate([dw, np.stack(extra_dw, axis=1)], axis=1),
            np.concatenate([quadrature, np.array(extra_q)]))


def dissipated_history(result, name: str) -> np.ndarray:
    """The energy an element (dissipated's) has dissipated by each output time of a solved run, J (N,), step by step
    on the run's own samples (a figure's: the quintic across events too; a yielding spring's plastic work from its
    plastic deformation's samples)."""
    model = result.origin[1]
    element = next((e for e in model.nonsmooth if e.path == name and e.law.name in YIELDING), None)
    if element is not None:
        plastic = result.nonsmooth.internal[f"{name}.plastic_deformation"]
        return element.law.core.fy * np.concatenate([[0.0], np.cumsum(np.abs(np.diff(plastic)))])
    row, belt, coefficients = _dissipator(model, name)
    w, quadrature = _rates(row, result.time, result.displacement, result.velocity, result.acceleration)
    w = w + belt
    power = sum(c * {"linear": w * w, "quadratic": np.abs(w) ** 3, "coulomb": np.abs(w)}[kind]
                for kind, c in coefficients.items())
    return np.concatenate([[0.0], np.cumsum((power * quadrature).sum(axis=1))])


def _rates(row: np.ndarray, time, x, v, a) -> tuple[np.ndarray, np.ndarray]:
    """row . x' at each output step's Gauss nodes, from the quintic Hermite of x, v, a (..., N, n) ->
    (..., N - 1, G); and the nodes' weights times the step."""
    from smdcli.analysis.energy import GAUSS_POINTS
    from smdcli.analysis.hermite_rule import hermite_slopes

    nodes, weights = np.polynomial.legendre.leggauss(GAUSS_POINTS)
    slope = hermite_slopes(0.5 * (nodes + 1))
    h = np.diff(time)[:, None]
    d, r, q = x @ row, v @ row, a @ row
    ends = np.stack([d[..., :-1], h[:, 0] * r[..., :-1], h[:, 0] ** 2 * q[..., :-1], d[..., 1:], h[:, 0] * r[..., 1:],
                     h[:, 0] ** 2 * q[..., 1:]], axis=-1)
    return ends @ slope.T / h, 0.5 * weights[None, :] * h
