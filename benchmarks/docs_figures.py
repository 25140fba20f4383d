"""Re-measure every figure the docs quote: each `<!-- measured: COMMAND -->` ... `<!-- /measured -->` block in
README.md and docs/*.md is replaced by what COMMAND prints on this machine, under a line naming the machine, the
date and the versions. The docs quote no timing by hand: a test checks that the performance page's and the
README's timings sit in such blocks.

    python benchmarks/docs_figures.py            run every block's command and rewrite the blocks
    python benchmarks/docs_figures.py --list     the blocks and their commands, nothing run
    python benchmarks/docs_figures.py --only exact_vs_rk45   the blocks whose command contains this text

COMMAND is run from the repository root with this Python (`python` in it means sys.executable); `smd` means this
Python's smd, and `{out}` in an smd command a temporary output folder (its `wrote` lines are left out). A command that fails leaves its block as it was and the script exits 1.
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import re
import shlex
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BLOCK = re.compile(r"(<!-- measured: (?P<command>.+?) -->\n)(?P<body>.*?)(<!-- /measured -->)", re.S)


def documents() -> list[Path]:
    """The files whose measured blocks this script keeps: README.md and every page of docs/."""
    return [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def blocks(text: str):
    """(command, body) of each measured block in a document's text."""
    return [(m["command"], m["body"]) for m in BLOCK.finditer(text)]


def machine() -> str:
    """One line: the date, the CPU, its cores, and the versions that decide the timings."""
    import numpy
    import scipy

    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return (f"{datetime.date.today().isoformat()}, {cpu}, {os.cpu_count()} cores, Python "
            f"{platform.python_version()}, numpy {numpy.__version__}, scipy {scipy.__version__}")


def argv(command: str) -> list[str]:
    """The command's words with `python` and `smd` bound to this interpreter."""
    words = shlex.split(command)
    if words[0] == "python":
        return [sys.executable, *words[1:]]
    if words[0] == "smd":
        return [sys.executable, "-m", "smdcli", *words[1:]]
    return words


def measure(command: str, stamp: str) -> str:
    """The block's new body: the stamp and what the command printed, as a text block."""
    words = argv(command)
    with tempfile.TemporaryDirectory() as out:
        if command.startswith("smd "):  # its output folder; a timing script makes its own
            words = [w.replace("{out}", out) for w in words]
        done = subprocess.run(words, cwd=ROOT, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"`{command}` exited {done.returncode}: {done.stderr.strip()[-400:]}")
    printed = [line for line in done.stdout.rstrip().splitlines() if not line.strip().startswith("wrote ")]
    return f"Measured {stamp}:\n\n```text\n$ {command}\n" + "\n".join(printed) + "\n```\n"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--list", action="store_true", help="list the blocks, run nothing")
    parser.add_argument("--only", default="", help="only the blocks whose command contains this text")
    args = parser.parse_args()
    stamp, failed = machine(), 0
    for path in documents():
        text = path.read_text()
        found = [(c, b) for c, b in blocks(text) if args.only in c]
        if not found:
            continue
        if args.list:
            for command, _ in found:
                print(f"{path.relative_to(ROOT)}: {command}")
            continue

        def replace(match: re.Match) -> str:
            nonlocal failed
            if args.only not in match["command"]:
                return match[0]
            print(f"{path.relative_to(ROOT)}: {match['command']}", file=sys.stderr, flush=True)
            try:
                body = measure(match["command"], stamp)
            except RuntimeError as error:
                print(f"  failed: {error}", file=sys.stderr)
                failed += 1
                return match[0]
            return match[1] + body + match[4]

        path.write_text(BLOCK.sub(replace, text))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
