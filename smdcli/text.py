"""Words for the terminal: counted nouns and text made safe to print. Imports nothing of smd (the bottom layer)."""

from __future__ import annotations


def plural(count: int, noun: str, plural_form: str | None = None) -> str:
    """'1 force segment', '3 force segments', '2 trajectories' (with plural_form given)."""
    return f"{count} {noun if count == 1 else (plural_form or noun + 's')}"


def printable(text: str) -> str:
    """Text with control characters (terminal escapes, NUL, bells, line breaks) shown as escapes: one safe line."""
    return "".join(c if c.isprintable() or c == " " else repr(c)[1:-1] for c in text)
