"""Numbers as words: a length in the unit that shows it."""

from __future__ import annotations


def length(v: float) -> str:
    """A length [m] in the unit that shows it: µm below 1 mm, mm below 1 m, else m."""
    if abs(v) < 1e-3:
        return f"{v * 1e6:.0f} µm"
    return f"{v * 1e3:.2f} mm" if abs(v) < 1.0 else f"{v:.3f} m"
