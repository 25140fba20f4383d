"""Output folders: made when missing, refused in one line when they cannot be written.

Must not import: anything of smd above errors.
"""

from __future__ import annotations

import os
from pathlib import Path

from smdcli.errors import UsageError


def output_folder(out: str | Path, make: bool = True) -> Path:
    """Create the output folder if needed (make) or only check that it could be (the writers make it when they
    write: a refused run leaves no empty folder behind); refuse one that cannot be written."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise UsageError(f"{out}: is not a folder (a file of that name exists); give an output folder with -o")
    if not make and not out.exists():
        parent = next(p for p in out.absolute().parents if p.exists())
        if not parent.is_dir():
            raise UsageError(f"{out}: cannot create output folder: {parent} is not a folder")
        if not os.access(parent, os.W_OK | os.X_OK):
            raise UsageError(f"{out}: cannot create output folder: {parent} is not writable")
        return out
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UsageError(f"{out}: cannot create output folder: {exc.strerror}") from None
    if not out.is_dir():
        raise UsageError(f"{out}: is not a folder")
    if not os.access(out, os.W_OK | os.X_OK):
        raise UsageError(f"{out}: output folder is not writable")
    return out
