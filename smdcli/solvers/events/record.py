"""What an exact event-driven run records, a whole batch of output steps at a time: the energy each term gains
over a step of the flow (Gauss-Legendre on the exact flow, exact for the quadratic powers of a linear flow), and
the state, forces, internal variables and energies at the output points.

A piecewise-linear scene has no internal ODE states, so every quantity is linear (or quadratic) in z and is
evaluated for many points by one matrix product.

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import numpy as np

from smdcli.model.nonsmooth import whole_tension
from smdcli.result import NonsmoothHistory
from smdcli.solvers.exact.flow import WEIGHTS, Flow
from smdcli.solvers.events.scene import Mode


def step_integrals(run, flow: Flow, mode: Mode, states, Z0: np.ndarray, h: float,
                   keep: bool) -> dict[str, np.ndarray]:
    """The energy each term gains over [0, h] of the flow from each row of Z0 (m, s): term -> (m,)."""
    scene, n, model = run.scene, run.n, run.model
    Z = flow.gauss_states(Z0, mode.b, h, keep)  # (m, G, s)
    w = WEIGHTS * h
    v = Z[..., n:2 * n]
    out = {}
    if run.damped:
        out["dissipated"] = ((v @ model.C) * v).sum(axis=-1) @ w
    work = np.zeros(len(Z0))
    if scene.blocks:
        force = np.zeros_like(v)
        for (lo, hi, _, exo), column in zip(scene.blocks, model.B.T):
            force += (Z[..., lo:hi] @ exo.g)[..., None] * column
        work += np.einsum("mgi,mgi->mg", force, v) @ w
    rate = Z @ mode.rate_rows.T + scene.belts
    tension = Z @ mode.tension_rows.T + mode.tension_const
    if scene.belts.any():  # a belt under a contact does work on it: T times the belt's share of d'
        work += (tension @ scene.belts) @ w
    out["input"] = work
    d = Z @ mode.d_rows.T
    for e, (element, state) in enumerate(zip(scene.elements, states)):
        term, power = element.law.dissipation(state, d[..., e], rate[..., e], tension[..., e])
        if term:
            out[term] = out.get(term, 0.0) + (power @ w if np.ndim(power) else np.full(len(Z0), power * w.sum()))
    return out


def stored_energies(run, states, Z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(kinetic, strain, contact) at each row of Z (m, s): the linear springs' and the elements' own (their internal
    variables, if Z carries them, row by row)."""
    n, model, scene = run.n, run.model, run.scene
    x, v = Z[:, :n], Z[:, n:2 * n]
    kinetic = 0.5 * ((v @ model.M) * v).sum(axis=1)
    strain = 0.5 * ((x @ model.K) * x).sum(axis=1)
    if model.cubic is not None:
        strain = strain + (0.25 * model.cubic.coef * (x @ model.cubic.D.T) ** 4).sum(axis=1)
    contact = np.zeros(len(Z))
    d = x @ scene.R.T
    for e, (element, state) in enumerate(zip(scene.elements, scene.live(states, Z))):
        term, value = element.law.stored(state, d[:, e])
        if term == "strain":
            strain = strain + value
        elif term == "contact":
            contact = contact + value
    return kinetic, strain, contact


class Outputs:
    """What the run records at each output point."""

    def __init__(self, run, grid: np.ndarray):
        self.run = run
        N, n, E = len(grid), run.n, run.scene.E
        self.x, self.v, self.a = np.empty((N, n)), np.empty((N, n)), np.empty((N, n))
        self.tension = np.empty((N, E))
        self.internal = {}
        for element in run.scene.elements:
            for name in element.law.internal_names:
                self.internal[f"{element.path}.{name}"] = np.empty(N)
        self.energy = {name: np.empty(N) for name in run.energy_terms + ("kinetic", "strain", "contact")}

    def store(self, k: int, z: np.ndarray, states) -> None:
        """Output point k at z."""
        self.store_many(k, z[None], states, {name: np.array([value]) for name, value in self.run.cumulative.items()})

    def store_many(self, k: int, Z: np.ndarray, states, cumulative: dict[str, np.ndarray], mode: Mode | None = None):
        """Output points k, k + 1, ... at the rows of Z, all in one mode (the states', where the caller has it not);
        `cumulative` each term's integral there."""
        run = self.run
        scene, n = run.scene, run.n
        mode = scene.mode(states) if mode is None else mode
        rows = slice(k, k + len(Z))
        self.x[rows], self.v[rows] = Z[:, :n], Z[:, n:2 * n]
        run.v_scale = max(run.v_scale, float(np.abs(Z[:, n:2 * n]).max(initial=0.0)))
        self.a[rows] = Z @ mode.acceleration_rows.T + mode.acceleration_const
        d = Z @ mode.d_rows.T
        self.tension[rows] = whole_tension(scene.elements, Z @ mode.tension_rows.T + mode.tension_const, d)
        for e, (element, state) in enumerate(zip(scene.elements, states)):
            law = element.law
            for name, value in zip(law.internal_names, law.internal_values(state, d[:, e])):
                self.internal[f"{element.path}.{name}"][rows] = value
        kinetic, strain, contact = stored_energies(run, states, Z)
        self.energy["kinetic"][rows], self.energy["strain"][rows], self.energy["contact"][rows] = \
            kinetic, strain, contact
        for name in run.energy_terms:
            self.energy[name][rows] = cumulative[name]

    def finish(self):
        """x, v, a and the elements' history."""
        run = self.run
        paths = tuple(e.path for e in run.scene.elements)
        kinds = tuple(e.kind for e in run.scene.elements)
        history = NonsmoothHistory(paths, kinds, self.tension, self.internal, tuple(run.events), self.energy,
                                   **run.event_arrays())
        return self.x, self.v, self.a, history
