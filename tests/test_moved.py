"""model/moved.py: a linear scene's model with one structural number moved is the model build makes of the
scenario with that number, on every bundled scene it applies to (plain, Rayleigh, modal damping, ground jumps)."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import bundled, model_of, one_dof
from smdcli.model import build
from smdcli.model.moved import moved
from smdcli.sweep.family import scenario_with

SCENES = ["two_dof_forced", "three_dof_forced", "three_storey_shaker", "five_storey_building", "shear_frame_record",
          "quarter_car_bump", "five_storey_tmd"]


def _paths(sc, model) -> list[str]:
    """Every path moved() takes in the scene: each mass by name and by index, each linear spring's k and damper's c,
    Rayleigh's alpha and beta where the scenario gives them."""
    paths = []
    for i, name in enumerate(model.dofs):
        paths += [f"mass.{name}.m", f"mass[{i}].m", f"mass.{name}.x0", f"mass[{i}].v0"]
    paths += [f"{e.name}.{'k' if e.kind == 'spring' else 'c'}" for e in model.elements if e.law == "linear"]
    if sc.damping is not None and sc.damping.given in ("alpha", "beta"):
        paths += ["damping.alpha", "damping.beta"]
    return paths


def _now(model, path: str, sc=None) -> float:
    """The model's number at a mass's m, a spring's k, a damper's c or Rayleigh's alpha or beta path."""
    owner = path.rpartition(".")[0]
    if owner == "damping":
        return 1e-3 + getattr(sc.damping, path.rpartition(".")[2])  # never 0: a move must change C
    if owner.startswith("mass"):
        i = int(owner[5:-1]) if owner.startswith("mass[") else model.dofs.index(owner[5:])
        return float(model.M[i, i])
    return next(e.coef for e in model.elements if e.name == owner)


def _same(a: np.ndarray, b: np.ndarray) -> float:
    """The largest difference relative to the larger array's largest entry."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return float(np.abs(a - b).max(initial=0.0)) / max(float(np.abs(a).max(initial=0.0)),
                                                        float(np.abs(b).max(initial=0.0)), 1e-300)


def _filter_rounding(ground: dict, step: float) -> float:
    """A record's band-pass's own rounding, relative to its peak: each of sosfiltfilt's two passes amplifies a
    sample's rounding by up to the sum of 1 / (1 - |p|) over the filter's poles (1,190 for 0.1 - 20 Hz at 100 Hz,
    where 0.1 Hz's poles sit 0.0024 from the unit circle: 5e-13; measured 2.4e-13 on an Intel Xeon, below 1e-13 on
    an AMD EPYC)."""
    from scipy.signal import butter, sos2zpk

    if "filter" not in ground:
        return 0.0
    low, high = ground["filter"]
    sos = butter(ground.get("filter_order", 4), [low, high], btype="bandpass", fs=1.0 / step, output="sos")
    poles = sos2zpk(sos)[1]
    return 2 * float(np.sum(1.0 / (1.0 - np.abs(poles)))) * np.finfo(float).eps


@pytest.mark.parametrize("name", SCENES)
def test_a_moved_model_is_the_model_built_with_the_number(name):
    sc, base, _ = bundled(name)
    for path in _paths(sc, base):
        value = 1.3 * _now(base, path, sc) if path.endswith((".m", ".k", ".c", "alpha", "beta")) else 0.37
        fast = moved(base, sc, path, value)
        built = build(scenario_with(sc, {path: value}))
        assert fast is not None, path
        for array in ("M", "C", "K", "x0", "v0"):
            assert _same(getattr(fast, array), getattr(built, array)) < 1e-13, (path, array)
        if built.added_damping is not None:
            assert _same(fast.added_damping, built.added_damping) < 1e-13, path
        assert len(fast.jumps) == len(built.jumps)
        for (t, dx, dv), (u, ex, ev) in zip(fast.jumps, built.jumps):
            assert t == u and _same(dx, ex) < 1e-13 and _same(dv, ev) < 1e-13, path
        assert [e.coef for e in fast.elements] == pytest.approx([e.coef for e in built.elements], rel=1e-15)


def test_a_scene_only_build_can_make_is_left_to_it():
    sc, base, _ = model_of(one_dof(0.5, law="quadratic"))
    assert moved(base, sc, "spring[0].k", 30.0) is None  # nonlinear: its numbers live beside K
    sc, base, _ = model_of(one_dof(0.5))
    assert moved(base, sc, "mass.nobody.m", 2.0) is None
    assert moved(base, sc, "mass[3].m", 2.0) is None
    assert moved(base, sc, "spring[0].k", -1.0) is None  # not a scene: build's refusal turns the stencil one-sided
    assert moved(base, sc, "mass.m.m", 0.0) is None
    assert moved(base, sc, "damping.alpha", 2.0) is None  # no [damping]
    sc, base, _ = bundled("shear_frame_bilinear")
    assert moved(base, sc, "damping.alpha", 2.0) is None  # nonlinear, and its Rayleigh given through zeta
    sc, base, _ = model_of(one_dof(0.5) + "[damping]\nzeta = 0.05\nomega = [2.0, 9.0]\n")
    assert moved(base, sc, "damping.alpha", 2.0) is None  # build says what alpha means beside zeta
    assert moved(base, sc, "spring[0].k", 30.0).K[0, 0] == pytest.approx(30.0, rel=1e-15)


def test_a_moved_amplitude_is_the_force_built_with_it():
    """A force's amplitude, on every bundled linear scene whose forces have one: the moved force's values over the
    run and its generator's state at the end are the built scene's, to 1e-13; a table's or an expression's is left to
    build (its numbers are its values)."""
    from smdcli.model import time_grid
    from smdcli.shapes.table import Table

    checked = 0
    for name in ["one_dof_harmonic", "three_dof_forced", "two_dof_forced", "one_dof_square_wave", "one_dof_square_fourier",
                 "three_storey_shaker", "tmd_one_dof"]:
        sc, base, _ = bundled(name)
        grid = time_grid(sc.time)
        for j, force in enumerate(sc.forces):
            path, value = f"force[{j}].amplitude", 1.7 * force.amplitude + 0.3
            fast = moved(base, sc, path, value)
            if force.type in ("table", "expression"):
                assert fast is None, path
                continue
            built = build(scenario_with(sc, {path: value}))
            assert _same(fast.signals[j].value(grid), built.signals[j].value(grid)) < 1e-13, (name, path)
            if built.signals[j].exo() is not None:
                end = float(grid[-1])
                assert _same(fast.signals[j].exo_state(end), built.signals[j].exo_state(end)) < 1e-13, (name, path)
            assert not isinstance(fast.signals[j], Table)
            checked += 1
    assert checked >= 10


@pytest.mark.parametrize("force, keys", [
    ('type = "sine"\namplitude = 2.0\nomega = 5.0\nphase = 0.3', ["omega", "phase"]),
    ('type = "cosine"\namplitude = 2.0\nfrequency = 0.7', ["frequency"]),
    ('type = "square"\namplitude = 1.5\nperiod = 0.8\nduty = 0.4', ["duty"]),
    ('type = "fourier_square"\namplitude = 1.5\nperiod = 0.8\nterms = 5', ["period"]),
    ('type = "chirp"\namplitude = 1.0\nf0 = 0.5\nf1 = 3.0\nt1 = 4.0', ["f0", "f1", "t1"]),
])
def test_a_moved_frequency_phase_or_sweep_is_the_force_built_with_it(force, keys):
    """A force's frequency (as its scenario gives it: omega, frequency or period), phase, duty or chirp sweep moved:
    the force's values over the run and its generator's state at the end are the built scene's, to 1e-13; the same
    frequency moved as any of the three is one force; a key the force's type does not read is left to build."""
    import math

    from smdcli.model import time_grid
    from smdcli.shapes.registry import SHAPES
    from smdcli.sweep.family import decoded, parameter_value

    sc, base, _ = model_of(one_dof(0.5, extra=f"[[force]]\non = \"m\"\n{force}\n"))
    grid = time_grid(sc.time)
    doc = decoded(sc.text)
    for key in keys:
        path = f"force[0].{key}"
        value = 1.07 * parameter_value(doc, path, sc) + 0.01
        fast = moved(base, sc, path, value)
        built = build(scenario_with(sc, {path: value}))
        assert fast is not None, path
        assert _same(fast.signals[0].value(grid), built.signals[0].value(grid)) < 1e-13, path
        if built.signals[0].exo() is not None:
            end = float(grid[-1])
            assert _same(fast.signals[0].exo_state(end), built.signals[0].exo_state(end)) < 1e-13, path
    if sc.forces[0].omega is not None:
        w = 1.1 * sc.forces[0].omega
        as_omega = moved(base, sc, "force[0].omega", w).signals[0].value(grid)
        for path, value in (("force[0].frequency", w / (2 * math.pi)), ("force[0].period", 2 * math.pi / w)):
            if path.rpartition(".")[2] in SHAPES[sc.forces[0].type].fields:
                assert _same(moved(base, sc, path, value).signals[0].value(grid), as_omega) < 1e-13, path
            else:  # a sine has no period: build refuses it, and so does moved
                assert moved(base, sc, path, value) is None, path
    if "duty" not in keys:
        assert moved(base, sc, "force[0].duty", 0.3) is None


def test_a_moved_law_key_is_the_law_built_with_it():
    """A yielding, friction or stop element's own key (law_keys.law_moved): where the model's matrices do
    not move with it, the law read again is the law build makes of the scenario with that number and the matrices
    are the base's; where they move (a spring's k, a hardening, a Bouc-Wen alpha) or the belt does, it is left to
    build; a value that is no scene is refused as build refuses it."""
    from smdcli.analysis.law_keys import law_moved
    from smdcli.errors import ScenarioError
    from smdcli.sweep.family import decoded, parameter_value

    moved_keys, refused = set(), 0
    for name in ["elastoplastic_record", "coulomb_free_decay", "friction_isolated_building", "shear_frame_bilinear",
                 "vibro_impact_gap", "stick_slip_belt", "bouncing_ball", "bouc_wen_benchmark", "ida_frame"]:
        sc, base, _ = bundled(name)
        doc = decoded(sc.text)
        for element in base.nonsmooth:
            for key in type(element.law).keys:
                path = f"{element.path}.{key}"
                try:
                    now = parameter_value(doc, path, sc)
                except Exception:  # an optional key the table leaves out and the sweep cannot read
                    continue
                for value in (1.013 * now + 0.01, -1.0):
                    try:
                        built = build(scenario_with(sc, {path: value}))
                    except ScenarioError:
                        built = None
                    try:
                        fast = law_moved(sc, doc, base, path, value)
                    except ScenarioError:
                        assert built is None, (name, path, value)
                        refused += 1
                        continue
                    if fast is None:
                        assert key in ("k", "hardening", "alpha", "belt_velocity") or built is None, (name, path)
                        continue
                    assert built is not None, (name, path, value)
                    assert [e.law for e in fast.nonsmooth] == [e.law for e in built.nonsmooth], (name, path)
                    assert [e.belt for e in fast.nonsmooth] == [e.belt for e in built.nonsmooth], (name, path)
                    for array in ("M", "C", "K", "x0", "v0"):
                        assert _same(getattr(fast, array), getattr(built, array)) == 0.0, (name, path, array)
                    moved_keys.add(f"{type(element.law).__name__}.{key}")
    assert {"Elastoplastic.fy", "Bilinear.fy", "Friction.force", "Friction.static", "Stop.restitution"} <= moved_keys, \
        moved_keys
    assert refused >= 5


@pytest.mark.parametrize("name, extra", [
    ("shear_frame_record", ""), ("elastoplastic_record", ""), ("friction_isolated_building", ""),
    ("shear_frame_record", 'baseline = "linear"\nfilter = [0.1, 20.0]'), ("shear_frame_record", "hold = true"),
    ("shear_frame_record", "scale = 0.7"),
])
def test_a_moved_record_scale_is_the_record_built_with_it(name, extra):
    """A recorded ground acceleration's scale (model/moved.scaled_ground): the record's samples times the ratio are
    the ones build reads and processes (a baseline's and a filter's processing is linear in them) over the run, held
    or ended, to 1e-13, the rest of the model the base's; a record with a shift, or another ground motion, is left to
    build."""
    from smdcli import scenario
    from smdcli.model import time_grid
    from smdcli.model.moved import scaled_ground
    from smdcli.sweep.family import decoded, parameter_value

    base_sc = bundled(name)[0]
    text = base_sc.text.replace('quantity = "acceleration"', f'quantity = "acceleration"\n{extra}')
    sc = scenario.parse(text, str(base_sc.path))
    base, grid = build(sc), time_grid(sc.time)
    doc = decoded(sc.text)
    now = parameter_value(doc, "ground_motion.scale", sc)
    for value in (1.37 * now, -0.5 * now):
        fast = scaled_ground(base, doc["ground_motion"], now, value)
        built = build(scenario_with(sc, {"ground_motion.scale": value}))
        assert fast is not None
        allowed = 1e-13 + _filter_rounding(doc["ground_motion"], float(np.diff(built.ground.given.t).mean()))
        for mine, theirs in zip(fast.signals, built.signals, strict=True):
            assert _same(mine.value(grid), theirs.value(grid)) < allowed
            assert _same(mine.value_left(grid), theirs.value_left(grid)) < allowed
        assert fast.ground.acceleration is fast.signals[-1] and fast.ground.given.ended == built.ground.given.ended
        assert fast.M is base.M and fast.K is base.K and fast.nonsmooth is base.nonsmooth
    shifted = scenario.parse(text.replace('quantity = "acceleration"', 'quantity = "acceleration"\nshift = 0.01'),
                             str(base_sc.path))
    assert scaled_ground(build(shifted), decoded(shifted.text)["ground_motion"], now, 2.0) is None  # affine, not linear
    assert scaled_ground(base, doc["ground_motion"], 0.0, 2.0) is None
    sc, base, _ = bundled("quarter_car_bump")  # a ground displacement: its jumps move with it
    assert scaled_ground(base, {}, 1.0, 2.0) is None
