"""Input files read whole and bounded: scenario, campaign and robot TOML, and MJCF model files.

Every input file is checked before it is parsed: it must be a regular file (a FIFO would block
the read, ``/dev/zero`` would never end it, a directory is not a file) of at most a size that
no real input comes near. A parsed TOML document is then checked for nesting depth and array
lengths, so that no later step (``copy.deepcopy``, ``json``, ``repr``, a per-item check) meets
a structure that exhausts the recursion limit, the memory or the time. :func:`shown` quotes a
user's value in an error message, elided when it is long, so that a message stays one line.

The standard library only: the scenario, robot, campaign and model readers all use it.
"""

from __future__ import annotations

import os
import stat
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any

MAX_TOML_BYTES = 1 << 20
"""The largest scenario, campaign or robot file [bytes] (1 MiB): the largest shipped one is
4.6 kB (``scenarios/fault_cable_break.toml``); 1 MiB is 200 times that, room for thousands of
waypoints, and parses in well under a second (a 100 MB file took 55 s and 1.3 GB)."""
MAX_MODEL_BYTES = 16 << 20
"""The largest MJCF model file [bytes] (16 MiB): the shipped scenes are 14 kB (meshes and
textures live in files of their own); 16 MiB is a thousand times that."""
MAX_NESTING = 32
"""The deepest nesting of tables and arrays in a TOML input: the shipped files nest 9 levels at
most (a campaign block's axis whose values are realism tables with arrays in them); 32 keeps
the copies, JSON and messages of the data far from Python's recursion limit (1 000 frames)."""
MAX_ARRAY_ITEMS = 100_000
"""The longest array in a TOML input: a campaign's axis lists at most one value per run
(``campaign.spec.MAX_RUNS``, 100 000); no other list of any schema comes near it."""
SHOWN_CHARS = 60
"""How many characters of a user's value an error message quotes before eliding the rest."""


def shown(value: Any) -> str:
    """A user's value as an error message quotes it: its ``repr`` on one line, elided when long.

    Args:
        value: anything a file gave (a string, a number, a list, an array).

    Returns:
        ``repr(value)`` (an array's as a list, on one line), :func:`elided`.
    """
    if hasattr(value, "tolist"):
        value = value.tolist()  # a numpy array: one line, not numpy's wrapped rows
    return elided(repr(value))


def elided(text: str) -> str:
    """``text`` if short, else its first :data:`SHOWN_CHARS` characters, "…" and its length."""
    if len(text) <= SHOWN_CHARS:
        return text
    return f"{text[:SHOWN_CHARS]}… ({len(text)} characters)"


def read_bytes(
    path: Path,
    what: str,
    limit: int,
    error: Callable[[str], Exception],
    content: bool = True,
    in_directory: str = "",
) -> bytes:
    """The content of a regular file of at most ``limit`` bytes, refused before reading else.

    The file is opened without blocking (a FIFO swapped in after a check opens at once) and
    checked on its open descriptor, so that what is read is what was checked.

    Args:
        path: the file.
        what: what it is, for messages ("scenario file").
        limit: the most bytes it may hold.
        error: makes the caller's exception from a one-line message.
        content: read it; ``False``: only check it (a file a library reads itself), ``b""``.
        in_directory: the name the file has in a directory given instead ("robot.toml"), for
            the fix the error says.

    Raises:
        Exception: ``error``'s, naming the path: missing, not a regular file, too large,
            unreadable.
    """
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except (FileNotFoundError, NotADirectoryError):
        raise error(f"{path}: {what} not found") from None
    except IsADirectoryError:
        raise error(_directory(path, what, in_directory)) from None
    except ValueError:  # "embedded null byte"
        raise error(f"{shown(str(path))}: a path cannot hold a NUL character") from None
    except OSError as exc:
        raise error(f"{path}: cannot read the {what}: {exc.strerror}") from None
    try:
        info = os.fstat(fd)
        if stat.S_ISDIR(info.st_mode):
            raise error(_directory(path, what, in_directory))
        if not stat.S_ISREG(info.st_mode):
            raise error(f"{path} is not a regular file (a device, FIFO or socket); give a {what}")
        if info.st_size > limit:
            raise error(
                f"{path}: {info.st_size} bytes, more than the {limit} a {what} may hold; "
                "give a smaller file"
            )
        with os.fdopen(fd, "rb", closefd=False) as f:
            data = f.read(limit + 1) if content else b""  # (grown since its stat: bounded)
    except OSError as exc:
        raise error(f"{path}: cannot read the {what}: {exc.strerror}") from None
    finally:
        os.close(fd)
    if len(data) > limit:
        raise error(f"{path}: more than the {limit} bytes a {what} may hold; give a smaller file")
    return data


def read_toml(
    path: Path, what: str, error: Callable[[str], Exception], in_directory: str = ""
) -> dict:
    """A TOML input file, parsed and checked (:func:`read_bytes`, :func:`check_shape`).

    Args:
        path: the file.
        what: what it is, for messages ("scenario file").
        error: makes the caller's exception from a one-line message.
        in_directory: the name the file has in a directory given instead (:func:`read_bytes`).

    Raises:
        Exception: ``error``'s, naming the path and what is wrong.
    """
    raw = read_bytes(path, what, MAX_TOML_BYTES, error, in_directory=in_directory)
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise error(f"{path}: not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{path}: not valid TOML: {exc}") from None
    except RecursionError:  # tomllib recurses once per level of nesting
        raise error(_too_deep(path)) from None
    except ValueError as exc:  # an integer of more digits than Python converts (4 300)
        raise error(f"{path}: not valid TOML: {exc}") from None
    check_shape(data, path, error)
    return data


def check_shape(data: Any, path: Path, error: Callable[[str], Exception]) -> None:
    """Refuse nesting deeper than :data:`MAX_NESTING` or an array too long (iteratively).

    An array may hold at most :data:`MAX_ARRAY_ITEMS` items.

    Raises:
        Exception: ``error``'s, naming the path and the dotted key of the first offender.
    """
    stack: list[tuple[Any, str, int]] = [(data, "", 0)]
    while stack:
        node, where, depth = stack.pop()
        if depth > MAX_NESTING:
            raise error(_too_deep(path, where))
        if isinstance(node, dict):
            stack.extend(
                (v, f"{where}.{k}" if where else str(k), depth + 1) for k, v in node.items()
            )
        elif isinstance(node, list):
            if len(node) > MAX_ARRAY_ITEMS:
                raise error(
                    f"{path}: {elided(where)}: {len(node)} items, more than the "
                    f"{MAX_ARRAY_ITEMS} an array may hold; give fewer"
                )
            stack.extend((v, f"{where}[{i}]", depth + 1) for i, v in enumerate(node))


def _directory(path: Path, what: str, in_directory: str) -> str:
    fix = f"; give its {in_directory}" if in_directory else ""
    return f"{path}: a directory, not a {what}{fix}"


def _too_deep(path: Path, where: str = "") -> str:
    at = f" at {elided(where)}" if where else ""
    return (
        f"{path}: tables or arrays nested deeper than {MAX_NESTING} levels{at}; "
        "no field of this file nests so deep"
    )
