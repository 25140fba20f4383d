"""Result of one solve: time-major arrays, labels, statistics. Writers only read it.

Imports nothing of smd (the bottom layer).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np


@dataclass(frozen=True)
class SolverStats:
    """What a solve cost and how it went; -1 where a method does not report a count."""

    method: str
    requested_method: str
    reason: str
    rtol: float | None = None
    atol: float | None = None
    dt: float | None = None
    nfev: int = 0
    njev: int = 0
    nlu: int = 0
    steps_accepted: int = 0
    steps_rejected: int = 0
    wall_time_s: float = 0.0
    success: bool = True
    message: str = "ok"
    # The largest error of the trajectories this run vouches for, relative to each quantity's peak: rounding
    # for exact methods, the tolerances for adaptive ones, the step's truncation for fixed-step ones.
    stated_accuracy: float = float("nan")
    # Why the run's numbers break its own physics (analysis.guards), "; "-joined; "" where they hold
    suspect: str = ""

    def as_attrs(self) -> dict:
        """Flat attributes for HDF5 and JSON; None becomes NaN (tolerances) or -1."""
        out = {}
        for key, value in self.__dict__.items():
            if value is None:
                value = float("nan")
            out[key] = value
        return out


@dataclass(frozen=True)
class GroundHistory:
    """The support's displacement, velocity and acceleration on the output grid, (N,) each (impulses left out)."""

    displacement: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    given: str = "acceleration"  # the quantity the scenario gave
    integrated_accuracy: float = 0.0  # stated accuracy of what was integrated from rest (relative to its peak)


@dataclass(frozen=True)
class NonsmoothHistory:
    """The nonsmooth elements along a run (hysteretic springs, friction contacts, stops): each one's tension on
    the grid (N, E), its internal variables ("spring[0].plastic_deformation" -> (N,)), the events (time, element,
    kind), each event's state, and the energy terms they bring: hysteretic, friction, impact (cumulative), contact
    (stored)."""

    paths: tuple[str, ...]
    kinds: tuple[str, ...]  # spring | friction | stop
    tension: np.ndarray  # (N, E), positive in tension; a hysteretic spring's whole force (its linear part too)
    internal: dict[str, np.ndarray]
    events: tuple[tuple[float, str, str], ...]
    energy: dict[str, np.ndarray]  # per term, (N,): as the solver integrated them on its own pieces
    # the state at each event as its solver located it: x and v (events, n), each element's tension (events, E);
    # None where the method does not locate events (the Newmark family's return mapping)
    event_x: np.ndarray | None = None
    event_v: np.ndarray | None = None
    event_tension: np.ndarray | None = None
    event_v_before: np.ndarray | None = None  # v just before each event: an impact's jump from it to event_v

    def event_state(self):
        """(times, x, v, tension) of the events with their states (empty arrays where none were located)."""
        if self.event_x is None or not len(self.events):
            E = len(self.paths)
            return np.zeros(0), np.zeros((0, 0)), np.zeros((0, 0)), np.zeros((0, E))
        return np.array([t for t, _, _ in self.events], dtype=float), self.event_x, self.event_v, self.event_tension

    def balance(self) -> Energy:
        """The run's energy balance from the terms its solver integrated: stored (kinetic, strain, contact) less its
        start, plus everything dissipated or lost, less the work put in."""
        e = self.energy
        stored = e["kinetic"] + e["strain"] + e["contact"]
        residual = stored - stored[0] + e["dissipated"] + e["hysteretic"] + e["friction"] + e["impact"] - e["input"]
        energy = Energy(e["kinetic"], e["strain"], e["dissipated"], e["input"], residual, 0.0,
                        e.get("quadrature", "8-point Gauss-Legendre on the exact flow between events"),
                        hysteretic=e["hysteretic"], friction=e["friction"], impact=e["impact"], contact=e["contact"])
        reached = energy.largest
        worst = float(np.max(np.abs(residual), initial=0.0))
        return replace(energy, max_relative_residual=worst / reached if reached > 0 else 0.0)


@dataclass(frozen=True)
class ElementForces:
    """Force in each spring and damper, (N, elements), positive in tension (an element on [a, b] pulls a toward b),
    and the ground's reaction on the system, (N,); a matrix scene has no elements, only the reaction."""

    spring: np.ndarray
    damper: np.ndarray
    spring_names: tuple[str, ...]
    damper_names: tuple[str, ...]
    spring_connects: tuple[tuple[str, str], ...]
    damper_connects: tuple[tuple[str, str], ...]
    reaction: np.ndarray
    reaction_meaning: str
    added_damping: np.ndarray | None = None  # (N, n): the force of [damping]'s C on each DOF, not an element's
    element_form: bool = True
    friction: np.ndarray | None = None  # (N, frictions): each contact's force, tension positive
    friction_names: tuple[str, ...] = ()
    friction_connects: tuple[tuple[str, str], ...] = ()
    stop: np.ndarray | None = None  # (N, stops): each stop's contact force (0 while free)
    stop_names: tuple[str, ...] = ()
    stop_connects: tuple[tuple[str, str], ...] = ()
    internal: dict = field(default_factory=dict)  # "spring[0].plastic_deformation" -> (N,): hysteretic variables

    def tension(self, name: str) -> np.ndarray:
        """An element's tension (N,) by its name (spring[0], damper[1], friction[0], stop[0]); KeyError where none has
        it."""
        for names, table in ((self.spring_names, self.spring), (self.damper_names, self.damper),
                             (self.friction_names, self.friction), (self.stop_names, self.stop)):
            if name in names:
                return table[:, names.index(name)]
        raise KeyError(name)


@dataclass(frozen=True)
class Energy:
    """The energy balance on the output grid, (N,) each, J: kinetic + strain - initial + dissipated - input = residual."""

    kinetic: np.ndarray
    strain: np.ndarray
    dissipated: np.ndarray  # cumulative
    input: np.ndarray  # cumulative work of the applied forces (and the ground's motion)
    residual: np.ndarray
    max_relative_residual: float  # largest |residual| over the largest energy reached
    quadrature: str  # how dissipated and input were integrated
    # with nonsmooth elements (None otherwise): dissipated by yielding (and Bouc-Wen loops), by friction, lost at
    # impacts (and in compliant stops' dampers), all cumulative; stored in compliant stops
    hysteretic: np.ndarray | None = None
    friction: np.ndarray | None = None
    impact: np.ndarray | None = None
    contact: np.ndarray | None = None

    @property
    def largest(self) -> float:
        """The largest energy the run reached, J: what the residual is measured by."""
        losses = [q for q in (self.hysteretic, self.friction, self.impact) if q is not None]
        stored = self.strain + (self.contact if self.contact is not None else 0.0)
        return max(largest_energy(self.kinetic, stored, self.dissipated, self.input),
                   *(float(np.max(np.abs(q), initial=0.0)) for q in losses), 0.0)

    @property
    def terms(self) -> tuple[str, ...]:
        """The terms this balance holds: the five of every run, and the nonsmooth ones where there are any."""
        return ENERGY_TERMS + tuple(name for name in NONSMOOTH_TERMS if getattr(self, name) is not None)

    def to_dict(self) -> dict:
        """The time series as lists and the figure of merit, for JSON."""
        return {name: getattr(self, name).tolist() for name in self.terms} | {
            "max_relative_residual": self.max_relative_residual, "quadrature": self.quadrature}


ENERGY_TERMS = ("kinetic", "strain", "dissipated", "input", "residual")
NONSMOOTH_TERMS = ("hysteretic", "friction", "impact", "contact")


def finite_peak(q: np.ndarray, known: tuple[float, float] | None = None) -> float:
    """The largest finite |q| (0 for none), without a temporary of q's size where every entry is finite; known: q's
    extremes, where the caller has them."""
    low, high = known or extremes(q)
    if all_finite(q, (low, high)):
        return max(high, -low)
    return float(np.abs(q[np.isfinite(q)]).max(initial=0.0))


def extremes(q: np.ndarray) -> tuple[float, float]:
    """(min, max) of q, (0, 0) for none: a NaN or an inf in q makes one of them so."""
    return (float(np.min(q)), float(np.max(q))) if q.size else (0.0, 0.0)


AT_REST_VALUES = 2 ** 20  # values of a run's histories from which its columns at rest are looked for


def moving_columns(*histories: np.ndarray) -> np.ndarray | None:
    """The columns of (N, n) histories that are not 0 at every row of every one, where the others (at rest
    throughout: DOFs a wave has not reached) are most of many; None where they are not, or the histories are small,
    so that a caller works on every column as it is."""
    N, n = histories[0].shape
    if n < 64 or N * n < AT_REST_VALUES:
        return None
    moving = np.flatnonzero(np.logical_or.reduce([np.any(q != 0, axis=0) for q in histories]))
    return moving if len(moving) <= n // 2 else None


def all_finite(q: np.ndarray, known: tuple[float, float] | None = None) -> bool:
    """Every entry of q finite (a NaN or an inf makes its minimum or maximum one); known: q's extremes, where the
    caller has them."""
    return all(map(math.isfinite, known or extremes(q)))


def largest_energy(kinetic, strain, dissipated, work) -> float:
    """The largest energy a run reached: mechanical, dissipated or put in; what the residual is measured by."""
    return max(float(np.max(kinetic + strain, initial=0.0)), float(np.max(np.abs(dissipated), initial=0.0)),
               float(np.max(np.abs(work), initial=0.0)))


class OnFirstRead:
    """A dataclass field that may be given a function of no arguments instead of its value: the function is called
    where the field is first read, and its value kept. For an array few readers need: the applied force on every DOF,
    8 MB for 1,000 DOFs over 1,001 points, is a tenth of a Taylor run of the 1,000-mass chain, and a run read for its
    motion alone never needs it."""

    def __set_name__(self, owner, name):
        self.name = name

    def __get__(self, obj, owner=None):
        if obj is None:
            raise AttributeError(self.name)  # the class has no default for it: dataclass makes the field required
        value = obj.__dict__[self.name]
        if callable(value):
            value = obj.__dict__[self.name] = value()
        return value

    def __set__(self, obj, value):
        obj.__dict__[self.name] = value


@dataclass(frozen=True)
class Result:
    """Trajectories on the output grid, (N, n) each, SI units, with the cost of getting them."""

    time: np.ndarray
    dofs: tuple[str, ...]
    displacement: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    force: np.ndarray = OnFirstRead()  # applied, on each DOF; a solver may give the function that computes it
    stats: SolverStats
    t_failed: float | None = None  # where a failed run stopped
    notes: tuple[str, ...] = field(default=())
    ground: GroundHistory | None = None  # with support motion: displacement, velocity, acceleration are relative
    elements: ElementForces | None = None  # attached after a successful run (analysis.energy.with_physics)
    energy: Energy | None = None
    nonsmooth: NonsmoothHistory | None = None  # a scene with hysteretic springs, friction or stops: their history
    origin: tuple | None = field(default=None, repr=False, compare=False)  # (Scenario, Model) it was solved from
    # times -> (x, v) from the run's own method (an adaptive one's interpolant), for quadratures between outputs
    interpolant: Any = field(default=None, repr=False, compare=False)
    # ((array, (min, max)), ...): extremes a solver found as it wrote the arrays (extremes_of), so that the checks
    # after a run need not pass over them again
    found_extremes: tuple = field(default=(), repr=False, compare=False)
    storeys: Any = None  # analysis.storeys.Storeys of a successful run of a scene with [building]
    # (n,) each DOF's largest |absolute acceleration| located on the solution, where the solver located it (the
    # compiled kernel of a yielding frame's runs), else None: read at the samples
    located_acceleration: np.ndarray | None = None

    def changed(self, **changes) -> Result:
        """This result with some fields changed, as dataclasses.replace, without computing a field not yet read
        (OnFirstRead)."""
        unknown = set(changes) - {f.name for f in fields(self)}
        if unknown:
            raise TypeError(f"Result has no field {', '.join(sorted(unknown))}")
        new = object.__new__(type(self))
        new.__dict__.update(self.__dict__, **changes)
        return new

    def __getstate__(self):
        self.force  # noqa: B018  (computed, so that a pickle holds no function)
        return self.__dict__

    def with_events(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(t, x, v) of the samples with each located event's state merged in time order, an impact as its jump
        (the velocity before it, then after, at one position): what a phase portrait draws, whose samples alone
        cut a stick's corner or an impact's jump."""
        if self.nonsmooth is None or self.nonsmooth.event_x is None or not len(self.nonsmooth.events):
            return self.time, self.displacement, self.velocity
        t_event, x_event, v_event, _ = self.nonsmooth.event_state()
        if self.nonsmooth.event_v_before is not None:
            t_event, x_event = np.repeat(t_event, 2), np.repeat(x_event, 2, axis=0)
            v_event = np.stack([self.nonsmooth.event_v_before, v_event], axis=1).reshape(-1, v_event.shape[1])
        return merged(self.time, (self.displacement, self.velocity), t_event, (x_event, v_event))

    def absolute(self, quantity: str) -> np.ndarray:
        """displacement, velocity or acceleration measured from the fixed frame: relative plus the ground's."""
        relative = getattr(self, quantity)
        return relative if self.ground is None else relative + getattr(self.ground, quantity)[:, None]

    def extremes_of(self, quantity: str) -> tuple[float, float]:
        """(min, max) of one of the arrays (extremes): what the solver found as it wrote it, where it did and the array
        is still the one it wrote, else one pass over it."""
        q = getattr(self, quantity)
        for array, found in self.found_extremes:
            if array is q:
                return found
        return extremes(q)

    @property
    def success(self) -> bool:
        """Whether the solver reached the end time."""
        return self.stats.success

    def to_dict(self) -> dict:
        """Plain data (lists, numbers, strings) for JSON or a DataFrame: grid, trajectories, statistics and the
        elements and energy where attached."""
        out = {"time": self.time.tolist(), "dofs": list(self.dofs)}
        for name in ("displacement", "velocity", "acceleration", "force"):
            out[name] = getattr(self, name).tolist()
        out["stats"] = self.stats.as_attrs()
        out["notes"] = list(self.notes)
        if self.ground is not None:
            out["ground"] = {name: getattr(self.ground, name).tolist()
                             for name in ("displacement", "velocity", "acceleration")}
        if self.elements is not None:
            e = self.elements
            out["elements"] = {"spring_force": e.spring.tolist(), "damper_force": e.damper.tolist(),
                               "springs": list(e.spring_names), "dampers": list(e.damper_names),
                               "reaction": e.reaction.tolist()}
        if self.energy is not None:
            out["energy"] = self.energy.to_dict()
        return out

    def peak_displacement(self) -> np.ndarray:
        """Largest |x| per DOF over the finite part of the run."""
        x = np.where(np.isfinite(self.displacement), np.abs(self.displacement), 0.0)
        return x.max(axis=0) if len(x) else np.zeros(len(self.dofs))


def merged(time: np.ndarray, samples: tuple, t_event: np.ndarray, at_events: tuple) -> tuple:
    """(time, *samples) with the events' values merged in time order (an event at a sample's time after it)."""
    if not len(t_event):
        return (time, *samples)
    order = np.argsort(np.concatenate([time, t_event]), kind="stable")
    return (np.concatenate([time, t_event])[order],
            *(np.concatenate([a, b])[order] for a, b in zip(samples, at_events)))
