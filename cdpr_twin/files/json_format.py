"""The project's JSON files: strict RFC 8259 (an undefined number is ``null``), one format."""

from __future__ import annotations

import json
import math
from typing import Any


def finite_or_null(data: Any) -> Any:
    """``data`` with every non-finite float (NaN, ±∞) as ``None``: JSON (RFC 8259) has neither.

    A reader (``jq``, JavaScript, a strict parser) then gets ``null`` where a number is undefined
    — a deviation never measured, a run that did not reach p1 — instead of a bare ``NaN``.
    """
    if isinstance(data, float):
        return data if math.isfinite(data) else None
    if isinstance(data, dict):
        return {k: finite_or_null(v) for k, v in data.items()}
    if isinstance(data, list | tuple):
        return [finite_or_null(v) for v in data]
    return data


def json_text(data: dict | list) -> str:
    """The project's JSON files: RFC 8259 (undefined numbers ``null``), indented, final newline."""
    return json.dumps(finite_or_null(data), indent=2, sort_keys=False, allow_nan=False) + "\n"
