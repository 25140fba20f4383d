"""The springs and dampers of a scene as the model uses them: node indices, laws, incidence rows.

Sign: an element connecting [a, b] carries the tension T = law(x_b - x_a) (the ground's motion is 0 in the
relative coordinates of a support-motion run); it pushes a by +T and b by -T, so a stretched element pulls its
ends together. The forces of a solved run are smdcli.analysis.forces.

Must not import: solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from smdcli.scenario import GROUND, Scenario


@dataclass(frozen=True)
class Incidence:
    """Nonlinear elements of one law: rows of D (+1 on the first node, -1 on the second) and coefficients."""

    D: np.ndarray  # (n_elements, n)
    coef: np.ndarray  # (n_elements,)
    paths: tuple[str, ...]

    def __len__(self) -> int:
        return len(self.coef)


@dataclass(frozen=True)
class Element:
    """One two-terminal element as the model uses it: node indices (-1 for the ground) and its law."""

    kind: str  # spring | damper
    name: str  # spring[0], damper[2]: its path in the scenario
    connects: tuple[str, str]
    a: int
    b: int
    coef: float  # k or c
    law: str  # linear | cubic | quadratic
    k3: float = 0.0


def elements_of(scenario: Scenario, dofs: tuple[str, ...]) -> tuple[Element, ...]:
    """The scenario's springs and dampers in file order (none for a [system] scene)."""
    index = {name: i for i, name in enumerate(dofs)} | {GROUND: -1}
    return tuple(Element(e.kind, f"{e.kind}[{e.index}]", tuple(e.connects), index[e.connects[0]],
                         index[e.connects[1]], float(e.coef), e.law, float(e.k3))
                 for e in scenario.springs + scenario.dampers)


def incidence_row(connects: tuple[str, str], index: dict[str, int], n: int) -> np.ndarray:
    """A row of D: +1 on the first node, -1 on the second, nothing for the ground."""
    row = np.zeros(n)
    a, b = connects
    if a != GROUND:
        row[index[a]] += 1.0
    if b != GROUND:
        row[index[b]] -= 1.0
    return row


def incidence(rows) -> Incidence | None:
    """The Incidence of (row, coefficient, path) triples, or None for none."""
    if not rows:
        return None
    return Incidence(
        D=np.array([r for r, _, _ in rows]),
        coef=np.array([c for _, c, _ in rows], dtype=float),
        paths=tuple(p for _, _, p in rows),
    )


def incidence_matrix(elements, n: int):
    """D with D x = x_a - x_b for each element's ends (a, b) in order, the ground's end left out: dense where small
    or more than a tenth full, else CSR (sparse.cheapest's rule; built without scipy.sparse where dense, whose
    import is most of a small scene's start-up)."""
    a, b = (np.array([getattr(e, end) for e in elements], dtype=int) for end in ("a", "b"))
    index = np.arange(len(elements))
    rows, columns = np.concatenate([index[a >= 0], index[b >= 0]]), np.concatenate([a[a >= 0], b[b >= 0]])
    signs = np.concatenate([np.ones(np.count_nonzero(a >= 0)), -np.ones(np.count_nonzero(b >= 0))])
    if len(elements) < 64 or len(rows) > (len(elements) * n) // 10:
        D = np.zeros((len(elements), n))
        np.add.at(D, (rows, columns), signs)
        return D
    from scipy.sparse import coo_matrix

    return coo_matrix((signs, (rows, columns)), shape=(len(elements), n)).tocsr()
