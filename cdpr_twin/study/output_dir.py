"""The study's own files: each written whole, and an earlier study's removed before a new one.

The study directory keeps the promises of a run's directory (:mod:`cdpr_twin.files.transaction`):

1. **One writer.** ``reproduce`` claims the directory with the run's lock
   (:class:`~cdpr_twin.files.transaction.OutputDir`): a second study on it is refused, touching
   nothing.
2. **One study's files.** Right after the claim, before any run starts, the earlier study's
   outputs are removed: :data:`STUDY_FILES` (its report, figures and ``runs.json``), every
   ``*.partial`` and its run directories under ``runs/`` (the ones named as the study names
   its runs; another directory there is left alone). Nothing of an earlier study is left to
   look like the new one's, even when the new one is stopped or fails; keep an earlier study
   by giving the new one another ``--out``. A directory that holds files of those names but
   is no study's (no ``study.json``, ``runs.json`` or study ``report.json``: someone's own
   ``report.md``) is refused, nothing removed.
3. **Whole files only.** Each file is written as ``<name>.partial``, flushed and ``fsync``'ed,
   then renamed to its final name (the directory ``fsync``'ed); ``report.md`` is written last.
   An ``OSError`` (a full disk) is an :class:`~cdpr_twin.files.transaction.OutputError` naming the
   file;
   what was written stays ``*.partial`` (the next study removes it), no final name is left
   truncated.
"""

from __future__ import annotations

import contextlib
import re
from pathlib import Path

from cdpr_twin.files.transaction import Marker, OutputDir, OutputDirError, partial_of, writing

FIGURES = ("fig5a", "fig5b", "fig7a", "fig7b", "fig8")
"""The study's figures (``<name>.png``)."""
STUDY_FILES = ("report.md", "report.json", "runs.json", *(f"{n}.png" for n in FIGURES))
"""The final names of a study's own files (beside its ``runs/``)."""
STUDY_MARKER = "study.json"
"""Written as the study starts (the command, its run count): a stopped study's directory is
still a study's, refused by the other commands (``runs.json`` only comes at the end)."""
RUN_NAME = re.compile(r"(open_loop|pbvs_.+)_seed\d+(_without_.+|_goal_.+)?")
"""How the study names its runs (:func:`cdpr_twin.study.plan.plan`, ``extra_runs``)."""


def clear_earlier_study(out: Path) -> None:
    """Remove an earlier study's files from ``out`` (claimed by this study); see the module doc.

    A run directory under ``runs/`` is claimed as a run would claim it (an earlier run's
    files removed, refused while a live run holds it), then removed if nothing else is in it.

    Raises:
        OutputDirError: a run directory under ``runs/`` is in use by a live run, or ``out``
            holds files of a study's names but is no study's (nothing is removed then).
        OutputError: a file cannot be removed.
    """
    runs = out / "runs"
    found = [n for n in STUDY_FILES if (out / n).exists()]
    if runs.is_dir():
        found += [f"runs/{d.name}" for d in sorted(runs.iterdir()) if RUN_NAME.fullmatch(d.name)]
    if found and not _is_study(out):
        raise OutputDirError(
            f"{out}: holds {', '.join(found[:4])}{', …' if len(found) > 4 else ''} but is not a "
            f"study's directory (no {STUDY_MARKER}, runs.json or study report.json): reproduce "
            "would remove them; give it another --out, or move them away"
        )
    for path in [out / n for n in STUDY_FILES] + [partial_of(out / n) for n in STUDY_FILES]:
        with writing(path):
            path.unlink(missing_ok=True)
    if not runs.is_dir():
        return
    for run_dir in sorted(runs.iterdir()):
        if run_dir.is_dir() and not run_dir.is_symlink() and RUN_NAME.fullmatch(run_dir.name):
            owner = OutputDir(run_dir)
            owner.claim()  # the lock, then the run's files (and *.partial) removed
            owner.release()
            with contextlib.suppress(OSError):  # something else is in it: not the study's
                run_dir.rmdir()


MARKERS = (
    Marker(STUDY_MARKER, frozenset({"command", "runs"})),
    Marker("report.json", frozenset({"runs", "findings"})),
)
"""What marks a study's directory as ours: ``study.json`` (from its start), its report.json."""


def _is_study(out: Path) -> bool:
    """Whether ``out`` holds a study: its marker, its ``runs.json``, or a study's report.json."""
    runs = out / "runs.json"
    return (runs.is_file() and not runs.is_symlink()) or any(m.written_by_us(out) for m in MARKERS)
