"""What is at a path, asked once, with the OS's refusals turned into the caller's errors.

The standard library only: the outputs, scenario, resource and CLI modules all use it.
"""

from __future__ import annotations

import errno
import os
import stat
from collections.abc import Callable
from pathlib import Path


def path_kind(path: Path, error: Callable[[str], Exception]) -> str | None:
    """What is at ``path`` (links followed): ``"dir"``, ``"file"`` (regular), ``"other"``, ``None``.

    ``None`` when nothing is there. Another ``OSError`` (a name too long, permission denied),
    which ``Path.exists()`` raises on Python 3.11 and takes for "missing" on 3.12, is refused,
    and so is a NUL character (TOML's ``"\u0000"``).

    Raises:
        Exception: ``error``, given one line naming the path, the OS's reason and the fix.
    """
    try:
        mode = os.stat(path).st_mode
    except (FileNotFoundError, NotADirectoryError):
        return None
    except ValueError:  # "embedded null byte": no file system names one so
        raise error(f"{str(path)!r}: a path cannot hold a NUL character; give another") from None
    except OSError as exc:
        fix = {errno.ENAMETOOLONG: "give shorter names", errno.EACCES: "check its permissions"}
        raise error(
            f"{path}: {exc.strerror}; {fix.get(exc.errno or 0, 'give another path')}"
        ) from None
    return "dir" if stat.S_ISDIR(mode) else "file" if stat.S_ISREG(mode) else "other"


def unwritable(directory: Path) -> str | None:
    """Why files cannot be made in an existing ``directory`` (the OS's words), or ``None``."""
    if os.access(directory, os.W_OK | os.X_OK):
        return None
    read_only = os.statvfs(directory).f_flag & os.ST_RDONLY  # or its permissions
    return os.strerror(errno.EROFS if read_only else errno.EACCES)
