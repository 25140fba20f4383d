"""Every category of bad input: exit 2, one line naming file and field, no traceback, nothing written."""

from pathlib import Path

import pytest

CORPUS = Path(__file__).resolve().parent / "bad_scenarios"
EXPECTED = dict(line.split("\t", 1) for line in (CORPUS / "EXPECTED.tsv").read_text().splitlines()
                if line and not line.startswith("#"))


def test_the_corpus_is_complete():
    files = {p.name for p in CORPUS.iterdir() if p.suffix == ".toml"}
    assert files == set(EXPECTED) - {"does_not_exist.toml"}
    assert len(EXPECTED) >= 40


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_bad_scenario_exit_2_one_line_nothing_written(name, tmp_path, cli):
    """tests/bad_scenarios/: exit 2, one line naming the file and the field, no traceback, nothing written,
    and an earlier output of the same name untouched."""
    scenario = CORPUS / name
    out = tmp_path / "out"
    out.mkdir()
    keep = out / f"{scenario.stem}.h5"
    keep.write_bytes(b"an earlier result")
    result = cli("simulate", scenario, "-o", out)
    assert result.exit_code == 2, result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith(f"smd: {scenario}"), lines[0]
    assert EXPECTED[name] in lines[0], lines[0]
    assert "Traceback" not in result.output
    assert sorted(p.name for p in out.iterdir()) == [keep.name]
    assert keep.read_bytes() == b"an earlier result"


VALID = (CORPUS / "zero_mass.toml").read_text().replace("m = 0.0", "m = 1.0")


def test_unwritable_output_folder(tmp_path, cli):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    scenario = tmp_path / "ok.toml"
    scenario.write_text(VALID)
    result = cli("simulate", scenario, "-o", blocker / "sub")
    assert result.exit_code == 2
    assert "cannot create output folder" in result.stderr


def test_a_fifo_is_refused_at_once_as_scenario_and_as_table_file(tmp_path, cli):
    """Reading a named pipe would wait for a writer forever: it is refused without being read."""
    import os
    import time

    fifo = tmp_path / "pipe.toml"
    os.mkfifo(fifo)
    scene = tmp_path / "table.toml"
    scene.write_text(VALID + '\n[[force]]\non = "m1"\ntype = "table"\nfile = "pipe.toml"\n')
    for target, message in ((fifo, "is a named pipe (FIFO), expected a scenario"),
                            (scene, "file: " + str(fifo) + ": is a named pipe (FIFO)")):
        start = time.monotonic()
        result = cli("simulate", target, "-o", tmp_path / "out")
        assert time.monotonic() - start < 10
        assert result.exit_code == 2 and message in result.stderr and result.stderr.count("\n") == 1
    assert not (tmp_path / "out").exists() or not list((tmp_path / "out").iterdir())
