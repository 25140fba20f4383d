"""Record files as engineers download them: PEER NGA .AT2, COSMOS v1.20 volume 2, two-column and one-column text.
Each format read to the last digit written, its unit and sampling found; every malformed file refused in one line
naming the file and the line, exit 2, nothing written; the bundled suite regenerated bit for bit."""

from __future__ import annotations

import json

import numpy as np
import pytest

import smdcli
from smdcli.scenario.record_files import read_samples
from conftest import ROOT

G = 9.80665
VALUES = ["  .1234567E-02", " -.2345678E-01", "  .3456789E+00", " -.4567891E-03", "  .5678912E-02",
          "  .6789123E-01", " -.7891234E-02"]


def at2(values=VALUES, unit="G", sampling="NPTS=      7, DT=   .0050 SEC", newline="\r\n", per_line=5) -> str:
    """An AT2 file's text: four header lines and the values, per_line a line."""
    lines = ["PEER NGA STRONG MOTION DATABASE RECORD", "TEST 1/1/00, STATION, 000",
             f"ACCELERATION TIME SERIES IN UNITS OF {unit}", sampling]
    lines += ["".join(values[i:i + per_line]) for i in range(0, len(values), per_line)]
    return newline.join(lines) + newline


def cosmos_series(values: list[str], channel: int, quantity: str = "acceleration", code: int = 4,
                  dt_ms: float = 10.0) -> list[str]:
    """One COSMOS v1.20 V2 series with its headers; values as written in (8F10.5) fields."""
    integers = [-999] * 100
    integers[0], integers[1], integers[2], integers[49] = 2, 1 if quantity == "acceleration" else 2, code, channel
    reals = [-999.0] * 100
    reals[61], reals[62] = dt_ms, dt_ms * len(values) / 1000
    lines = [f"Corrected {quantity}  (Format v01.20 with 13 text lines) Src: test"] + [f"text {i}" for i in range(12)]
    lines.append("  100 Integer-header values follow on  10 lines, Format= (10I8)")
    lines += ["".join(f"{v:8d}" for v in integers[i:i + 10]) for i in range(0, 100, 10)]
    lines.append("  100 Real-header values follow on  17 lines, Format= (6F13.3)")
    lines += ["".join(f"{v:13.3f}" for v in reals[i:i + 6]) for i in range(0, 100, 6)]
    lines += ['    2 Comment line(s) follow, each starting with a "|":', "| one", "| two"]
    lines.append(f"{len(values):8d} {quantity} pts, approx    0 secs, units=cm/sec2 ({code:02d}), Format=(8F10.5)")
    lines += ["".join(values[i:i + 8]) for i in range(0, len(values), 8)]
    lines.append(f"End-of-data for Chan {channel:2d} {quantity}")
    return lines


FIRST = ["   1.23456", "  -2.34567", "-123.45678", "   0.00001", "  12.00000", "  -0.50000", "   3.14159",
         "   2.71828", "  -9.87654", "   0.12345"]  # ten: a second line of two; the third value fills its field
SECOND = ["   0.10000", "  -0.20000", "   0.30000"]


@pytest.mark.parametrize("sampling,newline", [("NPTS=      7, DT=   .0050 SEC", "\r\n"),
                                              ("   7    0.0050    NPTS, DT", "\n")])
def test_an_at2_file_is_read_to_the_last_digit_in_either_layout(sampling, newline, tmp_path):
    """Both layouts of the NPTS/DT line, CRLF or LF: the values exactly as Python reads their text, times i DT, the
    unit G from line 3."""
    path = tmp_path / "rec.AT2"
    path.write_bytes(at2(sampling=sampling, newline=newline).encode())
    samples = read_samples(path)
    assert samples.format == "at2" and samples.units == "g"
    assert samples.values.tolist() == [float(v) for v in VALUES]
    assert samples.times.tolist() == (0.005 * np.arange(7)).tolist()


@pytest.mark.parametrize("unit,name,factor", [("G", "g", G), ("GAL", "cm/s^2", 0.01), ("CM/S^2", "cm/s^2", 0.01),
                                              ("CM/SEC/SEC", "cm/s^2", 0.01), ("M/S^2", "m/s^2", 1.0)])
def test_an_at2_file_s_unit_converts_the_record(unit, name, factor, tmp_path):
    """GAL is cm/s^2 (not the gallon): smd record reads the values times the unit, in m/s^2."""
    path = tmp_path / "rec.at2"
    path.write_text(at2(unit=unit))
    record = smdcli.read_record(path)
    assert record.units == name and record.format == "at2"
    assert record.acceleration == pytest.approx([float(v) * factor for v in VALUES], rel=1e-15)


def test_a_cosmos_file_s_channels_are_read_to_the_last_digit(tmp_path):
    """A V2 file with channel 1's acceleration and velocity and channel 2's acceleration: channel = N is the N-th
    acceleration series (the velocity skipped), its values as written, dt from the real header's 62nd value (ms),
    the unit from the integer header's 3rd (4: cm/s^2; 2: g; 11: mg, read as 1e-3 g)."""
    path = tmp_path / "rec.V2"
    lines = cosmos_series(FIRST, 1) + cosmos_series(SECOND, 1, "velocity", 5) + \
        cosmos_series(SECOND, 2, code=2, dt_ms=5.0)
    path.write_text("\n".join(lines) + "\n")
    first = read_samples(path)
    assert (first.format, first.units, first.channel) == ("cosmos", "cm/s^2", 1)
    assert first.values.tolist() == [float(v) for v in FIRST]
    assert first.times.tolist() == (0.01 * np.arange(10)).tolist()
    second = read_samples(path, channel=2)
    assert (second.units, second.values.tolist()) == ("g", [0.1, -0.2, 0.3])
    assert second.times[1] == 0.005
    milli = tmp_path / "milli.v2c"
    milli.write_text("\n".join(cosmos_series(SECOND, 1, code=11)) + "\n")
    record = smdcli.read_record(milli)
    assert record.units == "g" and record.acceleration == pytest.approx([1e-3 * G * float(v) for v in SECOND],
                                                                         rel=1e-15)


@pytest.mark.parametrize("separator", [",", " ", "\t"])
def test_one_column_text_with_dt_and_a_header(separator, tmp_path):
    """One value a line after header lines, at the given dt; two-column text of the same separators as before."""
    path = tmp_path / "rec.txt"
    path.write_text("acceleration (g)\n# a comment\n" + "\n".join(v.strip() for v in VALUES) + "\n")
    samples = read_samples(path, dt=0.02)
    assert samples.format == "one_column" and samples.values.tolist() == [float(v) for v in VALUES]
    assert samples.times[-1] == pytest.approx(0.12, rel=1e-15)
    two = tmp_path / "two.csv"
    two.write_text("t" + separator + "a\n" + "\n".join(f"{0.01 * i:.2f}{separator}{v.strip()}"
                                                       for i, v in enumerate(VALUES)) + "\n")
    assert read_samples(two).values.tolist() == [float(v) for v in VALUES]


MALFORMED = {
    "truncated.AT2": (at2(sampling="NPTS=      9, DT=   .0050 SEC"), "line 6: expected 9 acceleration values"),
    "long.AT2": (at2(sampling="NPTS=      4, DT=   .0050 SEC"), "line 5: expected 4 acceleration values in all"),
    "unit.AT2": (at2(unit="FT/S^2"), "line 3: expected the unit"),
    "negative.AT2": (at2(sampling="NPTS=      7, DT=  -.0050 SEC"), "line 4: expected a positive DT"),
    "cell.AT2": (at2(values=VALUES[:5] + ["  abc", " .1E-02"]), "line 6: expected acceleration values (numbers)"),
    "noheader.AT2": ("1 2 3\n", "expected an AT2 file's four header lines"),
    "short.V2": ("\n".join(cosmos_series(FIRST, 1)[:-3]) + "\n", "expected 10 acceleration values, the file ends"),
}


@pytest.mark.parametrize("name", sorted(MALFORMED))
def test_a_malformed_record_file_is_one_line_exit_2_naming_its_line_and_nothing_is_written(name, cli, tmp_path):
    """smd record and a scenario's [ground_motion] both refuse it: exit 2, one line naming the file and the line,
    no output folder."""
    text, expected = MALFORMED[name]
    path = tmp_path / name
    path.write_text(text)
    ran = cli("record", path, "-o", tmp_path / "out")
    assert ran.exit_code == 2 and len(ran.output.strip().splitlines()) == 1, ran.output
    assert name in ran.output and expected in ran.output, ran.output
    scene = tmp_path / "scene.toml"
    scene.write_text(SCENE.format(file=path.as_posix(), extra=""))
    ran = cli("simulate", scene, "-o", tmp_path / "out")
    assert ran.exit_code == 2 and "ground_motion.file" in ran.output and expected in ran.output, ran.output
    assert not (tmp_path / "out").exists()


SCENE = """
[time]
end = 0.03
step = 0.005
[[mass]]
name = "m"
m = 1.0
[[spring]]
connects = ["ground", "m"]
k = 400.0
[ground_motion]
quantity = "acceleration"
type = "table"
file = "{file}"
{extra}
"""


def test_a_scenario_s_ground_motion_reads_a_record_file_with_its_own_unit(tmp_path, cli):
    """An AT2 record drives the scene as the same samples in a two-column file in g do (to rounding); a units key
    that disagrees with the file's, dt on an AT2 and channel on text are refused naming the key."""
    path = tmp_path / "rec.AT2"
    path.write_text(at2())
    same = tmp_path / "rec.csv"
    same.write_text("\n".join(f"{0.005 * i!r},{v.strip()}" for i, v in enumerate(VALUES)) + "\n")
    scenes = {}
    for name, file, extra in (("at2", path, ""), ("csv", same, 'units = "g"')):
        scenes[name] = tmp_path / f"{name}.toml"
        scenes[name].write_text(SCENE.format(file=file.as_posix(), extra=extra))
    a, b = smdcli.simulate(scenes["at2"]), smdcli.simulate(scenes["csv"])
    assert np.abs(a.displacement - b.displacement).max() <= 1e-15 * np.abs(b.displacement).max()
    for extra, key, message in (('units = "m/s^2"', "units", "disagrees"), ("dt = 0.01", "dt", "gives its own"),
                                ("channel = 2", "channel", "only a COSMOS file")):
        bad = tmp_path / "bad.toml"
        bad.write_text(SCENE.format(file=(same if key == "channel" else path).as_posix(), extra=extra))
        ran = cli("simulate", bad, "-o", tmp_path / "out")
        assert ran.exit_code == 2 and f"ground_motion.{key}" in ran.output and message in ran.output, ran.output


def test_smd_record_prints_the_format_units_and_sampling_found(cli, tmp_path):
    """The terminal line and --json name the format, the unit and the sampling; the HDF5 source keeps them."""
    import h5py

    ran = cli("record", ROOT / "records" / "suite" / "record_05.V2", "--channel", "2", "-o", tmp_path, "--json",
              "--no-plots")
    data = json.loads(ran.output)
    assert (data["format"], data["channel"], data["units_in_file"], data["step_s"]) == ("cosmos", 2, "cm/s^2", 0.01)
    with h5py.File(tmp_path / "record_05_record.h5") as f:
        assert f["source"].attrs["format"] == "cosmos" and f["source"].attrs["channel"] == 2
    ran = cli("record", ROOT / "records" / "suite" / "record_01.AT2", "-o", tmp_path, "--no-plots")
    assert "at2 in g, 1750 samples every 0.01 s" in ran.output, ran.output


def test_the_bundled_suite_is_regenerated_bit_for_bit_and_starts_and_ends_at_rest(tmp_path, monkeypatch):
    """records/make_record_suite.py writes the twelve files again byte for byte; each reads, and the velocity and
    displacement integrated from it end within 1e-4 of their peaks (its baseline removed; the files' rounding of
    the values, 1e-7 g, leaves 6e-6)."""
    import importlib.util

    from scipy.integrate import cumulative_trapezoid

    spec = importlib.util.spec_from_file_location("make_record_suite", ROOT / "records" / "make_record_suite.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    monkeypatch.setattr(module, "SUITE", tmp_path)
    module.main()
    bundled = sorted((ROOT / "records" / "suite").iterdir())
    assert [p.name for p in bundled] == sorted(p.name for p in tmp_path.iterdir()) and len(bundled) == 12
    for path in bundled:
        assert path.read_bytes() == (tmp_path / path.name).read_bytes(), path.name
        record = smdcli.read_record(path)
        velocity = cumulative_trapezoid(record.acceleration, record.time, initial=0.0)
        displacement = cumulative_trapezoid(velocity, record.time, initial=0.0)
        assert abs(velocity[-1]) <= 1e-4 * np.abs(velocity).max(), path.name
        assert abs(displacement[-1]) <= 1e-4 * np.abs(displacement).max(), path.name
