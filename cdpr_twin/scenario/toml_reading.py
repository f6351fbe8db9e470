"""Typed, unit-aware reading of TOML tables, and generic parsing of options dataclasses.

This is the file edge: poses are written ``[x, y, z, rx, ry, rz]`` in metres and degrees,
angles elsewhere carry ``_deg`` in their key, and everything is converted to SI here. Errors
name the file, the field and the fix. :func:`parse_options` reads any frozen dataclass whose
fields carry :func:`cdpr_twin.plugins.option` metadata: estimators', controllers' and events'
options are parsed by this one function, from their own declarations.
"""

from __future__ import annotations

import dataclasses
import math
import typing
from collections.abc import Mapping
from typing import Any, Literal

import numpy as np

from cdpr_twin.files.inputs import elided, shown
from cdpr_twin.math.se3 import pose_from_vector
from cdpr_twin.options import OptionError, spec_of

MAX_POSITION = 1000.0
"""The largest coordinate of a pose's position in a file [m]: the largest cable robots span
hundreds of metres; beyond a kilometre the number is a typo (and 1e308 overflows the frame's
arithmetic)."""


class ScenarioError(ValueError):
    """A scenario file is missing, malformed, or has a bad field."""


def _frozen_array(a: Any) -> np.ndarray:
    out = np.array(a, dtype=float)
    out.flags.writeable = False
    return out


def _is_number(v: Any) -> bool:
    return not isinstance(v, bool) and isinstance(v, (int, float)) and math.isfinite(v)


class OptionReader:
    """Typed, unit-aware access to one TOML table, with errors naming file and field.

    Args:
        source: the file (for messages).
        table: the table's content.
        where: the table's dotted name (``""`` for the top level).
    """

    def __init__(self, source: Any, table: Mapping[str, Any], where: str) -> None:
        self.source, self.table, self.where = source, table, where
        self.used: set[str] = set()

    def fail(self, key: str, problem: str) -> ScenarioError:
        """An error naming the file and ``<table>.<key>`` (a long key elided)."""
        name = elided(f"{self.where}.{key}" if self.where else key)
        return ScenarioError(f"{self.source}: {name}: {problem}")

    def has(self, key: str) -> bool:
        """Whether the table sets ``key``."""
        return key in self.table

    def raw(self, key: str, default: Any = ..., kind: str = "") -> Any:
        """The value as written (``default`` when absent; required when no default)."""
        self.used.add(key)
        if key in self.table:
            return self.table[key]
        if default is ...:
            raise self.fail(key, f"missing; add {key} = <{kind}>")
        return default

    def number(
        self,
        key: str,
        default: Any = ...,
        minimum: float | None = None,
        exclusive: bool = False,
        unit: str = "",
        value: Any = ...,
        infinite: bool = False,
    ) -> float:
        """A finite number (or ``inf`` where ``infinite``), at least ``minimum``."""
        v = self.raw(key, default, f"number{' ' + unit if unit else ''}") if value is ... else value
        if not (_is_number(v) or (infinite and isinstance(v, float) and v == math.inf)):
            what = "a finite number or inf" if infinite else "a finite number"
            raise self.fail(key, f"must be {what}{' in ' + unit if unit else ''}, got {shown(v)}")
        if minimum is not None and (v <= minimum if exclusive else v < minimum):
            raise self.fail(
                key,
                f"must be {'>' if exclusive else '≥'} {minimum}"
                f"{' ' + unit if unit else ''}, got {shown(v)}",
            )
        return float(v) + 0.0  # a file's -0.0 is zero: +0.0 (numpy refuses a scale of -0.0)

    def integer(self, key: str, default: Any = ..., minimum: int | None = None) -> int:
        """An integer, at least ``minimum``."""
        v = self.raw(key, default, "integer")
        if isinstance(v, bool) or not isinstance(v, int):
            raise self.fail(key, f"must be an integer, got {shown(v)}")
        if minimum is not None and v < minimum:
            raise self.fail(key, f"must be ≥ {minimum}, got {shown(v)}")
        return int(v)

    def string(self, key: str, default: Any = ..., choices: tuple[str, ...] = ()) -> str:
        """A string, one of ``choices`` when given."""
        v = self.raw(key, default, "string")
        if not isinstance(v, str):
            raise self.fail(key, f"must be a string, got {shown(v)}")
        if "\x00" in v:  # TOML's "\u0000": no name, path or choice holds one
            raise self.fail(key, f"must not hold a NUL character, got {shown(v)}")
        if choices and v not in choices:
            raise self.fail(key, f"{shown(v)} is not one of {', '.join(choices)}")
        return v

    def boolean(self, key: str, default: Any = ...) -> bool:
        """True or false."""
        v = self.raw(key, default, "true/false")
        if not isinstance(v, bool):
            raise self.fail(key, f"must be true or false, got {shown(v)}")
        return v

    def pose(self, key: str, value: Any = ...) -> np.ndarray:
        """A pose ``[x, y, z, rx, ry, rz]`` (m, deg) as a read-only (4, 4) transform."""
        v = self.raw(key, kind="[x, y, z, rx, ry, rz] (m, deg)") if value is ... else value
        if not isinstance(v, list) or len(v) != 6 or not all(_is_number(x) for x in v):
            raise self.fail(
                key, f"must be a pose [x, y, z, rx, ry, rz] in m and degrees, got {shown(v)}"
            )
        if any(abs(x) > MAX_POSITION for x in v[:3]):
            raise self.fail(
                key,
                f"its position must be within ±{MAX_POSITION:g} m (no cable robot's frame is "
                f"larger), got {shown(v)}",
            )
        return _frozen_array(pose_from_vector(v))

    def list_of(self, key: str, kind: str, spec: Any = None) -> list:
        """A list (of anything; items are checked by the caller), at most ``spec.max_items``."""
        v = self.raw(key, kind=f"list of {kind}")
        if not isinstance(v, list):
            raise self.fail(key, f"must be a list of {kind}, got {shown(v)}")
        most = None if spec is None else spec.max_items
        if most is not None and len(v) > most:
            raise self.fail(
                key, f"must list at most {most} {kind}{spec.max_items_why}, got {len(v)}"
            )
        return v

    def table_of(self, key: str, required: bool = True) -> OptionReader:
        """A sub-table's reader."""
        v = self.raw(key, ... if required else {}, "table")
        if not isinstance(v, dict):
            raise self.fail(key, f"must be a table [{key}], got {shown(v)}")
        return OptionReader(self.source, v, f"{self.where}.{key}" if self.where else key)

    def done(self, known: tuple[str, ...] = ()) -> None:
        """Refuse keys nobody asked for (typos).

        Args:
            known: the keys the table may hold besides those read (optional fields left out),
                listed in the error.
        """
        unknown = sorted(set(self.table) - self.used)
        if unknown:
            fields = ", ".join(sorted(self.used | set(known))) or "none"
            raise self.fail(unknown[0], f"unknown field; known fields here: {fields}")


def _read_field(r: OptionReader, f: dataclasses.Field, hint: Any) -> Any:
    """One option's value, converted to SI (the caller checks that the key is present)."""
    spec = spec_of(f)
    key = spec.file_key(f.name)
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if spec.pose:
        if origin is tuple:
            items = r.list_of(key, "poses [x, y, z, rx, ry, rz] (m, deg)", spec)
            if not items:
                raise r.fail(key, "must be a non-empty list of poses [x, y, z, rx, ry, rz]")
            value: Any = tuple(r.pose(f"{key}[{i}]", p) for i, p in enumerate(items))
        else:
            value = r.pose(key)
    elif hint is float:
        value = r.number(
            key,
            minimum=spec.minimum,
            exclusive=spec.exclusive,
            unit=spec.unit,
            infinite=spec.infinite,
        )
        value = math.radians(value) if spec.unit == "deg" else value
    elif hint is bool:
        value = r.boolean(key)
    elif hint is int:
        value = r.integer(key, minimum=None if spec.minimum is None else int(spec.minimum))
    elif hint is str or origin is Literal:
        value = r.string(key, choices=tuple(args) if origin is Literal else ())
    elif origin is tuple and args[0] is float:
        items = r.list_of(key, f"numbers{' in ' + spec.unit if spec.unit else ''}", spec)
        value = tuple(
            r.number(
                f"{key}[{i}]",
                value=x,
                minimum=spec.minimum,
                exclusive=spec.exclusive,
                unit=spec.unit,
            )
            for i, x in enumerate(items)
        )
        value = tuple(map(math.radians, value)) if spec.unit == "deg" else value
    elif origin is tuple and args[0] is str:
        items = r.list_of(key, "strings", spec)
        if not all(isinstance(x, str) for x in items):
            raise r.fail(key, f"must be a list of strings, got {shown(items)}")
        value = tuple(items)
    else:  # a plugin author's mistake, not the user's
        raise TypeError(f"option {f.name}: type {hint!r} cannot be read from a file")
    return spec.convert(value) if spec.convert is not None else value


def read_options(
    r: OptionReader, cls: type, skip: tuple[str, ...] = (), required: bool = True
) -> dict[str, Any]:
    """The fields of an options dataclass that a table sets, converted to SI (by field name).

    Args:
        r: the table.
        cls: a frozen dataclass with :func:`cdpr_twin.plugins.option` fields.
        skip: keys of the table that belong to the caller (e.g. ``type``).
        required: refuse a table that lacks a field without default.

    Raises:
        ScenarioError: naming the file and field (unknown keys included).
    """
    hints = typing.get_type_hints(cls)
    kwargs: dict[str, Any] = {}
    for f in dataclasses.fields(cls):
        key = spec_of(f).file_key(f.name)
        if not r.has(key):
            no_default = f.default is dataclasses.MISSING
            if required and no_default and f.default_factory is dataclasses.MISSING:
                r.raw(key, kind=_kind(hints[f.name], spec_of(f)))  # raises "missing"
            continue
        kwargs[f.name] = _read_field(r, f, hints[f.name])
    r.used.update(skip)
    r.done(tuple(spec_of(f).file_key(f.name) for f in dataclasses.fields(cls)))
    return kwargs


def build_options(r: OptionReader, cls: type, build: Any, kwargs: dict[str, Any]) -> Any:
    """``build(**kwargs)``, its validation errors reported under the table's file keys."""
    keys = {f.name: spec_of(f).file_key(f.name) for f in dataclasses.fields(cls)}
    try:
        return build(**kwargs)
    except OptionError as exc:
        raise r.fail(keys.get(exc.field, exc.field), exc.problem) from None
    except (ValueError, TypeError) as exc:  # a plugin's own check: name the table
        where = r.where or "top level"
        raise ScenarioError(f"{r.source}: {where}: {type(exc).__name__}: {exc}") from None


def parse_options(r: OptionReader, cls: type, skip: tuple[str, ...] = ()) -> Any:
    """Build an options dataclass from a table, each field as its declaration says.

    Fields absent from the table keep their dataclass defaults (required ones are an error);
    unknown keys are refused. Validation errors of the dataclass (:class:`OptionError`) are
    reported under the field's file key.

    Raises:
        ScenarioError: naming the file and field.
    """
    return build_options(r, cls, cls, read_options(r, cls, skip))


def _kind(hint: Any, spec: Any) -> str:
    if spec.pose:
        return "list of poses" if typing.get_origin(hint) is tuple else "[x, y, z, rx, ry, rz]"
    names = {float: "number", int: "integer", bool: "true/false", str: "string"}
    unit = f" {spec.unit}" if spec.unit else ""
    return names.get(hint, "list") + unit
