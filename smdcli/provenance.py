"""The command line a result came from, set once by the CLI and stored by every writer; the scipy it ran with.
Imports nothing at module level."""

from __future__ import annotations

_command_line = ""


def set_command_line(text: str) -> None:
    """Record the command as typed (the CLI calls this once)."""
    global _command_line
    _command_line = text


def command_line() -> str:
    """The command as typed, or "" when smd is used as a library."""
    return _command_line


def scipy_version() -> str:
    """scipy's version without importing scipy (0.1 s) or importlib.metadata (20 ms of a 0.4 s run): its own
    version.py, read as text; importlib.metadata where that file is not as scipy writes it."""
    import re
    import sys

    if "scipy" in sys.modules:
        return sys.modules["scipy"].__version__
    from importlib.util import find_spec

    spec = find_spec("scipy")
    try:
        from pathlib import Path

        text = (Path(spec.submodule_search_locations[0]) / "version.py").read_text()
        return re.search(r"""^version = ["']([^"']+)["']""", text, re.MULTILINE).group(1)
    except (AttributeError, TypeError, IndexError, OSError):
        from importlib.metadata import version

        return version("scipy")
