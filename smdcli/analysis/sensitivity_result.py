"""The result of `smd sensitivity`: a scene's response and its derivatives with respect to P parameters, and the
quantities derived from them on request (an element's tension, the support's acceleration).

Must not import: io, plots, commands, cli.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

QUANTITIES = {"displacement": "m", "velocity": "m/s", "acceleration": "m/s^2"}
METHOD = ("exact: the scene and its sensitivity equations (the same M, C and K driven by -dM x'' - dC x' - dK x + "
          "B du/dp) solved together by the matrix exponential; the model's derivatives taken on the assembled model "
          "(one difference where every number of the model is affine in the parameter, else a five-point stencil, "
          "exact for polynomials of degree 4: every matrix, initial state and force generator of a linear scene)")


@dataclass
class Sensitivity:
    """A scene's response and its derivatives with respect to P parameters (per unit of each)."""

    scenario: str
    parameter: tuple[str, ...]
    value: np.ndarray  # (P,) the nominal values
    parameter_units: tuple[str, ...]
    time: np.ndarray
    dof: tuple[str, ...]
    displacement: np.ndarray  # (N, n)
    velocity: np.ndarray
    acceleration: np.ndarray
    d_displacement: np.ndarray  # (P, N, n)
    d_velocity: np.ndarray
    d_acceleration: np.ndarray
    peak_displacement: np.ndarray  # (n,)
    peak_time: np.ndarray  # (n,)
    d_peak_displacement: np.ndarray  # (P, n)
    accuracy: dict[str, np.ndarray]  # per data set, (P,): stated error relative to the parameter's largest value
    method: str = METHOD
    model_error: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (P,) the stencil's estimated error
    wall_time_s: float = 0.0
    forward_time_s: float = 0.0  # a forward run of the scene (sensitivity_cost.forward_time), for the comparison
    notes: tuple[str, ...] = ()
    outputs: list[Path] = field(default_factory=list)
    model: object = None  # the scene's Model
    derivatives: list = field(default_factory=list)  # model_derivative.Derivative per parameter
    event_times: np.ndarray = field(default_factory=lambda: np.zeros(0))  # where the solution is not smooth
    exact_at: Callable | None = None  # t -> (P, n) d_displacement at any time, on the exact flow (event runs)
    # t -> ((2n,) x and v, (P, 2n) their derivatives) at any time, on the exact flow (event runs)
    exact_state_at: Callable | None = None
    # an event run's checkpoints (its start, each event and each break): (t, the nonsmooth elements' states, each
    # element's internal variables' derivatives {name: (P,)}, per unit of each parameter)
    law_states: list = field(default_factory=list)
    # (t, left) -> (a, a', d a/dp, d a'/dp): the relative acceleration and its rate (n,), their derivatives (P, n),
    # at any time on the exact flow (event runs), right limits or (left) before an event at t
    exact_rates_at: Callable | None = None
    # (t, left) -> (a, d a/dp): the relative acceleration (n,) and its derivatives (P, n) at any time on a smooth
    # run's dense output; its attribute breaks: where the integration restarted (a kink, a force's break)
    dense_acceleration_at: Callable | None = None
    event_moves: dict = field(default_factory=dict)  # each event's time -> (P,) dt*/dp: how it moves (event runs)
    # path -> a hysteretic spring's, friction contact's or stop's tension (N,) and its derivatives (P, N) (event runs)
    law_tensions: Callable | None = None

    def ground_acceleration(self, times=None, rate: bool = False) -> tuple[np.ndarray, np.ndarray] | None:
        """The support's acceleration at times (the grid by default) (N,) and its derivative (P, N), or None without
        support motion: what turns the relative acceleration into the absolute one an accelerometer reads. With
        rate, its time derivative (right limits; None where the motion has none)."""
        if self.model is None or self.model.ground is None:
            return None
        from smdcli.model.system import GROUND_DOF

        ground = [j for j, dof in enumerate(self.model.force_dofs) if dof == GROUND_DOF]
        at = self.time if times is None else np.asarray(times, dtype=float)

        def of(model):
            signals = [model.signals[j] for j in ground]
            if rate:
                signals = [signal.derivative(float(self.time[0])) for signal in signals]
                if any(signal is None for signal in signals):
                    raise NotImplementedError
            return sum(np.broadcast_to(signal.value(at), at.shape) for signal in signals)
        try:
            return of(self.model), np.array([d.of(of) for d in self.derivatives]).reshape(len(self.derivatives), -1)
        except NotImplementedError:
            return None

    def element_tension(self, path: str) -> tuple[np.ndarray, np.ndarray]:
        """An element's tension on the grid (N,) and its derivative (P, N): a linear, cubic or quadratic spring or
        damper (a law of x and v alone; T = c d, k d + k3 d^3 or c |d| d of its stretch or stretch rate d = q_b - q_a),
        its derivative the law's own at the state plus its tangent times d's; a law with a history (a hysteretic
        spring, a friction contact, a stop) from the run's own, where it gives them (law_tensions)."""
        from smdcli.analysis.forces import element_forces, element_stretch, law_slope

        if any(e.path == path for e in self.model.nonsmooth):
            if self.law_tensions is None:
                raise NotImplementedError(f"{path}: this run kept no tensions of its laws (a linear scene has none)")
            return self.law_tensions(path)

        def tension(model):  # at the scene's state, of the model as given (a parameter moved in it, or not)
            return element_forces(model, self.displacement, self.velocity).tension(path)

        nominal = tension(self.model)  # KeyError where no spring or damper has the name
        element = next(e for e in self.model.elements if e.name == path)
        own, d_own = ((self.displacement, self.d_displacement) if element.kind == "spring" else
                      (self.velocity, self.d_velocity))
        slope = law_slope(element, element_stretch(element, own))
        derived = [at.of(tension) + slope * element_stretch(element, s) for at, s in zip(self.derivatives, d_own)]
        return nominal, np.array(derived).reshape(len(self.derivatives), -1)

    def units(self, quantity: str) -> tuple[str, ...]:
        """The units of d_<quantity>, one per parameter: m/(N/m), m/kg, ..."""
        return tuple(derivative_units(QUANTITIES[quantity], u) for u in self.parameter_units)


def derivative_units(of: str, parameter: str) -> str:
    """The units of d(of)/d(parameter): m/(N/m), m/kg, m for a dimensionless parameter."""
    if parameter in ("", "1"):
        return of
    return f"{of}/({parameter})" if any(c in parameter for c in "/*^ ") else f"{of}/{parameter}"
