"""Each law's force_derivatives against central differences of its own force: the law rebuilt with one parameter
moved, the mode and internal variables held (the Law interface's promise for the sensitivities that build on it)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from smdcli.elements.bouc_wen import BoucWen
from smdcli.elements.clough import Clough
from smdcli.elements.elastoplastic import Bilinear, Elastoplastic
from smdcli.elements.friction import Friction
from smdcli.elements.iwan import Iwan
from smdcli.elements.registry import SPRING_LAWS, TABLES
from smdcli.elements.stop import Stop


def whole_force(law, state, d, rate) -> float:
    """What the element exerts: the part stamped into K and the tension of its mode."""
    return law.linear_stiffness * d + law.tension(state, d, rate)


def moved(law, key: str, value: float):
    """The law with one parameter (or one part of an array parameter, key[i]) set to value."""
    if "[" in key:
        name, index = key[:-1].split("[")
        parts = list(getattr(law, name))
        parts[int(index)] = value
        return dataclasses.replace(law, **{name: tuple(parts)})
    return dataclasses.replace(law, **{key: value})


def value_of(law, key: str) -> float:
    if "[" in key:
        name, index = key[:-1].split("[")
        return getattr(law, name)[int(index)]
    return getattr(law, key)


def central(law, key, state, d, rate) -> float:
    """Richardson's extrapolation of two central differences: error O(h^4) of the force's fifth derivative."""
    p = value_of(law, key)
    h = 1e-4 * max(abs(p), 1e-3)
    f = lambda step: (whole_force(moved(law, key, p + step), state, d, rate)  # noqa: E731
                      - whole_force(moved(law, key, p - step), state, d, rate)) / (2 * step)
    return (4 * f(h / 2) - f(h)) / 3


def states_of(law, rng):
    """The modes a law reaches from the start at deformations and rates across its range, and from its events."""
    scale = 3 * max(np.atleast_1d(getattr(law, "fy", 1.0))) / max(np.atleast_1d(getattr(law, "k", None) or 1.0))
    found = [(law.start(0.0, 0.0), 0.0, 0.0)]  # at rest: a friction contact stuck
    for _ in range(40):
        d, rate = float(rng.uniform(-scale, scale)), float(rng.uniform(-2, 2))
        state = law.start(d, rate)
        found.append((state, d, rate))
        settled = law.settle(state, d, rate, lambda sign: sign * rate > 0)
        if settled:
            found.append((settled[0], d, rate))
        piece = law.piece(state)
        for guard in piece.guards:  # the state after each of its events, a little past it
            if guard.quantity == "d":
                after = law.event(state, guard.kind, guard.level, rate or guard.direction, whole_force(law, state,
                                                                                                      d, rate))
                found.append((after, guard.level + 1e-3 * scale * guard.direction, rate or guard.direction))
    return found


LAWS = [
    Elastoplastic(k=338.0, fy=0.8),
    Bilinear(k=400.0, fy=4.0, hardening=0.1),
    Bilinear(k=400.0, fy=4.0, hardening=-0.05),
    Clough(k=250.0, fy=3.0, hardening=0.05),
    Iwan(k=(100.0, 60.0, 30.0), fy=(0.5, 0.9, 1.4)),
    BoucWen(k=200.0, alpha=0.1, beta=30.0, gamma=20.0, n=1.5, A=1.0, z0=0.002),
    Friction(force=2.0, static=2.0, viscous=0.3, belt_velocity=0.1),
    Friction(force=2.0, static=3.0, stribeck_velocity=0.05, viscous=0.2, belt_velocity=0.1),
    Friction(force=2.0, static=2.0, regularization=1e-2, viscous=0.1),
    Stop(min=-0.02, max=0.03, k=2e4, c=5.0),
    Stop(min=-0.02, max=None, restitution=0.7),
]


@pytest.mark.parametrize("law", LAWS, ids=lambda law: f"{type(law).__name__}")
def test_force_derivatives_equal_central_differences_of_the_force(law):
    rng = np.random.default_rng(7)
    checked = 0
    for state, d, rate in states_of(law, rng):
        derivatives = law.force_derivatives(state, d, rate)
        if law.piece(state).held:
            assert derivatives is None  # a reaction, not its own force
            continue
        given = [key for key in law.keys if getattr(law, key) is not None]
        expected_keys = {f"{key}[{i}]" for key in given if key in law.arrays for i in range(len(getattr(law, key)))} \
            | {key for key in given if key not in law.arrays}
        expected_keys -= {"belt_velocity"} if isinstance(law, Friction) and law.belt_velocity == 0 else set()
        assert expected_keys <= set(derivatives), (state, sorted(derivatives))
        for key, value in derivatives.items():
            if key == "belt_velocity":  # it enters through d', the element's rate: d/d(belt) is d/d(d')
                h = 1e-6
                reference = (whole_force(law, state, d, rate + h) - whole_force(law, state, d, rate - h)) / (2 * h)
            else:
                reference = central(law, key, state, d, rate)
            scale = abs(whole_force(law, state, d, rate)) / max(abs(value_of(law, key)), 1e-12) + abs(reference)
            assert abs(value - reference) <= 1e-7 * scale + 1e-12, (key, state, d, rate, value, reference)
            checked += 1
    assert checked >= 40


def test_every_registered_law_gives_its_force_derivatives():
    """A law added to the registry without force_derivatives fails here (the base raises)."""
    classes = {type(law) for law in LAWS}
    registered = set(SPRING_LAWS.values()) | set(TABLES.values())
    assert registered <= classes, registered - classes


@pytest.mark.parametrize("law", [law for law in LAWS if law.smooth_jacobian(law.start(0.0, 0.1), 0.0, 0.1)],
                         ids=lambda law: f"{type(law).__name__}")
def test_a_smooth_law_s_jacobian_is_the_slope_of_its_force(law):
    """smooth_jacobian's tension slopes (the piece's linear parts aside: the sensitivity equations stamp those into
    K and C) against central differences of the whole force in d and d', the mode and internal variables held, at
    rates across the range and near zero (a regularized friction's slope F / r there)."""
    rng = np.random.default_rng(11)
    checked = 0
    for state, d, rate in states_of(law, rng):
        for at in (rate, 1e-3 * rate):
            found = law.smooth_jacobian(state, d, at)
            if found is None:
                continue
            piece = law.piece(state)
            slopes = (law.linear_stiffness + piece.stiffness + found[0][0], piece.damping + found[0][1])
            for which, value in enumerate(slopes):
                h = 1e-6 * max(abs((d, at)[which]), 1e-3)
                moved_by = lambda step: (d + step, at) if which == 0 else (d, at + step)  # noqa: E731
                reference = (whole_force(law, state, *moved_by(h)) - whole_force(law, state, *moved_by(-h))) / (2 * h)
                assert value == pytest.approx(reference, rel=1e-6, abs=1e-9 * abs(reference) + 1e-9), \
                    (state, d, at, which)
                checked += 1
    assert checked >= 40
