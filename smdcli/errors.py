"""The exceptions smd raises; the CLI turns each into one line and an exit code.

Imports nothing of smd but text (the bottom layer).
"""

from __future__ import annotations

from smdcli.text import printable


class SmdError(Exception):
    """Base of every error smd reports to a user; its message is one printable line."""

    exit_code = 1

    def __str__(self) -> str:
        return printable(super().__str__())


class ScenarioError(SmdError):
    """Bad input: names the file, the field path and, for TOML syntax, the line."""

    exit_code = 2

    def __init__(self, file: str, field: str | None, message: str, line: int | None = None):
        self.file = file
        self.field = field
        self.message = message
        self.line = line
        where = [str(file)]
        if line is not None:
            where.append(f"line {line}")
        if field:
            where.append(field)
        super().__init__(": ".join(where + [message]))


class UsageError(SmdError):
    """A command was called in a way that cannot work (bad option, unwritable folder)."""

    exit_code = 2


class SolverFailed(SmdError):
    """A solver did not reach the end time; says where and why."""

    exit_code = 1

    def __init__(self, message: str, result=None):
        self.result = result
        super().__init__(message)
