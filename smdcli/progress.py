"""Progress of long commands: one Rich bar on stderr, shown on a terminal only.

Every long command (simulate batches, sweep, compare-solvers, frequency
responses, phase, animate) reports through `bar(label, total)`, a context
manager yielding `advance(count=1, note=None)`. The library calls `advance`
whatever the output is; the CLI decides with `wanted(...)` whether a bar is
drawn. Imports nothing from smd but interrupts.
"""

from __future__ import annotations

import sys
from contextlib import contextmanager
from typing import Callable, Iterator

Advance = Callable[..., None]


def silent(count: int = 1, note: str | None = None) -> None:
    """An advance that draws nothing (piped output, --quiet, --json, library use)."""


def _print(text: str) -> None:
    print(text, flush=True)


silent.above = _print  # type: ignore[attr-defined]  # where no bar is drawn, text is just printed

def wanted(quiet: bool = False, as_json: bool = False) -> bool:
    """Whether a bar should be drawn: stderr is a terminal and the user asked for text."""
    return not (quiet or as_json) and sys.stderr.isatty()


@contextmanager
def bar(label: str, total: int, enabled: bool = True, transient: bool = False) -> Iterator[Advance]:
    """A bar of `total` steps labelled `label`; yields advance(count=1, note=None), where `note` names the work now
    running. A transient bar is erased when done, and its advance.above(text) prints text on stdout above it: the bar
    is erased first and drawn again below (a bar glued to the text it shares a terminal with reads as garbage)."""
    if not enabled:
        yield silent
        return
    from rich.console import Console
    from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn,
                               TimeRemainingColumn)

    from smdcli.interrupts import deferred

    console = Console(file=sys.stderr)
    columns = (TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
               TextColumn("eta"), TimeRemainingColumn(), TextColumn("{task.fields[note]}", style="dim"))
    progress = Progress(*columns, console=console, transient=transient, refresh_per_second=8)
    with deferred():  # its refresh thread starts and stops under locks that an interrupt must not cut
        progress.start()
    try:
        task = progress.add_task(label, total=max(total, 1), note="")

        def advance(count: int = 1, note: str | None = None) -> None:
            fields = {} if note is None else {"note": note}
            progress.update(task, advance=count, **fields)

        def above(text: str) -> None:
            if not transient:
                raise ValueError("above() needs a transient bar: a stopped one stays on screen")
            with deferred():
                progress.stop()  # transient: the bar's line is cleared
                _print(text)
                progress.start()

        advance.above = above  # type: ignore[attr-defined]
        yield advance
    finally:
        with deferred(raise_after=False):
            progress.stop()
