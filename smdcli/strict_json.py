"""Strict JSON for every `--json`: NaN and infinities become null, each named in a "nulls" map with its reason.

JavaScript's JSON.parse, jq and Python's json with parse_constant reject the
NaN and Infinity tokens that json.dumps writes by default. Imports nothing from smd.
"""

from __future__ import annotations

import json
import math
from typing import Any

STATUS = {0: "ok", 1: "failed", 2: "input error", 130: "interrupted", 143: "terminated"}


def status(exit_code: int | None) -> str:
    """The word for a file's outcome by its exit code ('not run' for None)."""
    return "not run" if exit_code is None else STATUS.get(exit_code, "failed")


def _reason(value: float) -> str:
    return "NaN" if math.isnan(value) else ("Infinity" if value > 0 else "-Infinity")


def _clean(value: Any, pointer: str, nulls: dict[str, str]) -> Any:
    if isinstance(value, dict):
        return {str(k): _clean(v, f"{pointer}/{str(k).replace('~', '~0').replace('/', '~1')}", nulls)
                for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_clean(v, f"{pointer}/{i}", nulls) for i, v in enumerate(value)]
    if hasattr(value, "tolist"):  # numpy scalars and arrays
        return _clean(value.tolist(), pointer, nulls)
    if isinstance(value, bool) or value is None or isinstance(value, (int, str)):
        return value
    if isinstance(value, float):
        if math.isfinite(value):
            return value
        nulls[pointer or "/"] = _reason(value)
        return None
    return str(value)


def dumps(data: Any) -> str:
    """JSON text that every strict parser reads; non-finite numbers are null, listed by JSON pointer under "nulls".

    For an object, "nulls" is added to it; for an array, to each object element that held one."""
    if isinstance(data, list):
        return json.dumps([_with_nulls(item) for item in data], indent=2, allow_nan=False)
    return json.dumps(_with_nulls(data), indent=2, allow_nan=False)


def _with_nulls(item: Any) -> Any:
    nulls: dict[str, str] = {}
    cleaned = _clean(item, "", nulls)
    if nulls:
        if isinstance(cleaned, dict):
            cleaned["nulls"] = nulls
        else:
            cleaned = {"value": cleaned, "nulls": nulls}
    return cleaned
