"""A run's output directory as a transaction: owned while written, committed by ``summary.json``.

The promises (issue 13), for any reader of an output directory:

1. **One writer.** A run owns its directory while it writes: ``.lock`` in the directory, created
   with ``O_CREAT | O_EXCL``, holds ``<pid> <host>``. A second run on the same directory is
   refused (:class:`OutputDirError`, exit 2) and touches nothing. A lock whose process is dead on
   this host (a killed run) is stale and taken over; checking and taking over happen under an
   ``flock`` of the directory, so two runs cannot both take over the same stale lock. The lock
   is removed when the run ends, however it ends (except SIGKILL: then it is stale).
2. **One run's files.** Right after taking the lock, before anything is written, the outputs
   of an earlier run (``timeseries.csv``, ``recording.rrd``, ``summary.json``, ``*.partial``)
   are **removed** (not moved aside: a directory holds one run, as ``--out`` names it; keep an
   earlier run by giving the new one another ``--out``).
3. **Whole files only.** Each file is written as ``<name>.partial``; when the run ends every
   file is completed, flushed and ``fsync``'ed first, then they are renamed to their final
   names, ``summary.json`` last (the directory is ``fsync``'ed before and after it).
   ``summary.json`` is the commit marker: present ⇔ the run ended, and its ``status`` says how
   (``completed``, ``interrupted``, ``terminated``, ``failed: …``).
4. **Failed writes stay partial.** An ``OSError`` while writing (disk full, permission) is an
   :class:`OutputError` naming the path and the cause; nothing is renamed and no
   ``summary.json`` is written: what was written stays ``*.partial``.

SIGTERM is turned into :class:`Terminated` (a :class:`KeyboardInterrupt`) by
:func:`~cdpr_twin.interrupts.sigterm_raises`, which the command installs around a run; a run
handles it as Ctrl-C.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import socket
from collections.abc import Iterator
from pathlib import Path

from cdpr_twin.json_format import json_text
from cdpr_twin.paths import path_kind

LOCK_NAME = ".lock"
"""The lock file in an output directory while a run writes it."""
OUTPUT_NAMES = ("timeseries.csv", "recording.rrd", "summary.json")
"""The final names of a run's files (removed with ``*.partial`` when a new run starts)."""
MARKERS = {
    "run": OUTPUT_NAMES,
    "campaign": ("campaign.json", "parts"),
    "study": ("runs.json", "study.json"),
    "calibration": ("calibrated_robot.toml", "calibration.json"),
}
"""What marks each command's output directory (study: ``reproduce``'s); the others refuse it."""


def others(kind: str) -> tuple[str, ...]:
    """The markers of every command's directory but ``kind``'s (:data:`MARKERS`)."""
    return tuple(n for k, names in MARKERS.items() if k != kind for n in names)


class OutputDirError(Exception):
    """The output directory cannot be used (the command's exit code 2).

    It is not a directory, cannot be written, or another run owns it.
    """


class OutputError(Exception):
    """Writing an output file failed (the command's exit code 1).

    Attributes:
        path: the file being written.
        cause: what went wrong (the OS's words).
        errno: the OS's error number, if it was an ``OSError``.
    """

    def __init__(self, path: Path, cause: str, errno: int | None = None) -> None:
        self.path, self.cause, self.errno = Path(path), cause, errno
        super().__init__(f"{path}: {cause}")

    def fix(self, otherwise: str) -> str:
        """What to do: "free some space" only when the disk is full, else ``otherwise``."""
        if self.errno in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG):
            return f"free some space, or {otherwise}"
        if self.errno in (errno.EACCES, errno.EPERM):
            return f"make it writable, or {otherwise}"
        return otherwise


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised by :func:`~cdpr_twin.interrupts.sigterm_raises`; a run takes it as Ctrl-C."""


@contextlib.contextmanager
def writing(path: Path) -> Iterator[None]:
    """Turn an ``OSError`` raised inside into an :class:`OutputError` naming ``path``."""
    try:
        yield
    except OSError as exc:
        raise OutputError(path, exc.strerror or str(exc), exc.errno) from None


def fsync_dir(path: Path) -> None:
    """Make the directory's entries (renames) durable."""
    with writing(path):
        fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def partial_of(path: Path) -> Path:
    """``<path>.partial``: where ``path`` is written until it is complete."""
    return path.with_name(path.name + ".partial")


def write_partial(path: Path, data: str | bytes) -> Path:
    """Write ``data`` (text: UTF-8) to ``<path>.partial``, flushed and ``fsync``'ed; its path.

    Raises:
        OutputError: the write failed (disk full, permission), naming the partial file.
    """
    tmp = partial_of(path)
    with writing(tmp), tmp.open("wb") as f:
        f.write(data.encode("utf-8") if isinstance(data, str) else data)
        f.flush()
        os.fsync(f.fileno())
    return tmp


def write_json_partial(path: Path, data: dict) -> Path:
    """Write JSON to ``<path>.partial``, flushed and ``fsync``'ed; returns that path."""
    return write_partial(path, json_text(data))


def write_json_atomic(path: Path, data: dict | list) -> Path:
    """Write indented JSON whole (:func:`write_atomic`): never a half-written file."""
    return write_atomic(path, json_text(data))


def write_atomic(path: Path, data: str | bytes) -> Path:
    """Write ``data`` whole: ``<path>.partial`` (``fsync``'ed), renamed, the directory synced.

    Raises:
        OutputError: the write failed (disk full, permission); ``path`` is not touched and
            what was written is left ``*.partial`` (the next claim of the directory removes it).
    """
    tmp = write_partial(path, data)
    with writing(path):
        os.replace(tmp, path)
    fsync_dir(path.parent)
    return path


def save_figure(fig, path: Path, keep_partial: bool = True, **savefig) -> Path:
    """A matplotlib figure saved whole: into ``<path>.partial``, then renamed.

    Args:
        fig: the figure.
        path: its final name.
        keep_partial: on failure leave the ``*.partial`` (a run's or study's directory, cleared
            by its next claim) or remove it (a single file in a user's directory).
        **savefig: ``Figure.savefig``'s options; give ``format`` (the partial name has none).

    Raises:
        OutputError: the write failed; ``path`` is not touched.
    """
    tmp = partial_of(path)
    try:
        with writing(tmp), tmp.open("wb") as f:
            fig.savefig(f, **savefig)
            f.flush()
            os.fsync(f.fileno())
        with writing(path):
            os.replace(tmp, path)
    except BaseException:
        if not keep_partial:
            with contextlib.suppress(OSError):
                tmp.unlink(missing_ok=True)
        raise
    return path


def write_whole(files: dict[Path, str | bytes]) -> None:
    """Write files whole: each as ``<name>.partial`` (flushed, ``fsync``'ed), then all renamed.

    Every file is complete before the first is renamed, so a final name never holds a
    half-written file. On failure the ``*.partial`` files are removed (a retry starts clean)
    and the files not yet renamed keep what they held. Text is written as UTF-8.

    Args:
        files: final path → its whole content; their directories must exist.

    Raises:
        OutputError: a file cannot be written (disk full, permission),
            naming it and the cause.
    """
    started: list[Path] = []
    try:
        for path, data in files.items():
            started.append(partial_of(path))
            write_partial(path, data)
        for path in files:
            with writing(path):
                os.replace(partial_of(path), path)
    except BaseException:
        for tmp in started:
            with contextlib.suppress(OSError):
                tmp.unlink(missing_ok=True)
        raise
    for directory in {path.parent for path in files}:
        fsync_dir(directory)


@contextlib.contextmanager
def _guard(directory: Path) -> Iterator[None]:
    """An exclusive ``flock`` of the directory: lock checks and takeovers, one at a time."""
    fd = os.open(directory, os.O_RDONLY | os.O_DIRECTORY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # releases the flock


def _owner(lock: Path) -> tuple[int, str] | None:
    """The (pid, host) a lock file names, or ``None`` when it names none (a torn lock)."""
    try:
        pid, host = lock.read_text(encoding="utf-8").split()
        return int(pid), host
    except (OSError, ValueError, UnicodeDecodeError):
        return None


def _alive(pid: int) -> bool:
    """Whether process ``pid`` runs on this host (a zombie does not)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    with contextlib.suppress(OSError, IndexError):
        stat = Path(f"/proc/{pid}/stat").read_text()
        return stat[stat.rindex(")") + 2] != "Z"
    return True


def _stale(owner: tuple[int, str] | None) -> bool:
    """Whether a lock's owner is gone: a torn lock, or a dead process on this host."""
    if owner is None:  # its writer died between creating and filling it (we hold the guard)
        return True
    pid, host = owner
    return host == socket.gethostname() and pid != os.getpid() and not _alive(pid)


class OutputDir:
    """A run's claim on its output directory: :meth:`claim` it, then :meth:`release` it.

    Args:
        path: the directory, or ``None`` (no outputs: claiming and releasing do nothing).
        outputs: the final names of an earlier output that a claim removes (with ``*.partial``):
            a run's by default.
        foreign: names whose presence means the directory holds another command's outputs
            (e.g. a run's in a campaign's directory): the claim is refused, nothing touched.
        partials: glob patterns of the final names whose ``*.partial`` a claim removes (the
            owner's unfinished files; another ``x.partial`` there is not ours): ``outputs``'.

    Attributes:
        path: the directory, or ``None``.
        lock: its lock file, or ``None``.
    """

    def __init__(
        self,
        path: Path | None,
        outputs: tuple[str, ...] = OUTPUT_NAMES,
        foreign: tuple[str, ...] = (),
        partials: tuple[str, ...] | None = None,
    ) -> None:
        self.path = None if path is None else Path(path)
        self.lock = None if path is None else self.path / LOCK_NAME
        self.outputs, self.foreign = outputs, foreign
        self.partials = outputs if partials is None else partials
        self._held = False
        self._made: list[Path] = []  # the directories the claim created, deepest first

    def claim(self) -> None:
        """Create the directory, take its lock and remove an earlier run's outputs.

        Raises:
            OutputDirError: the directory cannot be created or locked, or another run owns it.
            OutputError: an earlier run's file cannot be removed.
        """
        if self.path is None:
            return
        if path_kind(self.path, OutputDirError) not in (None, "dir"):
            raise OutputDirError(f"output directory {self.path}: exists and is not a directory")
        if held := [n for n in self.foreign if path_kind(self.path / n, OutputDirError)]:
            raise OutputDirError(
                f"output directory {self.path} holds another command's outputs "
                f"({', '.join(held)}); choose another directory"
            )
        self._acquire()
        try:
            self._clear()
        except BaseException:
            self.release()
            raise

    def _acquire(self) -> None:
        self._made = [
            p for p in (self.path, *self.path.parents) if path_kind(p, OutputDirError) is None
        ]
        try:
            self.path.mkdir(parents=True, exist_ok=True)
            with _guard(self.path):
                self._create_lock()
        except OSError as exc:
            self._remove_made()  # (e.g. a name too long for the last one: not its parents)
            where, why = f"output directory {self.path}", exc.strerror or exc
            raise OutputDirError(f"{where}: cannot write there: {why}") from None
        self._held = True

    def _create_lock(self) -> None:
        flags = os.O_CREAT | os.O_EXCL | os.O_WRONLY
        try:
            fd = os.open(self.lock, flags, 0o644)
        except FileExistsError:
            owner = _owner(self.lock)
            if not _stale(owner):
                pid, host = owner
                raise OutputDirError(
                    f"output directory {self.path} is in use by another run (pid {pid} on "
                    f"{host}); wait for it, or delete {self.lock} if no run uses it"
                ) from None
            self.lock.unlink()
            fd = os.open(self.lock, flags, 0o644)
        try:
            os.write(fd, f"{os.getpid()} {socket.gethostname()}\n".encode())
            os.fsync(fd)
        finally:
            os.close(fd)

    def _clear(self) -> None:
        """Remove an earlier run's outputs: final names and their owner's ``*.partial``."""
        unfinished = {p for pattern in self.partials for p in self.path.glob(f"{pattern}.partial")}
        stale = [self.path / n for n in self.outputs] + sorted(unfinished)
        for path in stale:
            with writing(path):
                path.unlink(missing_ok=True)

    def abandon(self) -> None:
        """Remove the owner's files begun since the claim, then release: nothing was recorded.

        For a command stopped while opening its outputs (a Ctrl-C then leaves no header-only
        ``*.partial`` behind, nor the directories the claim created, when they are empty).
        Nothing is touched unless this claim holds the directory.
        """
        if self._held:
            with contextlib.suppress(OutputError):
                self._clear()
            self.release()
            self._remove_made()

    def _remove_made(self) -> None:
        """Remove the directories the claim created, deepest first, those that are empty."""
        for made in self._made:
            with contextlib.suppress(OSError):
                made.rmdir()  # (only if empty)

    def release(self) -> None:
        """Remove the lock (if this claim still holds it)."""
        if self._held:
            self._held = False
            with contextlib.suppress(OSError):
                self.lock.unlink()


def out_path(text: str) -> Path:
    """An ``--out`` argument as a path; an empty one (an unset shell variable) is refused.

    ``Path("")`` is the current directory, whose unrelated files a claim would remove.

    Raises:
        argparse.ArgumentTypeError: ``text`` is empty or blank.
    """
    import argparse

    if not text.strip():
        raise argparse.ArgumentTypeError("is empty: give a directory (e.g. runs/my_run)")
    return Path(text)
