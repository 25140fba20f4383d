"""Atomic writing, the one helper every writer uses: a file is written under a temporary name beside its
final one and renamed when complete; inside together(), a run's files are renamed together at its end.
A signal received while writing (even one whose exception was swallowed) stops the rename.

Must not import: anything of smd but interrupts, errors and io.folders."""

from __future__ import annotations

import os
import tempfile
from contextlib import contextmanager, suppress
from pathlib import Path

from smdcli import interrupts

_pending: list[tuple[str, Path]] | None = None  # inside together(): renames waiting for the block's end
_kept: set[str] = set()  # temporary files that record progress (a streamed sweep's partial file): never discarded


def _commit(renames: list[tuple[str, Path]]) -> None:
    """Rename temporary files onto their final names, unless a signal came (even one whose exception was swallowed)."""
    from smdcli.errors import UsageError

    with interrupts.held():  # the check and the renames are one step for a signal
        interrupts.raise_if_received()
        for tmp, final in renames:
            try:
                os.replace(tmp, final)
            except OSError as exc:
                raise UsageError(f"{final}: cannot write: {exc.strerror or exc}") from None


def _discard(paths) -> None:
    with interrupts.held():
        for tmp in set(map(str, paths)) - _kept:
            with suppress(OSError):
                os.unlink(tmp)


@contextmanager
def together():
    """Files written with atomic_path inside the block appear together when it ends, or none of them does."""
    global _pending
    if _pending is not None:  # inside another: its end is the commit
        yield
        return
    _pending = []
    try:
        yield
        _commit(_pending)
    except BaseException as exc:
        _discard(tmp for tmp, _ in _pending)
        for tmp, _ in _pending:
            if tmp in _kept and isinstance(exc, KeyboardInterrupt):
                exc.add_note(f"{tmp} is kept; the same command with --resume finishes it")
        raise
    finally:
        _pending = None


@contextmanager
def atomic_path(final: Path):
    """Yield a temporary path beside `final`, its folder made as -o makes one; rename it onto `final` only if the
    block succeeds (inside together(): when that block ends). A file that cannot be written is a UsageError that
    names `final`, never the temporary name."""
    from smdcli.errors import UsageError
    from smdcli.io.folders import output_folder

    final = Path(final)
    if final.is_dir():
        raise UsageError(f"{final}: cannot write: a folder has that name; expected a file name")
    output_folder(final.parent)
    tmp = None
    try:
        # A signal is only recorded while the file is made: raised there, after the file appeared and before its name
        # came back, it left the file behind. It raises below, where the file is discarded.
        with interrupts.deferred(raise_after=False):
            fd, tmp = tempfile.mkstemp(prefix=f".{final.name}.", suffix=".part", dir=final.parent)
            os.close(fd)
        interrupts.raise_if_received()
        yield Path(tmp)
        # mkstemp makes the file private (0600); the result gets what the user's umask gives any new file.
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        if _pending is not None:
            _pending.append((tmp, final))
        else:
            _commit([(tmp, final)])
    except OSError as exc:
        if tmp is None:
            raise UsageError(f"{final}: cannot write: {exc.strerror or exc}") from None
        _discard([tmp])
        raise UsageError(f"{final}: cannot write: {_reason(exc, tmp)}") from None
    except BaseException:
        if tmp is not None:
            _discard([tmp])
        raise


def _reason(exc: OSError, tmp: str) -> str:
    """Why writing failed, in words that do not name the temporary file."""
    if exc.strerror:
        return exc.strerror
    text = str(exc).replace(tmp, "the file")
    return text.split(" (")[0] if "unable to" in text.lower() else text


@contextmanager
def resumable_path(partial: Path, final: Path):
    """Yield `partial`, a file that records its own progress (a streamed sweep): renamed onto `final` when the block
    succeeds (inside together(): when that block ends), and left where it is if anything fails, to be resumed."""
    partial, final = Path(partial), Path(final)
    _kept.add(str(partial))
    yield partial
    if _pending is not None:
        _pending.append((str(partial), final))
    else:
        _commit([(str(partial), final)])
