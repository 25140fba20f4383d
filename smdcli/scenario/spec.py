"""What a scenario is: frozen dataclasses and the limits they are read under.

Must not import: anything of smd but errors and the force shapes' names (the bottom of the scenario layer)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from smdcli.shapes.registry import FORCE_TYPES

GROUND = "ground"
# Output samples (time points x DOFs) one run may hold; beyond this the grid
# is refused before anything is allocated.
MAX_SAMPLES = 20_000_000
DEFAULT_POINTS = 1001


@dataclass(frozen=True)
class TimeSpec:
    """Output grid: from start to end, spaced by step, or `points` points."""

    start: float
    end: float
    step: float | None = None
    points: int | None = None


@dataclass(frozen=True)
class MassSpec:
    """A point mass [kg] with its initial displacement [m] and velocity [m/s]."""

    name: str
    m: float
    x0: float = 0.0
    v0: float = 0.0


@dataclass(frozen=True)
class ElementSpec:
    """A two-terminal element: a spring (coef = k [N/m]), a damper (coef = c [N s/m]), a friction contact or a
    stop (coef unused: their law holds their parameters)."""

    kind: str  # "spring" | "damper" | "friction" | "stop"
    index: int
    connects: tuple[str, str]
    coef: float
    law: str = "linear"  # spring: linear | cubic | a hysteretic law (smdcli.elements); damper: linear | quadratic
    k3: float = 0.0  # cubic spring coefficient [N/m^3]
    nonsmooth: Any = None  # the law (smdcli.elements) of a hysteretic spring, a [[friction]] or a [[stop]]

    @property
    def path(self) -> str:
        """Field path of this element in the scenario file."""
        return f"{self.kind}[{self.index}]"


@dataclass(frozen=True)
class MatrixSystem:
    """The book's matrix form: M, C, K given whole, inline (rows of numbers) or as files (CSR matrices)."""

    dofs: tuple[str, ...]
    M: Any  # tuple[tuple[float, ...], ...] inline; a scipy CSR matrix read from a file
    C: Any
    K: Any
    x0: tuple[float, ...]
    v0: tuple[float, ...]
    files: tuple[tuple[str, str, str], ...] = ()  # (M, C or K, the file's path, its sha256) for each file read

    @property
    def from_files(self) -> bool:
        """M, C and K were read from files (CSR), not written inline."""
        return not isinstance(self.M, tuple)

    def dense(self) -> tuple:
        """M, C and K as dense float arrays, however they were given."""
        import numpy as np

        return tuple(A.toarray() if self.from_files else np.array(A, dtype=float) for A in (self.M, self.C, self.K))


@dataclass(frozen=True)
class ForceSpec:
    """One applied force; the fields used depend on `type` (see DESIGN.md)."""

    index: int
    on: str
    type: str
    amplitude: float = 0.0
    omega: float | None = None  # rad/s, resolved from frequency or period
    phase: float = 0.0
    t0: float = 0.0
    duration: float | None = None
    shape: str = "rectangle"  # a pulse's
    duty: float = 0.5
    terms: int | None = None
    f0: float | None = None
    f1: float | None = None
    t1: float | None = None
    t: tuple[float, ...] = ()
    values: tuple[float, ...] = ()
    interpolation: str = "linear"
    expr: str | None = None
    file: str | None = None  # a table force's file, as resolved, and its text: the result keeps a copy
    file_text: str | None = None
    file_format: str | None = None  # how the file was read (record_files.FORMATS)
    file_units: str | None = None  # the unit the file names for its values (an AT2 or COSMOS record), else None

    @property
    def path(self) -> str:
        """Field path of this force (or of the ground motion's shape) in the scenario file."""
        return "ground_motion" if self.on == GROUND else f"force[{self.index}]"


GROUND_QUANTITIES = ("displacement", "velocity", "acceleration")
STANDARD_GRAVITY = 9.80665  # m/s^2 per g
# The units each ground-motion quantity may be given in, and their size in SI.
# Each is a known scaling of SI, accepted and converted: never read as a near spelling of another magnitude (cm/s^2
# is not "did you mean m/s^2?", a 100x error); gal (Gal) is cm/s^2, as seismological records use it.
GROUND_UNITS = {"displacement": {"m": 1.0, "cm": 0.01, "mm": 1e-3, "in": 0.0254, "ft": 0.3048},
                "velocity": {"m/s": 1.0, "cm/s": 0.01, "mm/s": 1e-3, "in/s": 0.0254, "ft/s": 0.3048},
                "acceleration": {"g": STANDARD_GRAVITY, "m/s^2": 1.0, "cm/s^2": 0.01, "mm/s^2": 1e-3, "gal": 0.01,
                                 "Gal": 0.01, "in/s^2": 0.0254, "ft/s^2": 0.3048}}


@dataclass(frozen=True)
class GroundMotionSpec:
    """[ground_motion]: one uniform motion of the support, the wall end of every element connected to ground.

    `shape` is a force shape (on = "ground") whose values are already in SI units: a table's `units`, `scale`
    and `shift` applied, an amplitude given in g converted."""

    quantity: str  # displacement | velocity | acceleration
    shape: ForceSpec
    units: str
    hold: bool = False  # a recorded acceleration held at its last value past its end, not ended there


@dataclass(frozen=True)
class DampingSpec:
    """[damping], added to the elements' (or [system]'s) C: Rayleigh alpha M + beta K (given as coefficients or
    through a ratio at two frequencies), or a damping ratio per mode."""

    alpha: float = 0.0  # 1/s
    beta: float = 0.0  # s
    modal: tuple[float, ...] = ()  # one ratio for every mode, or one per mode
    given: str = "alpha"  # the key the scenario gave first (alpha, beta, zeta or modal): what a message names


@dataclass(frozen=True)
class SolverSpec:
    """Requested method and tolerances; dt only for fixed-step methods."""

    method: str = "auto"
    rtol: float = 1e-6
    atol: float = 1e-9
    dt: float | None = None
    options: tuple[tuple[str, float | str], ...] = ()  # a method's own [solver] options (the registry's)


EXPECT_QUANTITIES = ("peak_displacement", "rms_displacement", "settling_time", "natural_frequency",
                     "energy_residual", "golden")
EXPECT_UNITS = {"peak_displacement": "m", "rms_displacement": "m", "settling_time": "s", "natural_frequency": "rad/s",
                "energy_residual": "1", "golden": "1"}


@dataclass(frozen=True)
class ExpectSpec:
    """One acceptance check of [[expect]]: a quantity of the run within min/max, or the run against a golden file."""

    index: int
    quantity: str
    dof: str | None = None
    mode: int = 1
    min: float | None = None
    max: float | None = None
    file: str | None = None  # golden: resolved against the scenario's folder
    rtol: float = 1e-9
    atol: float = 0.0

    @property
    def path(self) -> str:
        """The check's name in the scenario: expect[0]."""
        return f"expect[{self.index}]"


@dataclass(frozen=True)
class BuildingSpec:
    """[building]: the storeys of a chain of masses from the ground up, each mass's storey the one below it."""

    storey_heights: tuple[float, ...]  # m, one per mass of the chain
    masses: tuple[str, ...]  # the chain's masses, ground up (all masses in file order unless named)


@dataclass(frozen=True)
class Scenario:
    """A validated scenario file, frozen; variants are made with dataclasses.replace."""

    path: str
    text: str
    time: TimeSpec
    masses: tuple[MassSpec, ...] = ()
    springs: tuple[ElementSpec, ...] = ()
    dampers: tuple[ElementSpec, ...] = ()
    system: MatrixSystem | None = None
    forces: tuple[ForceSpec, ...] = ()
    solver: SolverSpec = field(default_factory=SolverSpec)
    title: str = ""
    description: str = ""
    sweep: tuple[tuple[str, Any], ...] = ()
    damping: DampingSpec | None = None
    ground_motion: GroundMotionSpec | None = None
    expect: tuple[ExpectSpec, ...] = ()
    frictions: tuple[ElementSpec, ...] = ()
    stops: tuple[ElementSpec, ...] = ()
    fit: tuple[tuple[str, Any], ...] = ()  # [fit]'s keys, read by `smd fit`
    optimize: tuple[tuple[str, Any], ...] = ()  # [optimize]'s keys, read by `smd optimize`
    building: BuildingSpec | None = None  # [building]: storey heights, for drifts, drift ratios and shears
    ida: tuple[tuple[str, Any], ...] = ()  # [ida]'s keys, read by `smd ida`

    @property
    def stem(self) -> str:
        """File name without folder and extension: the base of output names."""
        return Path(self.path).stem

    @property
    def dof_names(self) -> tuple[str, ...]:
        """Degree-of-freedom names in model order."""
        if self.system is not None:
            return self.system.dofs
        return tuple(m.name for m in self.masses)


# ---------------------------------------------------------------- reading
