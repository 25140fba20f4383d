"""How accurately the model's own numbers are computed: its matrices and its modes.

A stated accuracy is relative to the data set's largest magnitude: every entry's error is at most
stated_accuracy * max|data| (see docs/accuracy.md). Matrices are sums of a few element stamps, rounded a few
times. Modes come from eigensolvers that are backward stable: what they return is exact for a matrix within
c n eps of the one given, and how far that moves an eigenvalue or a shape depends on the problem (a rigid-body
mode's frequency moves by sqrt(eps), a shape of a repeated frequency is not determined at all). That is measured
here as it happens: the modes of the model perturbed by its solver's backward error, compared with its own.

Must not import: solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING

import numpy as np

from smdcli.model.mass import mass_solve
from smdcli.result import finite_peak
from smdcli.scenario import GROUND

if TYPE_CHECKING:
    from smdcli.model.system import Model
    from smdcli.result import Result

EPS = float(np.finfo(float).eps)
SAFETY = 10.0  # a perturbation shows an error's size, not its worst case: stated accuracies carry this margin
MEASURED_UP_TO = 200  # DOFs up to which modes are measured by perturbation; beyond, normwise bounds


def matrix_accuracy(model) -> dict[str, float]:
    """M, C, K: each entry a sum of at most n element stamps (and [damping]'s products), rounded once a term."""
    n = model.n
    stamps = 4 * (n + 1) * EPS
    accuracy = {"M": stamps, "K": stamps, "C": stamps}
    if model.added_damping is not None:  # alpha M + beta K, or M Phi diag Phi^T M from an eigensolver
        accuracy["C"] = max(stamps, modes_accuracy(model)["shapes"])
    return accuracy


def modes_accuracy(model) -> dict[str, float]:
    """Stated accuracies of natural_frequencies_rad_s, damping_ratios, shapes and eigenvalues, each relative to its
    data set's largest magnitude (inf where a quantity is not determined by the model, as a repeated mode's shape)."""
    if "_modes_accuracy" not in model.__dict__:  # kept with the (frozen) model, as its cached properties are
        with np.errstate(all="ignore"):  # a scene at the edge of double precision: an inf accuracy says so
            found = _measured(model) if model.n <= MEASURED_UP_TO else _bounded(model)
        model.__dict__["_modes_accuracy"] = {k: (v if v == v else np.inf) for k, v in found.items()}
    return model.__dict__["_modes_accuracy"]


def _relative(a: np.ndarray, b: np.ndarray) -> float:
    scale = max(float(np.abs(a).max(initial=0.0)), float(np.abs(b).max(initial=0.0)))
    if scale == 0:
        return 0.0
    with np.errstate(invalid="ignore"):
        gap = np.abs(a - b)
    gap = np.where(np.isnan(gap), np.inf, gap)
    return float(gap.max(initial=0.0) / scale)


def _perturbed(model, seed: int):
    """The model with M, C and K moved by a symmetric perturbation of norm 8 n eps times each one's norm: the
    backward error of the eigensolvers that give its modes."""
    rng = np.random.default_rng(seed)
    n = model.n
    changed = {}
    for name in ("M", "C", "K"):
        A = getattr(model, name)
        E = rng.standard_normal((n, n))
        E = E + E.T
        norm = np.linalg.norm(E, 2)
        size = 8 * n * EPS * float(np.linalg.norm(A, 2))
        changed[name] = A + (E * (size / norm) if norm > 0 else 0.0)
    return dataclasses.replace(model, **changed)


def _measured(model) -> dict[str, float]:
    """The largest change of each modal quantity over two perturbations by the backward error, times SAFETY."""
    base = model.modes
    worst = {"natural_frequencies_rad_s": 0.0, "damping_ratios": 0.0, "shapes": 0.0, "eigenvalues": 0.0}
    for seed in (1, 2):
        try:
            other = _perturbed(model, seed).modes
        except (np.linalg.LinAlgError, ValueError):  # a perturbed M not positive definite: nothing is determined
            return {key: np.inf for key in worst}
        pairs = {"natural_frequencies_rad_s": (base.natural_frequencies, other.natural_frequencies),
                 "damping_ratios": (_finite(base.damping_ratios), _finite(other.damping_ratios)),
                 "shapes": (base.shapes, other.shapes),
                 "eigenvalues": (_sorted(base.eigenvalues), _sorted(other.eigenvalues))}
        for key, (a, b) in pairs.items():
            worst[key] = max(worst[key], _relative(a, b))
    return {key: SAFETY * value + 4 * EPS for key, value in worst.items()}


def _finite(values: np.ndarray) -> np.ndarray:
    """Damping ratios with a rigid-body mode's inf kept comparable (inf on both sides is no error)."""
    return np.where(np.isinf(values), 0.0, values)


def _sorted(eigenvalues: np.ndarray) -> np.ndarray:
    return eigenvalues[np.lexsort((eigenvalues.imag, eigenvalues.real))]


def _bounded(model) -> dict[str, float]:
    """Normwise bounds for large models: eigenvalues within c n eps of the largest; a frequency w moves by that over
    w (sqrt of it for a rigid-body mode); a shape by it over the gap to the nearest other mode."""
    modes = model.modes
    squared = np.sort(modes.natural_frequencies ** 2)
    top = float(squared.max(initial=0.0))
    if model.is_sparse:  # its modes are the lowest few; the rounding scales with the highest
        top = max(top, model.omega_max ** 2)
    change = 8 * model.n * EPS * top
    w = np.sqrt(squared)
    frequency = float((change / (w + np.sqrt(change))).max(initial=0.0)) / max(float(w.max(initial=0.0)), 1e-300)
    gaps = np.diff(squared)
    shapes = change / float(gaps.min()) if len(gaps) and gaps.min() > 0 else (np.inf if len(gaps) else 4 * EPS)
    eig = float(np.abs(modes.eigenvalues).max(initial=0.0))
    return {"natural_frequencies_rad_s": frequency, "damping_ratios": frequency,
            "shapes": float(min(shapes, np.inf)), "eigenvalues": float(np.sqrt(change) / max(eig, 1e-300))}


def loaded_force(model: Model):
    """The applied force at the DOFs a force acts on, as a function of time ((N, loaded DOFs)): the columns of the
    (N, n) applied force that are not zero throughout (one of a 10,000-DOF chain's)."""
    loaded = np.flatnonzero(np.any(model.B != 0, axis=1))
    return lambda t: model.forces(t) @ model.B[loaded].T


def evaluation_accuracy(evaluate, time: np.ndarray) -> float:
    """Values computed from the time alone (applied forces, a given ground motion): t is itself rounded, so a value
    is known to what moving t by its rounding changes (a sine's argument w t carries eps w t), times SAFETY.
    Relative to the values' largest magnitude."""
    time = np.asarray(time, dtype=float)
    peak = change = 0.0
    width = max(1, int(np.size(evaluate(time[:1])))) if len(time) else 1
    rows = max(1, EVALUATED_VALUES // width)  # a 10,000-DOF run's forces: 80 MB each, four of them at once
    with np.errstate(all="ignore"):
        for start in range(0, len(time), rows):
            t = time[start:start + rows]
            value = np.asarray(evaluate(t), dtype=float)
            moved = np.asarray(evaluate(t * (1 + 2 * EPS)), dtype=float)
            peak = max(peak, float(np.max(np.abs(value), initial=0.0)))
            change = max(change, float(np.max(np.abs(moved - value), initial=0.0)))
    if not peak > 0:
        return 4 * EPS
    return SAFETY * change / peak + 4 * EPS


EVALUATED_VALUES = 1_000_000  # values evaluate() gives at once in evaluation_accuracy


def derived_accuracy(model: Model, result: Result) -> dict[str, float]:
    """The accuracy that element forces and energies inherit from the run's stated accuracy s of x and v: an element
    force moves by at most 2 s times the peak motion (relative to the data set's peak); an energy by 2 s of the
    largest energy, and the integrals also by the balance's residual (which holds their quadrature and method
    error), each relative to the largest energy; the residual vouches for nothing below its own size."""
    with np.errstate(all="ignore"):
        return _derived_accuracy(model, result)


def _derived_accuracy(model: Model, result: Result) -> dict[str, float]:
    s = result.stats.stated_accuracy
    # peaks without a temporary of each array's size (a 10,000-mass chain's are 80 MB each)
    X = finite_peak(result.displacement, result.extremes_of("displacement"))
    V = finite_peak(result.velocity, result.extremes_of("velocity"))
    out = {}

    def relative(bound: float, data: np.ndarray) -> float:
        peak = finite_peak(data)
        return bound / peak if peak > 0 else (0.0 if bound == 0 else math.inf)

    e = result.elements
    if e is not None:
        springs = [x for x in model.elements if x.kind == "spring"]
        dampers = [x for x in model.elements if x.kind == "damper"]
        slope = [x.coef + (12 * x.k3 * X * X if x.law == "cubic" else 0.0) for x in springs]
        drag = [x.coef * (4 * V if x.law == "quadratic" else 1.0) for x in dampers]
        moved = [k * 2 * s * X for k in slope] + [c * 2 * s * V for c in drag]
        out["spring_force"] = relative(max(moved[:len(springs)], default=0.0), e.spring)
        out["damper_force"] = relative(max(moved[len(springs):], default=0.0), e.damper)
        contacts = 0.0  # what the contacts to the ground add to the reaction's error, N
        for name, forces, connects in (("friction_force", e.friction, e.friction_connects),
                                       ("stop_force", e.stop, e.stop_connects)):
            if forces is not None and forces.shape[1]:  # constraint forces, from x, v and the forces: n roundings
                out[name] = max(s, 8 * 2.0**-53) * (model.n + 2)
                contacts += sum(out[name] * float(np.max(np.abs(forces[:, j]))) for j, ends in enumerate(connects)
                                if GROUND in ends)
        for name in e.internal:
            out[f"internal/{name}"] = max(s, 8 * 2.0**-53) * (model.n + 2)
        grounded = [m for m, x in zip(moved, springs + dampers) if min(x.a, x.b) < 0]
        if not model.element_form:
            grounded = [2 * s * (np.abs(model.K).sum() * X + np.abs(model.C).sum() * V)]
        out["reaction"] = relative(sum(grounded) + contacts, e.reaction)
    energy = result.energy
    if energy is not None:
        # Every energy is measured by the largest the run reached (each data set's accuracy_scale), not by its own
        # peak: an input work that stays zero, or a residual at rounding, is known to that, not to its own digits.
        largest = energy.largest
        moved = 2 * s * largest
        off = float(np.max(np.abs(energy.residual), initial=0.0))  # the balance's quadrature and method error
        for name in energy.terms:
            bound = moved if name in ("kinetic", "strain", "contact") else moved + off
            out[name] = bound / largest if largest > 0 else 0.0
    return out


def acceleration_accuracy(M: np.ndarray, C: np.ndarray, K: np.ndarray, stated, x: np.ndarray, v: np.ndarray,
                          a: np.ndarray, f: np.ndarray) -> np.ndarray:
    """The stated accuracy of a = M^-1 (f - C v - K x), relative to its peak, from that of x and v.

    A stiff scene's K x and C v are large terms that cancel (1e4 N against an acceleration of 0.04 m/s^2 in the
    1e6:1 chain), so the acceleration is only as good as those terms' errors and roundings over its own size.
    One run: M, C, K (n, n) and x, v, a, f (N, n); a family: a leading member axis on all, stated (S,)."""
    if not isinstance(M, np.ndarray):  # a sparse scene's (one run, diagonal M): the norms row by row
        mass = M.diagonal()
        norms = [np.array([float((abs(A).sum(axis=1).A1 / mass).max())]) for A in (K, C, M)]
        M = np.ones((1, 1, 1))
    else:
        M, C, K = (np.asarray(A, dtype=float).reshape((-1,) + np.shape(A)[-2:]) for A in (M, C, K))
        norms = None
    S = M.shape[0]
    stated = np.broadcast_to(np.asarray(stated, dtype=float), (S,))

    def peak(q):  # largest finite |q| per member, in two passes without a temporary of q's size
        q = np.asarray(q, dtype=float).reshape(S, -1)
        top = np.fmax(np.fmax.reduce(q, axis=1, initial=-np.inf), -np.fmin.reduce(q, axis=1, initial=np.inf))
        for s in np.flatnonzero(np.isinf(top)):  # a member that overflowed: its finite part
            finite = np.abs(q[s][np.isfinite(q[s])])
            top[s] = finite.max(initial=0.0)
        return np.maximum(top, 0.0)

    peak_x, peak_v, peak_a, peak_f = (peak(q) for q in (x, v, a, f))
    norm = lambda A: np.abs(mass_solve(M, A)).sum(axis=2).max(axis=1)  # noqa: E731 (inf-norm of M^-1 A)
    if norms is None:
        norms = [norm(K), norm(C), norm(np.broadcast_to(np.eye(M.shape[-1]), M.shape))]
    k, c = norms[0], norms[1]
    forcing = norms[2] * peak_f
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):  # overflowing terms: an inf bound, not a warning
        carried = stated * (k * peak_x + c * peak_v)
        rounding = 4 * EPS * (k * peak_x + c * peak_v + forcing)
        derived = np.where(peak_a > 0, (carried + rounding) / peak_a, stated)
    return np.maximum(stated, derived)
