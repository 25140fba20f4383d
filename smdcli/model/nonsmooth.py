"""The model's nonsmooth elements: hysteretic springs, friction contacts and stops, each a law (smdcli.elements)
on one row of the incidence: d = row . x (x_b - x_a, the ground's x being 0).

Must not import: solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from smdcli.elements import Law
from smdcli.scenario import GROUND, Scenario


@dataclass(frozen=True)
class NonsmoothElement:
    """One element: where it is in the scenario, its law, its row (d = row . x) and the belt under it."""

    path: str  # spring[2], friction[0], stop[1]
    kind: str  # spring | friction | stop
    law: Law
    connects: tuple[str, str]
    row: np.ndarray  # (n,): +1 at b, -1 at a
    belt: float = 0.0  # d' = row . v + belt: the ground end moving (a belt under the mass), m/s

    @property
    def law_label(self) -> str:
        """The law's name as the scenario writes it (elastoplastic, bouc_wen, coulomb, ...)."""
        return getattr(self.law, "law_name", self.law.name)

    @property
    def initial_stiffness(self) -> float:
        """The stiffness it has at rest (elastic), beyond what is stamped into K: for modes and [damping]."""
        law = self.law
        if self.kind != "spring":
            return 0.0
        return law.elastic_stiffness - law.linear_stiffness


def nonsmooth_elements(scenario: Scenario, dofs: tuple[str, ...]) -> tuple[NonsmoothElement, ...]:
    """Every hysteretic spring, friction contact and stop, in that order and in file order within each."""
    index = {name: i for i, name in enumerate(dofs)}
    n = len(dofs)
    found = []
    for spec in scenario.springs + scenario.frictions + scenario.stops:
        if spec.nonsmooth is None:
            continue
        a, b = spec.connects
        row = np.zeros(n)
        if b != GROUND:
            row[index[b]] += 1.0
        if a != GROUND:
            row[index[a]] -= 1.0
        belt = float(getattr(spec.nonsmooth, "belt_velocity", 0.0))
        # the ground end moving at the belt's speed: d = x_b - x_a gains +belt t if b is the ground, -belt t if a is
        sign = 1.0 if b == GROUND else -1.0 if a == GROUND else 0.0
        found.append(NonsmoothElement(spec.path, spec.kind, spec.nonsmooth, (a, b), row, sign * belt))
    return tuple(found)


def whole_tension(elements: tuple[NonsmoothElement, ...], tension, d) -> np.ndarray:
    """Each element's whole force from its law's tension and its deformation d (..., E): the law's part plus the
    linear part kept in K (a hysteretic spring's always-there stiffness), as the outputs store it."""
    linear = np.array([element.law.linear_stiffness for element in elements], dtype=float)
    return np.asarray(tension, dtype=float) + linear * np.asarray(d, dtype=float)


def initial_stiffness(K: np.ndarray, elements: tuple[NonsmoothElement, ...]) -> np.ndarray:
    """K with every hysteretic spring at its elastic stiffness: the scene at rest, as modes and [damping] see it."""
    extra = [e for e in elements if e.initial_stiffness]
    if not extra:
        return K
    K = K.copy()
    for e in extra:
        K += e.initial_stiffness * np.outer(e.row, e.row)
    return K


def check_initial_state(scenario: Scenario, elements: tuple[NonsmoothElement, ...], x0: np.ndarray) -> None:
    """The initial state within what every element can be in (Law.start_excess): a mass that starts past a rigid
    stop is an input error, not a run that passes through it."""
    from smdcli.errors import ScenarioError

    for e in elements:
        d = float(e.row @ x0)
        found = e.law.start_excess(d)
        if found is not None and found[0][0] > 1e-12 * max(found[1], 1e-300):
            raise ScenarioError(scenario.path, e.path, f"the initial state puts it {found[0][0]:.4g} past its limit "
                                f"(d = {d:.6g} m; {found[2]}): expected x0 within its limits")
