"""What software made an output: package, MuJoCo, NumPy and Python versions, and the git commit.

Recorded in every ``summary.json``, ``campaign.json`` and the campaign table's Parquet metadata,
so a result can be traced to the code that computed it. Standard library only: the versions are
read from the installed distributions' metadata (MuJoCo is not imported), and the commit from
git when the package runs from a checkout (``None`` for an installed wheel).
"""

from __future__ import annotations

import functools
import importlib.metadata
import platform
import subprocess
from pathlib import Path

_PACKAGE_DIR = Path(__file__).resolve().parent


def _version(distribution: str) -> str | None:
    try:
        return importlib.metadata.version(distribution)
    except importlib.metadata.PackageNotFoundError:
        return None


def _git_commit() -> str | None:
    """The checkout's commit (with ``-dirty`` when files differ), or ``None`` outside one."""
    if not (_PACKAGE_DIR.parent / ".git").exists():
        # an installed package (site-packages), never the checkout of some enclosing project
        return None
    try:
        proc = subprocess.run(
            ["git", "describe", "--always", "--dirty", "--abbrev=40", "--match=NO_TAGS"],
            cwd=_PACKAGE_DIR.parent,
            capture_output=True,
            text=True,
            timeout=10,
        )
    except (OSError, subprocess.SubprocessError):
        return None
    return proc.stdout.strip() or None if proc.returncode == 0 else None


@functools.cache
def software() -> dict[str, str | None]:
    """The versions and the commit, as recorded in outputs (computed once a process)."""
    from cdpr_twin import __version__

    return {
        "cdpr_twin": __version__,
        "mujoco": _version("mujoco"),
        "numpy": _version("numpy"),
        "python": platform.python_version(),
        "git_commit": _git_commit(),
    }
