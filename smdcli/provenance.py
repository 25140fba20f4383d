"""The command line a result came from, set once by the CLI and stored by every writer. Imports nothing."""

from __future__ import annotations

_command_line = ""


def set_command_line(text: str) -> None:
    """Record the command as typed (the CLI calls this once)."""
    global _command_line
    _command_line = text


def command_line() -> str:
    """The command as typed, or "" when smd is used as a library."""
    return _command_line
