"""A finding of the study: the paper's claim beside the twin's numbers, and its verdict."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

AGREES, DISAGREES, NOT_APPLICABLE = "agrees", "disagrees", "n/a"
"""The verdicts."""


@dataclass(frozen=True)
class Finding:
    """One of the paper's claims beside the twin's numbers.

    Attributes:
        finding: the claim.
        paper: what the paper reports.
        twin: what the twin gives.
        threshold: the criterion the verdict applies to the twin's numbers.
        verdict: ``"agrees"``, ``"disagrees"`` or ``"n/a"`` (no criterion, or no data).
        why: the mechanism behind the twin's number.
    """

    finding: str
    paper: str
    twin: str
    threshold: str
    verdict: str
    why: str


Rule = Callable[[dict], Finding | None]
"""A finding's rule: report numbers → the finding, or ``None`` (numbers missing)."""


def verdict(ok: bool | None) -> str:
    """``agrees`` / ``disagrees`` for a checked criterion, ``n/a`` for none."""
    return NOT_APPLICABLE if ok is None else (AGREES if ok else DISAGREES)


def length(v: float) -> str:
    """A length in the unit that shows it: µm below 1 mm, mm below 1 m, else m."""
    if abs(v) < 1e-3:
        return f"{v * 1e6:.0f} µm"
    return f"{v * 1e3:.2f} mm" if abs(v) < 1.0 else f"{v:.3f} m"
