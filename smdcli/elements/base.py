"""What every nonsmooth element law answers: its TOML form, its force in each mode, the events that end a mode,
and what happens at them.

An element connects two nodes a and b; its deformation is d = x_b - x_a (the ground's x is 0, or moves with a
belt), its rate d' likewise, and its force is a tension T: it pushes a by +T and b by -T (as a spring's k d).

Between two events every law here is in one *mode* (elastic or yielding, stuck or slipping, free or in contact),
and in a mode its tension is a Piece: a stiffness and a damping added along d, a constant, or a constraint that
holds d (or d') where it is, the tension then being whatever keeps it there. A mode ends where a Guard's quantity
(d, d', or a held element's tension) crosses its level in its direction: the event. For a piecewise-linear law
every quantity is linear in the state, so a scene of such elements is linear between events and solved exactly
(smdcli.solvers.events.piecewise); a smooth law adds a nonlinear tension (and internal states) that integrators take.

Imports nothing of smd but errors (the bottom layer): the scenario reader, the model and the solvers consult it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, ClassVar

import numpy as np

# Guard quantities: the deformation, its rate, a held element's tension, or an internal variable ("internal:z").
D, RATE, TENSION = "d", "rate", "tension"
ON_SURFACE = 1e-12  # relative slack with which a point on a yield surface counts as on it (the solvers' TOUCH)
KINK = "kink"  # not an event: where a smooth law's right-hand side has a kink, an integrator restarts
# Event kinds, as /events/kind names them.
EVENT_KINDS = ("yield", "unload", "reload", "stick", "slip", "contact", "impact", "separation", "rest")
# No smooth tension: a mode linear in d and d'. A law with a smooth tension numbers its own code (its module's SMOOTH_*,
# evaluated in smdcli.kernels.rhs) and names it in its kernel_piece.
SMOOTH_NONE = 0
# The Newmark family's spring rows (smdcli.kernels.return_mapping): an elastic-perfectly-plastic core (k, fy),
# or a smooth hysteretic variable stepped by the trapezoidal rule (Bouc-Wen's z); a law gives its rows (newmark_rows).
NEWMARK_CORE, NEWMARK_SMOOTH_Z = range(2)


@dataclass(frozen=True)
class Guard:
    """The end of a mode: `quantity` crosses `level` going `direction` (+1 up, -1 down); `kind` names the event."""

    quantity: str
    level: float
    direction: int
    kind: str


@dataclass(frozen=True)
class Piece:
    """An element's tension in one mode: T = stiffness d + damping d' + constant, or held (a constraint)."""

    stiffness: float = 0.0
    damping: float = 0.0
    constant: float = 0.0
    held: bool = False  # d' = 0 (relative to a belt): the tension is the constraint's force
    nonlinear: Callable[[float, float, np.ndarray], float] | None = None  # T(d, d', internal) added, if smooth
    guards: tuple[Guard, ...] = ()


@dataclass(frozen=True)
class KernelPiece:
    """What a compiled kernel evaluates of a mode beyond its Piece: the smooth tension's code (SMOOTH_*) and
    parameters, and the power dissipated into energy `term`: pd d'^2 + pc d' + px d d' (+ the smooth tension's
    share)."""

    law: int = SMOOTH_NONE
    parameters: tuple[float, ...] = ()
    term: str = ""
    pd: float = 0.0
    pc: float = 0.0
    px: float = 0.0


@dataclass
class State:
    """An element's discrete mode and internal variables, carried from event to event."""

    mode: str
    internal: dict[str, float] = field(default_factory=dict)


class Law:
    """A nonsmooth element law. Subclasses are frozen dataclasses of their parameters."""

    table: ClassVar[str]  # the scenario table: spring, friction or stop
    name: ClassVar[str]  # the law as the scenario names it
    keys: ClassVar[tuple[str, ...]]  # the table's keys beyond connects (and law)
    piecewise_linear: ClassVar[bool] = True  # linear between events: solvable exactly
    ode_states: ClassVar[tuple[str, ...]] = ()  # internal variables with a differential equation (Bouc-Wen's z)
    internal_names: ClassVar[tuple[str, ...]] = ()  # what /elements writes per step (plastic_deformation, z)
    stiff: ClassVar[bool] = False  # its smooth tension can make a scene stiff: auto steps it implicitly
    units: ClassVar[dict[str, str]] = {}  # its keys' units, for sweeps' axes
    # keys its tension, internal rates and start are affine in (a smooth law's): one difference is their exact
    # derivative, where a sensitivity otherwise takes a five-point stencil of models
    affine_keys: ClassVar[tuple[str, ...]] = ()
    # its events' new internal variables affine in the state and old ones (a plastic deformation d - T / k): where
    # every law's are, a linear spring's k or damper's c moves the scene affinely, one difference its derivative
    affine_events: ClassVar[bool] = True
    holds_impulse: ClassVar[bool] = True  # held, it carries an impact's impulse (a bounded force cannot: friction)
    capacity: ClassVar[float | None] = None  # the most force it holds (a stuck contact's breakaway); None: unbounded

    arrays: ClassVar[tuple[str, ...]] = ()  # its keys given as arrays (one value per part)

    @property
    def elastic_stiffness(self) -> float:
        """The stiffness it has at rest, elastic: what modes, [damping] and the accuracy estimates see."""
        return float(getattr(self, "k", None) or 0.0)

    @property
    def linear_stiffness(self) -> float:
        """The part of the stiffness that is always there (a bilinear spring's b k): stamped into K."""
        return 0.0

    def unit_of(self, key: str) -> str:
        """The units of one of its keys (a sweep's axis)."""
        return self.units.get(key, "")

    def start(self, d: float, rate: float) -> State:
        """The mode at the start, from rest deformation and rate (internal variables at their initial values)."""
        raise NotImplementedError

    def piece(self, state: State) -> Piece:
        """The tension in the state's mode, and the guards that end it."""
        raise NotImplementedError

    def event(self, state: State, kind: str, d: float, rate: float, tension: float) -> State:
        """The state after an event of this element (kind from one of its guards)."""
        raise NotImplementedError

    def settle(self, state: State, d: float, rate: float, moving) -> tuple[State, str] | None:
        """The mode a spring takes at this instant, and the event kind, where it changes: on its yield surface and
        loading outward it yields, yielding and no longer loading it unloads; moving(sign) says whether d moves
        the sign's way now (by its rate, or from rest by its acceleration). None where nothing changes (and for
        contacts, whose stick and slip the solver decides together)."""
        return None

    def newmark_rows(self, d: float) -> list[tuple[int, tuple[float, ...], float]] | None:
        """The Newmark family's rows of this spring starting at deformation d: (NEWMARK_* code, parameters, the
        committed state), one row per part; None where the family cannot step it (contacts: their events)."""
        return None

    def tension(self, state: State, d: float, rate: float) -> float:
        """The tension in a mode that is not held, at d and d'."""
        piece = self.piece(state)
        value = piece.stiffness * d + piece.damping * rate + piece.constant
        if piece.nonlinear is not None:
            value += piece.nonlinear(d, rate, state.internal)
        return value

    def force_derivatives(self, state: State, d: float, rate: float) -> dict[str, float] | None:
        """d/dp of its whole force (linear_stiffness d + tension) for each of its parameters p (an array key's parts as
        key[i]; keys left unset omitted), at d and d' with the mode and internal variables held (their own
        derivatives are the state's). d' is the element's own rate, a belt's speed in it. None in a held mode
        (stuck, in rigid contact): its force is then the reaction the scene needs, not its own."""
        raise NotImplementedError

    def key_scale(self, key: str) -> float | None:
        """The scale over which its force changes with a key, where that is finer than the key's own size, or None:
        a stencil in the key steps in this scale (a belt's speed of 0.2 m/s under a regularization of 1e-3 m/s)."""
        return None

    def smooth_jacobian(self, state: State, d: float, rate: float) -> tuple[tuple, tuple] | None:
        """The derivatives of its smooth tension and of its ode_states' rates with respect to (d, d', q), q the
        ode_states: (2 + q numbers for the tension, q rows of 2 + q for the rates) at d, d' in this mode; what the
        sensitivity equations of a smooth scene integrate. None where the law has none (piecewise-linear laws: their
        sensitivities are event to event)."""
        return None

    def internal_values(self, state: State, d: float) -> tuple[float, ...]:
        """The internal variables /elements records, at deformation d in this state."""
        return ()

    def ode(self, state: State, d: float, rate: float) -> tuple[float, ...]:
        """Rates of the ode_states."""
        return ()

    def dissipation(self, state: State, d: float, rate: float, tension: float) -> tuple[str, float]:
        """(energy term, power) this element dissipates: hysteretic, friction, impact; ('', 0) if none."""
        return "", 0.0

    def jump(self, state: State, d_old: float, d_new: float) -> tuple[State, float]:
        """The state after d jumps from d_old to d_new at once (the ground's jump), and the energy dissipated on
        the way (none by default: the mode's decisions follow from the new state)."""
        return state, 0.0

    def kernel_piece(self, state: State) -> KernelPiece:
        """The mode's smooth tension and dissipated power as compiled kernels take them (none by default)."""
        return KernelPiece()

    @property
    def compiled(self) -> bool:
        """Whether compiled kernels can evaluate this law: linear between events, or its smooth tension named by a
        kernel code (kernel_piece); a law without one is refused by the compiled integrators, never dropped."""
        return self.piecewise_linear or type(self).kernel_piece is not Law.kernel_piece

    def stored(self, state: State, d: float) -> tuple[str, float]:
        """(energy term, energy) this element stores: strain for springs, contact for compliant stops."""
        return "", 0.0

    @property
    def dissipation_never_decreases(self) -> bool:
        """Whether the energy this law books as dissipated can only grow (its power never negative): what the
        run's check of its physics may hold it to."""
        return True

    def start_excess(self, d: float):
        """How far a start at deformation d lies outside anything the law can be in (a rigid stop passed), as
        excess gives it, or None: a spring deformed past yield starts on its surface, a contact stuck or slipping."""
        return None

    def warning(self) -> str | None:
        """A line on parameters that are accepted but ask for care (a hysteresis that is not bounded), or None."""
        return None

    def excess(self, d, rate, tension):
        """How far each sample (arrays d, d', T along a run) lies outside what the law allows, >= 0 where it does
        (a stuck contact holding more than its breakaway, a yield surface passed, a rigid stop passed), with the
        scale it is measured by and what the law says: (excess, scale, rule); None where the law bounds nothing."""
        return None
