"""Sensitivities of classically damped scenes in modal coordinates (analysis/modal_sensitivity.py): against a
complex-step derivative of the state transition written here, against the dense stacked system (whose own tests hold
it to the complex step), and its refusals (a force's edge between samples, resonance, critical damping), where the
dense path answers instead."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
import scipy.linalg

import smdcli
from conftest import assert_sensitivities_agree, sensitivity_with
from smdcli.analysis.model_derivative import augmented_model, model_derivatives
from smdcli.analysis.modal_sensitivity import MODAL_METHOD, modal_sensitivities
from smdcli.model import build, time_grid
from smdcli.scenario import parse

H = 1e-30  # the complex step


def chain(n: int, k: float = 100.0, c: float = 0.5, force: str = 'type = "sine"\namplitude = 10.0\nomega = 5.0',
          extra: str = "", end: float = 4.0, step: float = 0.01) -> str:
    """An n-mass chain fixed at one end (masses 1 + i / n kg), a spring k and damper c on every link (classical
    damping, C = c / k K), a force on the first mass."""
    lines = ["[time]", f"end = {end}", f"step = {step}"]
    for i in range(n):
        lines += ["[[mass]]", f'name = "m{i}"', f"m = {1.0 + i / n}"]
    for i in range(n):
        left = "ground" if i == 0 else f"m{i - 1}"
        lines += ["[[spring]]", f'connects = ["{left}", "m{i}"]', f"k = {k}"]
        if c:
            lines += ["[[damper]]", f'connects = ["{left}", "m{i}"]', f"c = {c}"]
    lines += ["[[force]]", 'on = "m0"', force]
    return "\n".join(lines) + "\n" + extra


def assert_within_1e_11(found, reference, params: list[str]) -> None:
    """x, v and a and each parameter's derivatives of two runs within 1e-11 of each one's largest, the derivatives
    also within ten times both stated errors."""
    for quantity in ("displacement", "velocity", "acceleration"):
        mine, theirs = getattr(found, quantity), getattr(reference, quantity)
        assert np.abs(mine - theirs).max() <= 1e-11 * np.abs(theirs).max(), quantity
        mine, theirs = getattr(found, f"d_{quantity}"), getattr(reference, f"d_{quantity}")
        for i, param in enumerate(params):
            largest = np.abs(theirs[i]).max()
            error = np.abs(mine[i] - theirs[i]).max()
            stated = found.accuracy[f"d_{quantity}"][i] + reference.accuracy[f"d_{quantity}"][i]
            assert error <= min(1e-11, 10 * stated) * largest, (param, quantity, error / largest, stated)


def dense(sc, params):
    """The sensitivities by the dense stacked system (the modal path held off)."""
    return sensitivity_with(sc, params, 10**9)


def test_a_chain_s_stiffness_sensitivity_matches_the_complex_step_of_its_state_transition():
    """40 masses, k of the first spring: the complex-step derivative of the exact transition (expm of the complex
    state matrix, the force's sine and cosine in the state), to 1e-10 of the largest sensitivity."""
    n = 40
    sc = parse(chain(n), "chain.toml")
    found = smdcli.sensitivity(sc, ["spring[0].k"])
    assert found.method == MODAL_METHOD
    masses = 1.0 + np.arange(n) / n

    def transition(k0):
        links = np.full(n, 100.0).astype(complex)
        links[0] = k0
        K = np.diag(links + np.append(links[1:], 0.0)) - np.diag(links[1:], 1) - np.diag(links[1:], -1)
        C = 0.005 * (np.diag(np.full(n, 100.0) + np.append(np.full(n - 1, 100.0), 0.0))
                     - np.diag(np.full(n - 1, 100.0), 1) - np.diag(np.full(n - 1, 100.0), -1))
        A = np.zeros((2 * n + 2, 2 * n + 2), complex)
        A[:n, n:2 * n] = np.eye(n)
        A[n:2 * n, :n] = -K / masses[:, None]
        A[n:2 * n, n:2 * n] = -C / masses[:, None]
        A[n, 2 * n] = 10.0 / masses[0]  # 10 sin(5 t) on the first mass
        A[2 * n, 2 * n + 1], A[2 * n + 1, 2 * n] = 5.0, -5.0  # (sin, cos)' = 5 (cos, -sin)
        step, z, out = scipy.linalg.expm(A * 0.01), np.zeros(2 * n + 2, complex), []
        z[2 * n + 1] = 1.0
        for _ in range(len(found.time)):
            out.append(z[:n].copy())
            z = step @ z
        return np.array(out)
    reference = transition(100.0 + 1j * H).imag / H
    largest = np.abs(reference).max()
    assert np.abs(found.d_displacement[0] - reference).max() <= 1e-10 * largest
    assert np.abs(found.displacement - transition(100.0).real).max() <= 1e-12 * np.abs(found.displacement).max()


@pytest.mark.parametrize("params, extra, force", [
    (["spring[0].k", "damper[3].c", "mass.m5.m", "force[0].amplitude", "force[0].omega", "mass.m0.x0"], "", None),
    # stiff: |lambda| h up to 20, the modes' coupling summed over a sixteenth of the step and squared four times
    (["spring[0].k", "damper[3].c", "mass.m5.m"], "stiff", None),
    (["damping.alpha", "damping.beta", "spring[7].k", "mass.m2.m"], "[damping]\nalpha = 0.3\nbeta = 0.002\n", None),
    # 15 of the 30 modes overdamped (beta's damping grows with frequency): both eigenvalues of each stepped
    (["damping.beta", "spring[3].k", "mass.m7.m"], "[damping]\nalpha = 0.1\nbeta = 0.17\n", None),
    (["ground_motion.amplitude", "ground_motion.omega", "spring[1].k", "mass.m0.v0"],
     '[ground_motion]\nquantity = "acceleration"\ntype = "sine"\namplitude = 2.0\nomega = 7.0\n', None),
    (["spring[2].k", "force[0].amplitude"], "", 'type = "step"\namplitude = 3.0\nt0 = 0.5'),
    (["spring[2].k", "mass.m4.m", "force[0].amplitude"], "", 'type = "square"\namplitude = 2.0\nperiod = 0.8'),
])
def test_the_modal_path_agrees_with_the_dense_stacked_system(params, extra, force):
    """Every kind of parameter (an element, a mass, a force's amplitude and frequency, an initial state, Rayleigh's
    coefficients, the ground motion's) and force (sine, step, square wave with its edges on output points, support
    motion): x, v and a and their derivatives within 1e-11 of each one's largest, and within both stated errors."""
    stiff = extra == "stiff"
    text = chain(30, k=1e6 if stiff else 100.0, c=0.0 if extra.startswith("[damping]") else 50.0 if stiff else 0.5,
                 force=force or 'type = "sine"\namplitude = 10.0\nomega = 5.0', extra="" if stiff else extra)
    text = text.replace('name = "m0"\nm = 1.0', 'name = "m0"\nm = 1.0\nx0 = 0.01\nv0 = 0.02')
    sc = parse(text, "chain.toml")
    found, reference = smdcli.sensitivity(sc, params), dense(sc, params)
    assert found.method == MODAL_METHOD and reference.method != MODAL_METHOD
    assert_within_1e_11(found, reference, params)
    assert np.allclose(found.d_peak_displacement, reference.d_peak_displacement, rtol=1e-9, atol=1e-12)


def test_a_long_chain_s_element_parameters_couple_its_modes_through_thin_factors(monkeypatch):
    """120 masses: an element's stiffness, a damper and a mass each move alpha and beta by a matrix of rank one or
    two, so that the modes' coupling over a step is a product of thin factors (2 r T columns, not 2n): against the
    dense stacked system within 1e-11 of each one's largest and both stated errors; a force's amplitude, which
    moves neither, couples nothing."""
    import smdcli.analysis.modal_sensitivity as modal_path

    taken = []

    class Spied(modal_path._Coupling):
        def __init__(self, *args):
            super().__init__(*args)
            taken.append(tuple(kind for kind, *_ in self.parts))
    monkeypatch.setattr(modal_path, "_Coupling", Spied)
    params = ["spring[0].k", "damper[3].c", "mass.m5.m", "force[0].amplitude"]
    sc = parse(chain(120, end=1.0), "chain.toml")
    found, reference = smdcli.sensitivity(sc, params), dense(sc, params)
    assert found.method == MODAL_METHOD and taken == [("thin",) * 4]
    assert_within_1e_11(found, reference, params)


def refusal_of(text: str, params: list[str]):
    """modal_sensitivities' answer for the scene (None: the dense path's)."""
    sc = parse(text, "scene.toml")
    base = build(sc)
    grid = time_grid(sc.time)
    derivatives = model_derivatives(sc, base, grid, params, None, flowed=True)
    stacked, scales = augmented_model(base, derivatives)
    return modal_sensitivities(base, stacked, scales, grid)


def test_where_it_does_not_serve_the_dense_path_answers():
    """A square wave's edges between output points (a period of 0.77 s on 0.01 s steps), an undamped chain forced
    at its own first frequency (Y's equation singular), a chain whose lowest mode is critically damped, and a
    chain too small for the path: None, and `smd sensitivity` answers by the stacked system."""
    params = ["spring[0].k", "spring[1].k"]
    between = chain(30, force='type = "square"\namplitude = 2.0\nperiod = 0.77')
    assert refusal_of(between, params) is None
    undamped = parse(chain(30, c=0.0), "u.toml")
    first = float(build(undamped).modes.natural_frequencies[0])
    resonant = chain(30, c=0.0, force=f'type = "sine"\namplitude = 1.0\nomega = {first!r}')
    assert refusal_of(resonant, params) is None
    assert refusal_of(chain(30, c=0.0, force='type = "sine"\namplitude = 1.0\nomega = 5.0'), params) is not None
    base = build(parse(chain(30, c=0.0), "c.toml"))
    w1 = float(base.modes.natural_frequencies[0])
    critical = chain(30, c=0.0, extra=f"[damping]\nalpha = {2 * w1!r}\nbeta = 0.0\n")  # zeta_1 = alpha / (2 w1) = 1
    assert refusal_of(critical, params) is None
    assert refusal_of(chain(10), ["spring[0].k"]) is None  # (P + 1) n = 20: the dense system is cheaper
    sc = parse(between, "between.toml")
    found = smdcli.sensitivity(sc, params)
    assert found.method != MODAL_METHOD and np.isfinite(found.d_displacement).all()


FORCES = [
    'type = "sine"\namplitude = {a}\nomega = {w}',
    'type = "cosine"\namplitude = {a}\nomega = {w}',
    'type = "step"\namplitude = {a}\nt0 = 0.25',
    'type = "square"\namplitude = {a}\nperiod = 0.4',
    'type = "constant"\namplitude = {a}',
    'type = "pulse"\namplitude = {a}\nt0 = 0.1\nduration = 0.3\nshape = "half_sine"',
    'type = "table"\nt = [0.0, 0.5, 1.0, 1.5]\nvalues = [0.0, {a}, -{a}, 0.5]',
    'type = "table"\nt = [0.0, 0.5, 1.0, 1.5]\nvalues = [0.0, {a}, -{a}, 0.5]\ninterpolation = "previous"',
    None,  # free vibration: no force at all
]


@settings(max_examples=40, deadline=None, derandomize=True, database=None)
@given(st.integers(1, 5), st.sampled_from(["dampers", "rayleigh", "modal"]), st.sampled_from(FORCES),
       st.floats(0.5, 3.0), st.floats(1.0, 12.0), st.integers(0, 3), st.booleans())
def test_random_classically_damped_chains_agree_on_both_paths(n, damping, force, amplitude, omega, which, moving):
    """Chains of 1 to 5 masses, classically damped three ways (a damper beside every spring in proportion, Rayleigh's
    alpha and beta, modal ratios), under each force with a generator, started at rest or moving; a parameter of each
    kind: the modal path (held on however small the scene) against the dense stacked system, within ten times the
    stated errors of both."""
    rng = np.random.default_rng(n * 1000 + which)
    lines = ["[time]", "end = 2.0", "step = 0.01"]
    for i in range(n):
        lines += ["[[mass]]", f'name = "m{i}"', f"m = {rng.uniform(0.5, 2.0)!r}"]
        if moving:
            lines += [f"x0 = {rng.uniform(-0.02, 0.02)!r}", f"v0 = {rng.uniform(-0.1, 0.1)!r}"]
    for i in range(n):
        k = rng.uniform(50.0, 400.0)
        lines += ["[[spring]]", f'connects = ["{"ground" if i == 0 else f"m{i - 1}"}", "m{i}"]', f"k = {k!r}"]
        if damping == "dampers":
            lines += ["[[damper]]", f'connects = ["{"ground" if i == 0 else f"m{i - 1}"}", "m{i}"]',
                      f"c = {0.004 * k!r}"]
    if force is None:  # free vibration from an initial state
        lines = [line for line in lines if not line.startswith(("x0", "v0"))]
        lines.insert(lines.index('name = "m0"') + 2, "x0 = 0.01\nv0 = 0.05")
    else:
        lines += ["[[force]]", f'on = "m{n - 1}"', force.format(a=amplitude, w=omega)]
    if damping == "rayleigh":
        lines += ["[damping]", "alpha = 0.4", "beta = 0.003"]
    elif damping == "modal":
        lines += ["[damping]", "modal = 0.03"]
    scaled = "force[0].amplitude" if force and "amplitude" in force else "mass.m0.x0"  # a table has no amplitude
    params = [["spring[0].k"], [f"mass.m{n - 1}.m"], [scaled],
              ["damper[0].c" if damping == "dampers" else f"spring[{n - 1}].k"]][which]
    sc = parse("\n".join(lines) + "\n", "chain.toml")
    found, reference = sensitivity_with(sc, params, 1), dense(sc, params)
    assert found.method == MODAL_METHOD
    assert_sensitivities_agree(found, reference, str(params))


def test_past_the_dense_limit_a_classically_damped_scene_is_answered_in_modal_coordinates(monkeypatch):
    """More stacked DOFs than the dense exponential takes (MAX_SIZE, here lowered to 100: 3 parameters of 40 masses
    stack 160) are answered where the modal path serves, equal to the dense stacked system's answer; refused in one
    line where it does not (a damper at one end only: not classical), and where its run would not fit in memory."""
    import smdcli.analysis.sensitivity_limits as limits
    from smdcli.errors import UsageError

    params = ["spring[0].k", "damper[3].c", "mass.m5.m"]
    sc = parse(chain(40, end=1.0), "chain.toml")
    reference = dense(sc, params)
    monkeypatch.setattr(limits, "MAX_SIZE", 100)
    found = smdcli.sensitivity(sc, params)
    assert found.method == MODAL_METHOD
    assert_within_1e_11(found, reference, params)
    one_end = chain(40, c=0.0, end=1.0).replace('[[force]]', '[[damper]]\nconnects = ["m38", "m39"]\nc = 0.5\n[[force]]')
    with pytest.raises(UsageError, match=r"3 parameters of a 40-DOF scene stack 160 DOFs; smd sensitivity takes at "
                                         r"most 100 \(beyond, a classically damped scene in modal coordinates\)"):
        smdcli.sensitivity(parse(one_end, "one_end.toml"), ["spring[0].k", "damper[0].c", "mass.m5.m"])
    monkeypatch.setattr(limits, "fits", lambda needed: False)
    with pytest.raises(UsageError, match=r"need about .* GB in modal coordinates"):
        smdcli.sensitivity(sc, params)
