"""The run's own physics checked along its solution (analysis.guards): a dissipated energy that decreases, a
stuck contact holding more than its static force, a yield surface or a rigid stop passed, or an energy balance off
by more than the run states make it 'suspect', in the summary, the notes, --json and the file, and exit 1 under
--strict. The bundled scenes, solved as they are, are none of these."""

import dataclasses
import json

import h5py
import numpy as np
import pytest
from conftest import SCENARIOS

import smdcli
from smdcli.analysis.guards import suspicions


@pytest.mark.parametrize("stem", ["friction_isolated_building", "elastoplastic_record", "shear_frame_bilinear",
                                  "bouncing_ball", "vibro_impact_gap", "stick_slip_belt", "coulomb_free_decay",
                                  "three_dof_forced", "bouc_wen_multisine"])
@pytest.mark.parametrize("method", [None, "Radau"])
def test_the_bundled_scenes_are_not_suspect(stem, method):
    result = smdcli.simulate(SCENARIOS / f"{stem}.toml", method=method)
    assert result.stats.suspect == ""
    assert suspicions(result.origin[1], result) == ()


def corrupted(result, **energy_changes):
    return result.changed(energy=dataclasses.replace(result.energy, **energy_changes))


def test_a_decreasing_friction_energy_is_suspect():
    result = smdcli.simulate(SCENARIOS / "friction_isolated_building.toml")
    model = result.origin[1]
    friction = result.energy.friction.copy()
    friction[1000:] -= 0.05 * friction.max()  # friction giving back 5 % of what it took: creating energy
    reasons = suspicions(model, corrupted(result, friction=friction))
    assert any(r.startswith("the friction energy decreases by") and "t = 10 s" in r for r in reasons), reasons


def test_a_stuck_contact_beyond_its_static_force_is_suspect():
    result = smdcli.simulate(SCENARIOS / "friction_isolated_building.toml")
    model, history = result.origin[1], result.nonsmooth
    tension = history.tension.copy()
    static = model.nonsmooth[0].law.static
    tension[500, 0] = 1.5 * static
    bad = result.changed(nonsmooth=dataclasses.replace(history, tension=tension))
    reasons = suspicions(model, bad)
    assert any(r.startswith("friction[0]: its force stays within its static force") and "t = 5 s" in r
               for r in reasons), reasons


def test_a_rigid_stop_passed_is_suspect():
    result = smdcli.simulate(SCENARIOS / "bouncing_ball.toml")
    model = result.origin[1]
    x = result.displacement.copy()
    x[10] = -1e-3  # through the floor at min = 0
    reasons = suspicions(model, result.changed(displacement=x))
    assert any(r.startswith("stop[0]: a rigid stop is never passed") for r in reasons), reasons


def test_an_energy_balance_beyond_the_stated_accuracy_is_suspect():
    result = smdcli.simulate(SCENARIOS / "one_dof_nonlinear_stiff.toml", method="rk4")
    assert result.energy.max_relative_residual > 10 * result.stats.stated_accuracy  # rk4's estimate misses it
    assert "energy balance is off" in result.stats.suspect


def test_suspect_in_the_summary_json_and_file_and_exit_1_under_strict(tmp_path, cli, monkeypatch):
    import smdcli.analysis.guards as guards

    monkeypatch.setattr(guards, "suspicions", lambda model, result: ("friction[0]: made up for the test",))
    ran = cli("simulate", SCENARIOS / "two_dof_forced.toml", "-o", tmp_path, "--no-plots", "--json")
    assert ran.exit_code == 0
    entry = json.loads(ran.stdout)[0]
    assert entry["status"] == "suspect" and entry["suspect"] == ["friction[0]: made up for the test"]
    assert "warning: suspect: friction[0]: made up for the test" in entry["notes"]
    with h5py.File(tmp_path / "two_dof_forced.h5") as f:
        assert f["solver"].attrs["suspect"] == "friction[0]: made up for the test"
    strict = cli("simulate", SCENARIOS / "two_dof_forced.toml", "-o", tmp_path, "--no-plots", "--strict")
    assert strict.exit_code == 1 and "warning: suspect: friction[0]: made up for the test" in strict.stdout
    monkeypatch.undo()
    clean = cli("simulate", SCENARIOS / "two_dof_forced.toml", "-o", tmp_path, "--no-plots", "--strict", "--json")
    assert clean.exit_code == 0 and json.loads(clean.stdout)[0]["status"] == "ok"
    assert np.isfinite(json.loads(clean.stdout)[0]["energy_residual"])
