"""The README and docs/ as a newcomer reads them: the README short, its links alive, every `smd` command they show
run as written, every TOML block they show read by smd."""

from __future__ import annotations

import re
import shlex
import subprocess
import sys
import tomllib

import pytest
from conftest import ROOT

README = ROOT / "README.md"
PAGES = [README] + sorted((ROOT / "docs").glob("*.md"))


def shown_commands(path) -> list[str]:
    """Every `smd ...` command a page shows, inline or in a code block, that is runnable as written (synopses with
    placeholders such as SCENARIO or [--option] are forms, not commands)."""
    text = path.read_text()
    found = re.findall(r"`(smd [^`]+)`", text)
    found += [m.strip() for m in re.findall(r"^(?: {4}|\$ )\$? ?(smd .+)$", text, flags=re.M)]
    found += [m for m in re.findall(r"&& (smd .+)$", text, flags=re.M)]
    commands = []
    for command in found:
        command = command.split("  #")[0].strip()
        words = shlex.split(command)
        placeholder = any(re.fullmatch(r"[A-Z_]+(\.[a-z0-9]+)?", word) for word in words)
        names_a_file = any(re.search(r"\.(toml|h5|csv|txt)$", word) for word in words)
        measured = "{out}" in command  # a measured block's command, which benchmarks/docs_figures.py runs
        if placeholder or measured or not names_a_file or re.search(r"\[|\.\.\.|<", command):
            continue
        if command not in commands:
            commands.append(command)
    return commands


def blocks(path, language: str) -> list[str]:
    """The fenced code blocks of a page in one language."""
    return re.findall(rf"^```{language}\n(.*?)^```", path.read_text(), flags=re.M | re.S)


def toml_blocks(path) -> list[str]:
    """The ```toml blocks of a page."""
    return blocks(path, "toml")


def test_the_readme_is_read_in_two_minutes():
    text = README.read_text()
    assert len(text.splitlines()) < 250
    first_screen = "\n".join(text.splitlines()[:12])
    assert "python -m pip install -e '.[test]' && smd simulate scenarios/" in first_screen
    assert "python -m pip install -e '.[test]' && python -m pytest" in first_screen
    assert text.count("![") >= 1 and "```toml" in text


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_every_relative_link_resolves(page):
    for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", page.read_text()):
        if "://" not in target:
            assert (page.parent / target).exists(), f"{page.name}: {target}"


def test_the_pages_show_runnable_commands():
    commands = [c for page in PAGES for c in shown_commands(page)]
    assert len(commands) >= 20, commands
    assert {c.split()[1] for c in commands} >= {"simulate", "info", "compare-solvers", "sweep", "spectrum", "phase",
                                                 "draw", "animate", "diff", "export"}


@pytest.mark.slow
def test_every_command_shown_runs(tmp_path, cli, monkeypatch):
    """Each command of the README, then of each docs/ page, in order, in one folder that holds the repository's
    scenarios, records and tests, as a user at the repository root would: later commands read what earlier ones
    wrote (the docs/ pages read what the README's commands wrote). In this process, as the console script runs
    them (a process each spent 41 of the test's 91 s starting Python and importing); then the Python the pages
    show, each block a process of its own."""
    for name in ("scenarios", "records", "tests", "benchmarks"):
        (tmp_path / name).symlink_to(ROOT / name)
    (tmp_path / "chain.toml").write_text(toml_blocks(README)[0])  # "Save it as chain.toml"
    monkeypatch.chdir(tmp_path)
    failures = []
    for page in [README] + sorted(p for p in PAGES if p != README):
        for command in shown_commands(page):
            result = cli(*shlex.split(command)[1:])
            if result.exit_code != 0 or "Traceback" in result.output:
                failures.append(f"{page.name}: {command}: exit {result.exit_code}: {result.output[-500:]}")
    for page in PAGES:  # then the Python the pages show, where those commands left their files
        for code in blocks(page, "python"):
            result = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True,
                                    timeout=600)
            if result.returncode != 0:
                failures.append(f"{page.name}: python block: {result.stderr[-500:]}")
    assert not failures, "\n".join(failures)


BASE = {"time": {"end": 1.0, "step": 0.01},
        "mass": [{"name": "m1", "m": 1.0}, {"name": "m2", "m": 1.0}, {"name": "m3", "m": 1.0}]}


@pytest.mark.parametrize("page", [p for p in PAGES if toml_blocks(p)], ids=lambda p: p.name)
def test_every_toml_block_shown_is_read_by_smd(page, tmp_path):
    """A whole scenario is run as shown; a fragment (a table or two, as a reference shows them) is completed with
    [time] and three masses m1, m2, m3 where it has none, and must then be read and run."""
    import tomli_w

    from smdcli.cli import run as smd

    for i, block in enumerate(toml_blocks(page)):
        document = tomllib.loads(block)
        if "system" not in document:
            for key, value in BASE.items():
                document.setdefault(key, value)
        else:
            document.setdefault("time", BASE["time"])
        path = tmp_path / "scenarios" / f"block{i}.toml"
        path.parent.mkdir(exist_ok=True)
        path.write_text(tomli_w.dumps(document))
        (tmp_path / "tests").mkdir(exist_ok=True)
        if not (tmp_path / "records").exists():  # a scenario in scenarios/ names the shipped records as ../records
            (tmp_path / "records").symlink_to(ROOT / "records")
            (path.parent / "matrices").symlink_to(ROOT / "scenarios" / "matrices")  # and its matrix files so
        if not (tmp_path / "tests" / "golden").exists():
            (tmp_path / "tests" / "golden").symlink_to(ROOT / "tests" / "golden")
        code = smd(["simulate", str(path), "-o", str(tmp_path / "out"), "--no-plots", "--quiet"])
        allowed = (0, 1) if "expect" in document else (0,)  # 1: an [[expect]] shown of another scene fails
        assert code in allowed, f"{page.name} block {i}: exit {code}\n{block}"


MEASURED = re.compile(r"<!-- measured: (?P<command>.+?) -->\n(?P<body>.*?)<!-- /measured -->", re.S)
# A timing quoted in prose: a figure that belongs in a measured block.
TIMING = re.compile(r"\b\d[\d,.]*\s?(?:ms|us)\b|\d\s?x (?:faster|slower)|\d times (?:faster|slower)|\bs wall\b"
                    r"|\b(?:about|takes?|took|in) \d[\d,.]* (?:s|seconds|minutes)\b")


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_timings_are_quoted_from_the_script_that_measures_them(page):
    """Every time the docs quote is printed by the command of a measured block (benchmarks/docs_figures.py reruns
    them and names the machine), never typed by hand."""
    text = page.read_text()
    by_hand = [line for line in MEASURED.sub("", text).splitlines() if TIMING.search(line)]
    assert not by_hand, by_hand
    for found in MEASURED.finditer(text):
        words = shlex.split(found["command"])
        assert words[0] in ("python", "smd"), found["command"]
        if words[0] == "python":
            assert (ROOT / words[1]).is_file(), found["command"]
        assert found["body"].startswith("Measured ") and f"$ {found['command']}\n" in found["body"], \
            f"{page.name}: `{found['command']}` has not been measured (python benchmarks/docs_figures.py)"


def test_the_performance_page_is_measured():
    text = (ROOT / "docs" / "performance.md").read_text()
    commands = [m["command"] for m in MEASURED.finditer(text)]
    assert any("exact_vs_rk45" in c for c in commands) and any("compiled_vs_solve_ivp" in c for c in commands)
    assert any("sweep_vs_rk45" in c for c in commands)


def test_the_solvers_table_lists_exactly_the_registered_methods():
    """docs/solvers.md's table of methods names every method of the registry, and no other."""
    from smdcli.solvers.registry import NAMES

    rows = [line for line in (ROOT / "docs" / "solvers.md").read_text().splitlines() if line.startswith("| `")]
    listed = [name for row in rows for name in re.findall(r"`([^`]+)`", row.split("|")[1])]
    assert sorted(listed) == sorted(NAMES)


def test_compare_solvers_defaults_are_the_registrys_and_the_docs_say_so():
    """docs/compare-solvers.md lists compare-solvers' default methods as the registry's compare groups, in order."""
    from smdcli.solvers.registry import names

    text = (ROOT / "docs" / "compare-solvers.md").read_text()
    for group in ("adaptive", "fixed"):
        assert f"`{','.join(names(compare=group))}`" in text, group
