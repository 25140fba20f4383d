"""No plot smd writes cuts its text: every PNG of every plot kind, at the default size, has all it draws (titles,
labels, tick labels, legends, colour bars, annotations) inside the figure."""

from __future__ import annotations

import pytest
from conftest import ROOT, SCENARIOS

RECORD = ROOT / "records" / "synthetic_20s_100hz.csv"

# One run of each command and kind of plot, every plot it writes checked.
RUNS = {
    "simulate, forced three masses": ["simulate", SCENARIOS / "three_dof_forced.toml"],
    "simulate, one mass": ["simulate", SCENARIOS / "one_dof_underdamped.toml"],
    "simulate, ground record": ["simulate", SCENARIOS / "shear_frame_record.toml"],
    "simulate, impacts": ["simulate", SCENARIOS / "bouncing_ball.toml"],
    "simulate, friction": ["simulate", SCENARIOS / "friction_isolated_building.toml"],
    "simulate, initial conditions": ["simulate", SCENARIOS / "ic_underdamped.toml"],
    "sweep, overlay and metric": ["sweep", SCENARIOS / "one_dof_regimes_sweep.toml"],
    "sweep, heat map of one mass": ["sweep", SCENARIOS / "one_dof_underdamped.toml", "--param", "damper[0].c",
                                    "--values", "0.5,1,2", "--param", "spring[0].k", "--values", "10,20"],
    "sweep, initial conditions": ["sweep", SCENARIOS / "ic_underdamped.toml"],
    "sweep, frequency response": ["sweep", SCENARIOS / "frequency_response_zeta.toml"],
    "sweep, transmissibility": ["sweep", SCENARIOS / "transmissibility_1dof.toml"],
    "spectrum": ["spectrum", RECORD, "--damping", "0.02,0.05"],
    "inelastic spectrum": ["spectrum", RECORD, "--periods", "logspace(-1,0.5,12)", "--ductility", "1,2,4,8"],
    "constant-strength spectrum": ["spectrum", RECORD, "--periods", "logspace(-1,0.5,12)", "--strength", "0.1,0.3"],
    "record": ["record", RECORD],
    "record, processed": ["record", RECORD, "--baseline", "quadratic", "--filter", "0.1,20"],
    "random vibration": ["psd", SCENARIOS / "component_random_vibration.toml", "--input",
                         ROOT / "records" / "navmat_p9492_profile.csv"],
    "random vibration, force on a mass": ["psd", SCENARIOS / "three_dof_forced.toml", "--input", "white:1",
                                          "--on", "m2"],
    "response-spectrum analysis": ["rsa", SCENARIOS / "five_storey_building.toml", "--spectrum",
                                   ROOT / "records" / "design_spectrum_sds1_sd06.csv"],
    "shock spectrum": ["spectrum", ROOT / "records" / "half_sine_11ms_50g.csv", "--kind", "srs", "--q", "10,50"],
    "compare-solvers": ["compare-solvers", SCENARIOS / "two_dof_forced.toml", "--methods", "ode45,euler,newmark",
                        "--repeats", "1"],
    "phase, several scenarios": ["phase", SCENARIOS / "one_dof_underdamped.toml", SCENARIOS / "one_dof_overdamped.toml",
                                 SCENARIOS / "one_dof_critical.toml"],
    "phase, three masses": ["phase", SCENARIOS / "three_dof_forced.toml"],
    "phase, Poincare": ["phase", SCENARIOS / "one_dof_harmonic.toml", "--poincare"],
    "phase, hysteresis": ["phase", SCENARIOS / "shear_frame_bilinear.toml", "--hysteresis"],
    "draw": ["draw", SCENARIOS / "quarter_car_bump.toml"],
}


@pytest.fixture
def saved_figures(monkeypatch):
    """Every figure saved while the fixture is active, with what of it falls outside (in inches)."""
    from matplotlib.figure import Figure

    found = []
    original = Figure.savefig

    def checked(fig, fname, *args, **kwargs):
        renderer = fig.canvas.get_renderer()
        tight = fig.get_tightbbox(renderer)  # everything drawn: texts, legends, colour bars
        width, height = fig.get_size_inches()
        tolerance = 0.02  # inches: under two pixels at smd's 110 dpi
        outside = {side: round(amount, 3) for side, amount in (("left", -tight.x0), ("bottom", -tight.y0),
                                                                ("right", tight.x1 - width),
                                                                ("top", tight.y1 - height)) if amount > tolerance}
        found.append((str(fname), outside))
        return original(fig, fname, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", checked)
    return found


@pytest.mark.parametrize("name", sorted(RUNS))
def test_no_plot_cuts_its_text(name, tmp_path, saved_figures):
    from smdcli.cli import run as smd

    assert smd([str(a) for a in RUNS[name]] + ["-o", str(tmp_path), "--quiet"]) == 0
    assert saved_figures, "no figure was saved"
    clipped = [(path.split("/")[-1], outside) for path, outside in saved_figures if outside]
    assert not clipped, clipped
