"""Self-describing options of estimators, controllers and scenario tables (standard library only).

An ``Options`` frozen dataclass whose fields carry an :class:`OptionSpec` (through
:func:`option`) *is* its scenario-file schema: :mod:`cdpr_twin.scenario.toml_reading` parses
such a table generically from each field's type and its spec (unit, bounds, file key). This
module is a leaf: estimators, controllers, the simulation and the scenario reader all use it,
and it imports nothing of the package.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any


class OptionError(ValueError):
    """An option value is invalid.

    Attributes:
        field: the option (as named in the Options dataclass) at fault.
    """

    def __init__(self, field: str, problem: str) -> None:
        super().__init__(f"{field}: {problem}")
        self.field = field
        self.problem = problem


@dataclasses.dataclass(frozen=True)
class OptionSpec:
    """How one option is written in a scenario file.

    Attributes:
        key: the key in the file (default: the field name, plus ``_deg`` for angles).
        unit: unit in the file (``"deg"`` is converted to radians; others are SI already).
        minimum: lowest allowed value (numbers).
        exclusive: the minimum itself is not allowed.
        infinite: ``inf`` is allowed (written ``inf`` in TOML: "no limit", "instant").
        pose: the value is a pose ``[x, y, z, rx, ry, rz]`` (m, deg) → (4, 4) transform.
        convert: applied to the parsed value (e.g. a frame change).
        doc: one line for error messages and listings.
        max_items: the most items a list may hold (lists), checked before any item is read.
        max_items_why: why, as the error says it after the bound.
    """

    key: str = ""
    unit: str = ""
    minimum: float | None = None
    exclusive: bool = False
    infinite: bool = False
    pose: bool = False
    convert: Callable[[Any], Any] | None = None
    doc: str = ""
    max_items: int | None = None
    max_items_why: str = ""

    def file_key(self, field_name: str) -> str:
        """The key of this option in a scenario file."""
        if self.key:
            return self.key
        return f"{field_name}_deg" if self.unit == "deg" else field_name


def option(default: Any = dataclasses.MISSING, **spec: Any) -> Any:
    """A dataclass field carrying its :class:`OptionSpec` (``unit=``, ``minimum=``…).

    Args:
        default: the default in SI units (radians for ``unit="deg"``); omit for a required option.
        **spec: the :class:`OptionSpec` fields.
    """
    meta = {"option": OptionSpec(**spec)}
    if isinstance(default, (list, dict, set)):
        raise TypeError("option defaults must be immutable (use a tuple)")
    return dataclasses.field(default=default, metadata=meta)


def spec_of(field: dataclasses.Field) -> OptionSpec:
    """The :class:`OptionSpec` of an Options field (a default one when none was given)."""
    return field.metadata.get("option", OptionSpec())


@dataclasses.dataclass(frozen=True)
class NoOptions:
    """Options of a plugin that has none."""
