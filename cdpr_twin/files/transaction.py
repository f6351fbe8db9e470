"""An output directory as a transaction: owned while written, committed by its marker.

The promises, for any reader of an output directory (a run's: ``summary.json`` is its marker;
a campaign's, a calibration's and a study's keep them with their own files):

1. **One writer.** A run owns its directory while it writes: ``.lock`` in the directory, created
   with ``O_CREAT | O_EXCL``, holds ``<pid> <host>``. A second run on the same directory is
   refused (:class:`OutputDirError`, exit 2) and touches nothing. A lock whose process is dead on
   this host (a killed run) is stale and taken over; checking and taking over happen under an
   ``flock`` of the directory, so two runs cannot both take over the same stale lock. The lock
   is removed when the run ends, however it ends (except SIGKILL: then it is stale). A lock that
   cannot be written (a full disk) is removed again, and so is the directory the claim made:
   a refused run leaves no output directory and no lock.
2. **Only our own files are removed.** Right after taking the lock, before anything is written,
   the outputs of an earlier run (``timeseries.csv``, ``recording.rrd``, ``summary.json`` and
   their ``*.partial``) are **removed** (not moved aside: a directory holds one run, as
   ``--out`` names it; keep an earlier run by giving the new one another ``--out``). They are
   removed only when an earlier run of ours wrote them: its commit marker is there (a
   ``summary.json`` that is a regular file, parses as JSON and carries the keys only our
   summaries carry, :data:`RUN_MARKER`), or its stale lock (a killed run). A directory that
   holds a file of an output's name without that is someone else's: refused (exit 2), nothing
   removed. So is one where an output's name is the command's own input (the scenario given to
   ``run``), or a directory: what a claim removes is never a directory nor an input.
3. **Never through a link.** Every file is created as ``<name>.partial`` with
   ``O_CREAT | O_EXCL | O_NOFOLLOW`` (:class:`Partial`), never opened through a symbolic link;
   a ``<name>.partial`` already there (stale, or a link planted there) is unlinked first, which
   removes a link, never its target; one planted again in between makes ``O_EXCL`` fail: an
   :class:`OutputError`, not a followed link. A final name is only ever replaced by the rename
   of our own partial (checked to be the very file we created), which replaces a link there by
   our regular file and leaves the link's target alone. The removal of an earlier run's files
   lists the directory itself, so it sees dangling links too, and removes links, not targets.
4. **Whole files only.** Each file is written as ``<name>.partial``; when the run ends every
   file is completed, flushed and ``fsync``'ed first, then they are renamed to their final
   names, ``summary.json`` last (the directory is ``fsync``'ed before and after it).
   ``summary.json`` is the commit marker: present ⇔ the run ended, and its ``status`` says how
   (``completed``, ``interrupted``, ``terminated``, ``failed: …``).
5. **Failed writes stay partial.** An ``OSError`` while writing (disk full, permission) is an
   :class:`OutputError` naming the path and the cause; nothing is renamed and no
   ``summary.json`` is written: what was written stays ``*.partial``.

Beside the transaction: the project's one JSON format (:func:`json_text`: strict RFC 8259, an
undefined number written ``null``), the atomic writers of single files and figures, and
:func:`sweep_abandoned`, which tidies the directories of runs that died mid-way.

SIGTERM is turned into :class:`Terminated` (a :class:`KeyboardInterrupt`) by
:func:`~cdpr_twin.run.interrupts.sigterm_raises`, which the command installs around a run; a run
handles it as Ctrl-C.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import fnmatch
import json
import math
import os
import socket
import stat
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

from cdpr_twin.files.paths import path_kind


# ---------------------------------------------------------------- the project's JSON format
# Strict RFC 8259 (an undefined number is null), one format for every JSON file written.
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
    """SIGTERM, raised by :func:`~cdpr_twin.run.interrupts.sigterm_raises`: a run's Ctrl-C."""


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


_NEW_FILE = os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC
"""A file created afresh: never an existing one, never through a symbolic link."""


def _create(tmp: Path) -> int:
    """Create ``tmp`` afresh (``O_EXCL | O_NOFOLLOW``); its descriptor, open for writing.

    A file or link already at ``tmp`` (a stale partial, a planted link) is unlinked first: a
    link goes, its target stays. One that appears again in between is an error, never followed.

    Raises:
        OutputError: ``tmp`` cannot be created, is a directory, or was planted again.
    """
    with writing(tmp):
        try:
            return os.open(tmp, _NEW_FILE, 0o644)
        except FileExistsError:
            if stat.S_ISDIR(os.lstat(tmp).st_mode):
                raise IsADirectoryError(errno.EISDIR, os.strerror(errno.EISDIR)) from None
            os.unlink(tmp)
        try:
            return os.open(tmp, _NEW_FILE, 0o644)
        except FileExistsError:
            raise OutputError(
                tmp,
                "was made again by another program while it was being replaced (another "
                "program writes this directory); give another --out",
            ) from None


class Partial:
    """A file written as ``<path>.partial``, created afresh (never through a link), then renamed.

    The only way an output reaches its final name: :meth:`commit` renames the very file this
    created (checked by device and inode), which replaces whatever is at ``path`` (a link too:
    its target is not touched).

    Args:
        path: the final name.

    Attributes:
        path: the final name.
        partial: ``<path>.partial``.
        fd: the descriptor it was created with (open for writing until :meth:`file` or
            :meth:`close`).

    Raises:
        OutputError: the partial file cannot be created (naming it and the cause).
    """

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self.partial = partial_of(self.path)
        self.fd = _create(self.partial)
        info = os.fstat(self.fd)
        self._identity = (info.st_dev, info.st_ino)
        self._owns_fd = True

    def file(self, mode: str = "wb", **kwargs) -> IO:
        """The partial file as a Python file object, which takes over (and closes) :attr:`fd`.

        Args:
            mode: a writing mode of :func:`open` (``"wb"``, ``"w"``).
            **kwargs: :func:`open`'s other options (``encoding``, ``newline``).
        """
        self._owns_fd = False
        return os.fdopen(self.fd, mode, **kwargs)

    def name_of_fd(self) -> str:
        """A name that opens this very file, wherever its name now points (``/proc/self/fd``).

        For a library that opens files only by name (Rerun's file sink): the name resolves to
        the file this created, not to a link planted at ``<path>.partial`` since.
        """
        base = "/proc/self/fd" if os.path.isdir("/proc/self/fd") else "/dev/fd"
        return f"{base}/{self.fd}"

    def close(self) -> None:
        """Close :attr:`fd`, if :meth:`file` did not take it over (the file stays partial)."""
        if self._owns_fd:
            self._owns_fd = False
            with contextlib.suppress(OSError):
                os.close(self.fd)

    def commit(self) -> Path:
        """Rename the partial file to its final name (closing :attr:`fd`); the final name.

        Raises:
            OutputError: the partial file is gone or is no longer the one created here (another
                program replaced it): nothing is renamed.
        """
        self.close()
        with writing(self.partial):
            info = os.lstat(self.partial)
        if (info.st_dev, info.st_ino) != self._identity:
            raise OutputError(
                self.partial,
                "was replaced by another file while it was written (another program writes "
                "this directory); give another --out",
            )
        with writing(self.path):
            os.replace(self.partial, self.path)
        return self.path

    def remove(self) -> None:
        """Close and remove the partial file, if it is still the one created here."""
        self.close()
        with contextlib.suppress(OSError):
            info = os.lstat(self.partial)
            if (info.st_dev, info.st_ino) == self._identity:
                os.unlink(self.partial)


def _fill(out: Partial, data: str | bytes) -> None:
    """Write ``data`` (text: UTF-8) into ``out``'s partial file, flushed, ``fsync``'ed, closed."""
    with writing(out.partial), out.file("wb") as f:
        f.write(data.encode("utf-8") if isinstance(data, str) else data)
        f.flush()
        os.fsync(f.fileno())


def write_partial(path: Path, data: str | bytes) -> Partial:
    """Write ``data`` (text: UTF-8) to ``<path>.partial``, flushed and ``fsync``'ed.

    Returns:
        The :class:`Partial`: its :meth:`~Partial.commit` gives it its final name.

    Raises:
        OutputError: the write failed (disk full, permission), naming the partial file.
    """
    out = Partial(path)
    _fill(out, data)
    return out


def write_json_partial(path: Path, data: dict) -> Partial:
    """Write JSON to ``<path>.partial``, flushed and ``fsync``'ed (:func:`write_partial`)."""
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
    write_partial(path, data).commit()
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
    out = Partial(path)
    try:
        with writing(out.partial), out.file("wb") as f:
            fig.savefig(f, **savefig)
            f.flush()
            os.fsync(f.fileno())
        out.commit()
    except BaseException:
        if not keep_partial:
            out.remove()
        raise
    return path


def write_whole(files: dict[Path, str | bytes]) -> None:
    """Write files whole: each as ``<name>.partial`` (flushed, ``fsync``'ed), then all renamed.

    Every file is complete before the first is renamed, so a final name never holds a
    half-written file. On failure the ``*.partial`` files made here are removed (a retry starts
    clean) and the files not yet renamed keep what they held. Text is written as UTF-8.

    Args:
        files: final path → its whole content; their directories must exist.

    Raises:
        OutputError: a file cannot be written (disk full, permission),
            naming it and the cause.
    """
    started: list[Partial] = []
    try:
        for path, data in files.items():
            started.append(Partial(path))
            _fill(started[-1], data)
        for out in started:
            out.commit()
    except BaseException:
        for out in started:
            out.remove()
        raise
    for directory in {path.parent for path in files}:
        fsync_dir(directory)


@dataclass(frozen=True)
class Marker:
    """The file that marks a directory as written by one of our commands (its commit marker).

    Attributes:
        name: its name in the directory.
        keys: keys its JSON object always carries and another tool's file of that name would
            not (all of them must be there).
    """

    name: str
    keys: frozenset[str]

    def written_by_us(self, directory: Path) -> bool:
        """Whether ``directory`` holds this marker (or its partial) as we write it.

        A regular file (not a link) holding a JSON object with every one of :attr:`keys`.
        """
        for path in (directory / self.name, partial_of(directory / self.name)):
            try:
                if not stat.S_ISREG(os.lstat(path).st_mode):
                    continue
                with path.open("rb") as f:
                    data = json.loads(f.read(MARKER_MAX_BYTES))
            except (OSError, ValueError):
                continue
            if isinstance(data, dict) and self.keys <= data.keys():
                return True
        return False


MARKER_MAX_BYTES = 64 * 1024 * 1024
"""A marker is read whole only up to this size (a larger file is not ours: a summary is kB)."""
RUN_MARKER = Marker(
    "summary.json", frozenset({"scenario", "status", "estimator_names", "simulated_time_s"})
)
"""A run's ``summary.json``, as :func:`cdpr_twin.run.metrics.run_summary` writes it."""


def _entries(directory: Path, patterns: tuple[str, ...]) -> list[Path]:
    """The entries of ``directory`` whose names match a glob pattern, dangling links included.

    (``Path.glob`` on Python 3.11 skips a dangling link: a claim would not see it.)
    """
    try:
        names = os.listdir(directory)
    except FileNotFoundError:
        return []
    return sorted(directory / n for n in names if any(fnmatch.fnmatchcase(n, p) for p in patterns))


def _identities(paths: tuple[Path | None, ...]) -> set[tuple[int, int]]:
    """The (device, inode) of each path, as named (a link) and as followed (its target)."""
    found = set()
    for path in filter(None, paths):
        for look in (os.lstat, os.stat):
            with contextlib.suppress(OSError, ValueError, TypeError):
                info = look(path)
                found.add((info.st_dev, info.st_ino))
    return found


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
    """A command's claim on its output directory: :meth:`claim` it, then :meth:`release` it.

    Args:
        path: the directory, or ``None`` (no outputs: claiming and releasing do nothing).
        outputs: the final names of an earlier output that a claim removes (with ``*.partial``):
            a run's by default.
        foreign: names whose presence means the directory holds another command's outputs
            (e.g. a run's in a campaign's directory): the claim is refused, nothing touched.
        partials: glob patterns of the final names whose ``*.partial`` a claim removes (the
            owner's unfinished files; another ``x.partial`` there is not ours): ``outputs``'.
        owned: glob patterns of the names the command removes or replaces (by the claim or
            later): present without :attr:`marker`, the directory is someone else's and the
            claim is refused: ``outputs`` by default.
        marker: the commit marker of the command's earlier outputs (a run's ``summary.json``).
        inputs: the command's input files: none of them is ever removed as an output (a claim
            that would is refused).

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
        owned: tuple[str, ...] | None = None,
        marker: Marker | None = RUN_MARKER,
        inputs: tuple[Path | None, ...] = (),
    ) -> None:
        self.path = None if path is None else Path(path)
        self.lock = None if path is None else Path(path) / LOCK_NAME
        self.outputs, self.foreign = outputs, foreign
        self.partials = outputs if partials is None else partials
        self.owned = outputs if owned is None else owned
        self.marker, self.inputs = marker, inputs
        self._held = False
        self._took_over = False  # the claim took over a dead run's lock: the directory is ours
        self._made: list[Path] = []  # the directories the claim created, deepest first

    def claim(self) -> None:
        """Create the directory, take its lock and remove an earlier run's outputs.

        Raises:
            OutputDirError: the directory cannot be created or locked, another run owns it,
                or it holds files of an output's name that are not ours (or are inputs).
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
            self._check()
            self._clear()
        except BaseException:
            self.release()
            raise

    @property
    def _dir(self) -> Path:
        """The directory of a claim that has one (only its steps after :meth:`claim` use it)."""
        assert self.path is not None, "a claim without a directory has no steps"
        return self.path

    @property
    def _lock(self) -> Path:
        """The lock file of a claim that has a directory."""
        assert self.lock is not None, "a claim without a directory has no lock"
        return self.lock

    def _acquire(self) -> None:
        self._made = [
            p for p in (self._dir, *self._dir.parents) if path_kind(p, OutputDirError) is None
        ]
        for made in self._made:  # (os.stat found nothing there: a link to nothing, or nothing)
            if os.path.islink(made):
                raise OutputDirError(
                    f"output directory {self.path}: {made} is a dangling symbolic link (to "
                    f"{os.readlink(made)}); remove it, or choose another --out"
                )
        try:
            self._dir.mkdir(parents=True, exist_ok=True)
            with _guard(self._dir):
                self._create_lock()
        except OSError as exc:
            self._remove_made()  # (e.g. a name too long for the last one: not its parents)
            where, why = f"output directory {self.path}", exc.strerror or exc
            raise OutputDirError(f"{where}: cannot write there: {why}") from None
        self._held = True

    def _create_lock(self) -> None:
        flags = os.O_CREAT | os.O_EXCL | os.O_WRONLY | os.O_NOFOLLOW | os.O_CLOEXEC
        try:
            fd = os.open(self._lock, flags, 0o644)
        except FileExistsError:
            owner = _owner(self._lock)
            if owner is not None and not _stale(owner):
                pid, host = owner
                raise OutputDirError(
                    f"output directory {self.path} is in use by another run (pid {pid} on "
                    f"{host}); wait for it, or delete {self._lock} if no run uses it"
                ) from None
            self._lock.unlink()
            fd = os.open(self._lock, flags, 0o644)
            self._took_over = True
        try:
            os.write(fd, f"{os.getpid()} {socket.gethostname()}\n".encode())
            os.fsync(fd)
        except BaseException:  # (a full disk): no lock left behind, nor a directory made for it
            with contextlib.suppress(OSError):
                self._lock.unlink()
            raise
        finally:
            os.close(fd)

    def _stale_entries(self) -> list[Path]:
        """What a claim removes: the final names there and their owner's ``*.partial``."""
        finals = [p for p in (self._dir / n for n in self.outputs) if _present(p)]
        return finals + _entries(self._dir, tuple(f"{p}.partial" for p in self.partials))

    def _check(self) -> None:
        """Refuse a directory whose files of an output's name are not ours to remove.

        Raises:
            OutputDirError: such a file is an input of the command, a directory, or was not
                written by an earlier run of ours (no marker, no stale lock of ours).
        """
        named = _entries(self._dir, self.owned)
        candidates = sorted({*self._stale_entries(), *named})
        if inputs := _identities(self.inputs):
            for path in candidates:
                info = os.lstat(path)
                if (info.st_dev, info.st_ino) in inputs:
                    raise OutputDirError(
                        f"{path} is an input of this command and has the name of one of its "
                        "outputs, which would replace it; give another --out, or rename it"
                    )
        for path in candidates:
            if stat.S_ISDIR(os.lstat(path).st_mode):
                raise OutputDirError(f"{path} is a directory; remove it or choose another --out")
        ours = self._took_over or (self.marker is not None and self.marker.written_by_us(self._dir))
        if named and not ours:
            shown = ", ".join(p.name for p in named[:4]) + (", …" if len(named) > 4 else "")
            proof = f" (no {self.marker.name} of ours beside them)" if self.marker else ""
            raise OutputDirError(
                f"output directory {self.path} holds {shown}, which no earlier run of ours "
                f"wrote{proof}: they would be replaced; move them away, or choose another --out"
            )

    def _clear(self) -> None:
        """Remove an earlier run's outputs: final names and their owner's ``*.partial``.

        Links are removed, never their targets (``unlink``); dangling ones are seen too.
        """
        for path in self._stale_entries():
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
                self._lock.unlink()


def _present(path: Path) -> bool:
    """Whether anything is at ``path``, a dangling link too."""
    try:
        os.lstat(path)
    except (FileNotFoundError, NotADirectoryError):
        return False
    return True


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


# ------------------------------------------------------------- the directories of dead runs
# Tidying the run directories of runs that died mid-way (a stopped campaign's or study's).
def sweep_abandoned(parent: Path, wait: float = 0.0) -> list[Path]:
    """Tidy the run directories under ``parent`` whose run died (its lock's owner is gone).

    A campaign or study stopped ends its workers mid-run (SIGTERM, then SIGKILL): their run
    directories keep the lock and the ``*.partial`` files the run had begun. Each is claimed
    as the next run there would claim it (:class:`~cdpr_twin.files.transaction.OutputDir`: the dead
    run's lock taken over, its files removed), released, and removed when nothing else is
    left in it; a live run's directory is not touched.

    Args:
        parent: the directory of the run directories.
        wait: up to this long [s], wait for the owners on this host to end (Ray's shutdown
            does not wait for its workers).

    Returns:
        The directories tidied.
    """
    deadline = time.monotonic() + wait
    tidied = []
    for lock in sorted(Path(parent).glob(f"*/{LOCK_NAME}")):
        if _take(OutputDir(lock.parent), deadline):
            tidied.append(lock.parent)
            with contextlib.suppress(OSError):
                lock.parent.rmdir()  # (only if empty)
    return tidied


def _take(run: OutputDir, deadline: float) -> bool:
    """Claim and release ``run``'s directory, retrying while its owner lives until ``deadline``."""
    while True:
        try:
            run.claim()
        except OutputDirError:  # its run is alive (on Ray, maybe still ending)
            if time.monotonic() >= deadline:
                return False
            time.sleep(0.1)
            continue
        except OutputError:  # a file that cannot be removed: left as it is
            return False
        run.release()
        return True
