"""What a user sees: progress bars under a real pseudo-terminal and strict JSON from every --json (the commands
the README and docs/ show are run by test_docs.py)."""

import json
import os
import re
import select
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import SCENARIOS

SMD = [sys.executable, "-m", "smdcli"]


def run_in_pty(args: list[str], cwd: Path, timeout: float = 240) -> tuple[int, str]:
    """Run smd with stdin, stdout and stderr on a pseudo-terminal, as at a shell; returns (exit code, screen text)."""
    import pty

    master, slave = pty.openpty()
    env = dict(os.environ, COLUMNS="120", TERM="xterm-256color")
    process = subprocess.Popen([*SMD, *args], stdin=slave, stdout=slave, stderr=slave, cwd=cwd, env=env,
                               close_fds=True)
    os.close(slave)
    chunks, deadline = [], time.monotonic() + timeout
    while True:
        ready, _, _ = select.select([master], [], [], 0.2)
        if ready:
            try:
                data = os.read(master, 65536)
            except OSError:  # the child closed the terminal
                break
            if not data:
                break
            chunks.append(data)
        elif process.poll() is not None:
            break
        assert time.monotonic() < deadline, "the command did not finish"
    os.close(master)
    return process.wait(timeout=30), b"".join(chunks).decode(errors="replace")


def plain(screen: str) -> str:
    """Terminal output without colour and cursor escapes."""
    return re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", screen).replace("\r", "\n")


@pytest.mark.parametrize("args, label", [
    (["compare-solvers", "scenarios/two_dof_forced.toml", "--methods", "ode45,ode23", "--tolerances",
      "1e-3/1e-6,1e-4/1e-6", "--repeats", "1"], "comparing"),
    (["sweep", "scenarios/one_dof_regimes_sweep.toml"], "sweeping"),
    (["sweep", "scenarios/duffing_frequency_response.toml", "--frequency", "5:8:1", "--direction", "up", "--no-plots"],
     "frequency response"),
    (["animate", "scenarios/one_dof_underdamped.toml", "--end", "1", "--fps", "10"], "drawing frames"),
    (["phase", "scenarios/one_dof_regimes_sweep.toml"], "phase portraits"),
    (["simulate", "scenarios/one_dof_underdamped.toml", "scenarios/one_dof_harmonic.toml", "--no-plots"], "simulating"),
    (["spectrum", str(SCENARIOS.parent / "records" / "synthetic_20s_100hz.csv"), "--no-plots"], "spectra"),
    (["optimize", "scenarios/tmd_one_dof.toml", "--param", "spring[1].k=0.5:2", "--minimize", "rms:primary",
      "--starts", "3", "--no-plots"], "starts"),
])
def test_long_commands_show_progress_on_a_terminal(tmp_path, args, label):
    """The crash the issue reported lived only at a terminal (click's progress bar API moved): each long command
    runs under a pseudo-terminal, draws its bar to the end (N/N) and exits 0."""
    (tmp_path / "scenarios").symlink_to(SCENARIOS)
    code, screen = run_in_pty(args, tmp_path)
    text = plain(screen)
    assert code == 0, text[-2000:]
    assert "Traceback" not in text and "internal error" not in text, text[-2000:]
    assert label in text, text[-2000:]
    done = re.findall(r"(\d+)/(\d+)", text)
    assert done and any(a == b for a, b in done), text[-2000:]


def test_piped_output_has_no_progress_bar(tmp_path):
    result = subprocess.run([*SMD, "sweep", str(SCENARIOS / "one_dof_regimes_sweep.toml"), "-o", str(tmp_path),
                             "--no-plots"], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert result.stderr == "" and "sweeping" not in result.stdout


def strict(text: str):
    """json.loads as strict parsers read JSON: NaN, Infinity and -Infinity are errors."""
    def refuse(token):
        raise ValueError(f"not JSON: {token}")

    return json.loads(text, parse_constant=refuse)


def test_every_json_output_is_strict_json_and_lists_every_file(cli, tmp_path):
    broken = tmp_path / "broken.toml"
    broken.write_text("[time]\nend = 1.0\n")
    outputs = {}
    for name, args in {
        "simulate": ["simulate", SCENARIOS / "one_dof_underdamped.toml", broken, SCENARIOS / "ic_critical.toml",
                     "--no-plots"],
        "simulate_fail_fast": ["simulate", broken, SCENARIOS / "one_dof_underdamped.toml", "--no-plots", "--fail-fast"],
        "info_linear": ["info", SCENARIOS / "three_dof_forced.toml"],
        "info_nonlinear": ["info", SCENARIOS / "one_dof_nonlinear_stiff.toml"],
        "info_bad": ["info", broken],
        "sweep_settling": ["sweep", SCENARIOS / "one_dof_regimes_sweep.toml", "--metric", "settling_time",
                           "--no-plots"],
        "sweep_undamped_peak": ["sweep", SCENARIOS / "frequency_response_zeta.toml", "--no-plots"],
        "compare": ["compare-solvers", SCENARIOS / "one_dof_undamped.toml", "--methods", "central_difference,RK45",
                    "--steps", "0.1,0.5", "--tolerances", "1e-3", "--no-plots", "--repeats", "1"],
    }.items():
        out = [] if args[0] == "info" else ["-o", tmp_path / name]
        result = cli(*args, "--json", *out)
        outputs[name] = (result.exit_code, strict(result.stdout))
    code, runs = outputs["simulate"]
    assert code == 2 and [r["status"] for r in runs] == ["ok", "input error", "ok"]
    assert runs[1]["scenario"] == str(broken) and "mass" in runs[1]["message"] and runs[1]["exit_code"] == 2
    code, runs = outputs["simulate_fail_fast"]
    assert code == 2 and [r["status"] for r in runs] == ["input error", "not run"]
    code, data = outputs["info_bad"]
    assert code == 2 and data["status"] == "input error"
    code, data = outputs["sweep_settling"]
    assert code == 0 and data["metric"]["per_member"]["No damping: zeta = 0"]["m"] is None
    assert data["nulls"]["/metric/per_member/No damping: zeta = 0/m"] == "NaN"
    code, data = outputs["sweep_undamped_peak"]
    assert code == 0 and any(p["amplitude"] is None for p in data["peaks"])
    assert "Infinity" in data["nulls"].values()
    code, data = outputs["compare"]
    assert code == 0 and all(r["dt"] is None for r in data["runs"] if r["adaptive"])  # no fixed step
    diff = cli("diff", tmp_path / "simulate" / "one_dof_underdamped.h5", tmp_path / "simulate" / "ic_critical.h5",
               "--json")
    assert diff.exit_code == 1 and strict(diff.stdout)["status"] == "different"
    missing = cli("diff", tmp_path / "nothing.h5", tmp_path / "simulate" / "ic_critical.h5", "--json")
    assert missing.exit_code == 2 and strict(missing.stdout)["status"] == "unusable"




def test_a_batch_prints_each_summary_on_clean_lines_with_the_bar_below(tmp_path):
    """Several files at a terminal: the bar is erased before each summary and drawn again under it, labelled with
    the file's name (not its whole path), and gone when the batch is done."""
    (tmp_path / "scenarios").symlink_to(SCENARIOS)
    code, screen = run_in_pty(["simulate", "scenarios/one_dof_underdamped.toml", "scenarios/one_dof_harmonic.toml",
                               "--no-plots"], tmp_path)
    assert code == 0, screen[-2000:]
    lines = plain(screen).splitlines()
    for stem in ("one_dof_underdamped", "one_dof_harmonic"):
        first = [line for line in lines if f"{stem}.toml:" in line]
        assert first and first[0].lstrip().startswith(f"scenarios/{stem}.toml:"), first  # nothing glued before it
    notes = [line for line in lines if "simulating" in line]
    assert notes and not any("scenarios/" in line for line in notes), notes  # the name, not the path
    assert "\x1b[2K" in screen  # the bar's line erased (Rich clears it before each summary and at the end)
