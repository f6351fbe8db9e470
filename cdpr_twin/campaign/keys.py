"""Dotted keys into a scenario's data, the id of a resolved scenario, and the files it reads."""

from __future__ import annotations

import copy
import hashlib
import json
from collections.abc import Iterable
from pathlib import Path
from typing import Any


def set_dotted(data: dict, key: str, value: Any) -> None:
    """Set ``data[a][b]…[z] = value`` for ``key = "a.b….z"`` (tables created as needed).

    Raises:
        KeyError: a part of the path is not a table.
    """
    parts = key.split(".")
    node = data
    for part in parts[:-1]:
        node = node.setdefault(part, {})
        if not isinstance(node, dict):
            raise KeyError(f"{part!r} in {key!r} is not a table")
    node[parts[-1]] = copy.deepcopy(value)


def run_id(data: dict) -> str:
    """The id of a resolved scenario: 16 hex digits of its canonical JSON's SHA-256."""
    text = json.dumps(data, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def as_read(value: Any) -> Any:
    """``value`` with every integer as a float (bools kept): two runs' data equal so are one run.

    A float field reads 0 and 0.0 alike, and an integer field refuses 1.0, so data that differ
    only there were either one scenario or refused.
    """
    if isinstance(value, dict):
        return {k: as_read(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [as_read(v) for v in value]
    if isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    return value


def input_files(tasks: Iterable[Any]) -> list[Path]:
    """The files the runs read beside their scenario data (a run's id does not hold them).

    ``model.file``, ``model.nominal`` and ``.py`` plugins, resolved beside each task's
    scenario file; shipped robots (``model.robot``) are the package's own.
    """
    found: set[Path] = set()
    for task in tasks:
        base, model = Path(task.source).parent, task.data.get("model", {})
        refs = [model.get("file"), model.get("nominal")]
        refs += [p for p in task.data.get("plugins", []) if str(p).endswith(".py")]
        found |= {(base / r).resolve() for r in refs if isinstance(r, str)}
    return sorted(found)


def digests(paths: list[Path]) -> dict[str, str]:
    """SHA-256 of each readable file, by path (a file that cannot be read: its error)."""
    out = {}
    for path in paths:
        try:
            out[str(path)] = hashlib.sha256(path.read_bytes()).hexdigest()
        except OSError as exc:
            out[str(path)] = f"unreadable: {exc.strerror}"
    return out


def changed_inputs(recorded: dict[str, str], now: dict[str, str]) -> list[str]:
    """The files whose content differs from when the runs already made were made."""
    return [p for p, digest in recorded.items() if p in now and now[p] != digest]
