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


@pytest.mark.parametrize("periods", ["linspace(0.2,1.5,60)", "logspace(-2,1,200)"])
def test_a_spectrum_labels_guide_lines_where_its_curve_is(periods, tmp_path):
    """Every Sa and Sd guide line through the curve's own range has its label somewhere on the frame: a narrow band
    gets 1-2-5 lines (the curve at 0.3-0.7 g with only 1 g and 0.1 g drawn could not be read), and a label the
    frame would cut at the line's exit is moved along the line, not dropped."""
    import math
    import re

    import numpy as np

    from smdcli.analysis.spectrum import response_spectrum
    from smdcli.plots.spectrum import spectrum_figure
    from smdcli.scenario.record_files import read_record
    from smdcli.scenario.spec import STANDARD_GRAVITY as G
    from smdcli.sweep.spec import parse_values

    record = read_record(RECORD, units="g")
    spectrum = response_spectrum(record.time, record.acceleration, parse_values(periods), np.array([0.05]))
    fig = spectrum_figure(spectrum, record, "spectrum")
    labels = [t.get_text() for t in fig.axes[0].texts]
    sa_drawn = sorted(float(m.group(1)) for t in labels if (m := re.fullmatch(r"Sa (\S+) g", t)))
    sa = 2 * math.pi * spectrum.Sv[0] / spectrum.period / G
    inside = [v for v in sa_drawn if sa.min() <= v <= sa.max()]
    assert inside, (sa.min(), sa.max(), sa_drawn)
    sd_drawn = [t for t in labels if t.startswith("Sd ")]
    assert len(sd_drawn) >= 3 and len(sa_drawn) >= 3


def test_a_phase_axis_is_labelled_as_far_as_its_lags_reach(tmp_path, monkeypatch):
    """Three masses lag up to 5π/2 behind a force on the first: the phase axis is labelled in steps of π/2 past the
    largest lag (it stopped at 2π where the curve reached 3π)."""
    import math

    import h5py
    import numpy as np
    from matplotlib.figure import Figure

    from smdcli.cli import run as smd

    seen = []
    original = Figure.savefig
    monkeypatch.setattr(Figure, "savefig", lambda fig, *a, **k: (seen.append(fig), original(fig, *a, **k))[1])
    assert smd(["sweep", str(SCENARIOS / "three_dof_forced.toml"), "--frequency", "linspace(1,60,300)",
                "-o", str(tmp_path), "--quiet"]) == 0
    with h5py.File(tmp_path / "three_dof_forced_sweep.h5") as f:
        lag = float(np.nanmax(f["phase"][()]))
    phase_axis = seen[0].axes[1]
    ticks = phase_axis.get_yticks()
    assert lag > 2 * math.pi and ticks.max() >= lag and ticks.max() - lag < math.pi / 2
    labels = [t.get_text() for t in phase_axis.get_yticklabels()]
    assert labels[-1] == "5π/2" and labels[:5] == ["0", "π/2", "π", "3π/2", "2π"]


def test_log_axis_labels_are_plain_text_that_reads_as_the_tick_values():
    """The energy figure's residual axis is labelled 10⁻¹⁵ and 6×10⁻¹⁶ in plain text (no mathtext to parse), each label
    the value of its tick."""
    import math
    import re

    import smdcli
    from smdcli.plots.energy import energy_figure

    result = smdcli.simulate(SCENARIOS / "friction_isolated_building.toml")
    fig = energy_figure(result, "friction")
    fig.canvas.draw()
    axis = fig.axes[1].yaxis
    digits = str.maketrans("⁻⁰¹²³⁴⁵⁶⁷⁸⁹", "-0123456789")
    read = 0
    for tick in axis.get_major_ticks() + axis.get_minor_ticks():
        text = tick.label1.get_text()
        if not text or not tick.label1.get_visible():
            continue
        assert "$" not in text, text
        parts = re.fullmatch(r"(?:(\d+)×)?10([⁻⁰¹²³⁴⁵⁶⁷⁸⁹]+)", text)
        assert parts, text
        value = float(parts.group(1) or 1) * 10.0 ** int(parts.group(2).translate(digits))
        assert math.isclose(value, tick.get_loc(), rel_tol=1e-9), (text, tick.get_loc())
        read += 1
    assert read >= 3
