"""One redrawn line on stderr for the long commands: done of total, rate, and time left.

The project's own (a few lines) rather than tqdm or rich: the commands need only a line with a
rate and an estimate, the runs' own notes appended, and quiet when stderr is not a terminal (a
log or a pipe gets the command's own final lines, not a hundred redraws) — which is what this
does, with no dependency to install or to keep in step.
"""

from __future__ import annotations

import sys
import time
from typing import TextIO


def duration(seconds: float) -> str:
    """A time left or spent, as a person reads it (``45 s``, ``3.2 min``, ``1.4 h``)."""
    if seconds != seconds or seconds == float("inf"):
        return "?"
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.1f} min"
    return f"{seconds / 3600:.1f} h"


class Progress:
    """``label: done/total unit [#####.....] rate, left ETA``, redrawn in place on a terminal.

    Args:
        label: what is under way (the command's subject).
        unit: what is counted (``runs``, ``segments``, ``s simulated``).
        stream: where to draw (default: stderr at the time of the call).
        every: the shortest time between two redraws [s].
    """

    def __init__(self, label: str, unit: str, stream: TextIO | None = None, every: float = 0.2):
        self.label, self.unit = label, unit
        self.stream = sys.stderr if stream is None else stream
        self.tty = self.stream.isatty()
        self.start = time.perf_counter()
        self.every = every
        self._drawn = -float("inf")
        self._width = 0

    def update(self, done: float, total: float, note: str = "") -> None:
        """Redraw with ``done`` of ``total`` (and a note after the estimate)."""
        if not self.tty:
            return
        now = time.perf_counter()
        if now - self._drawn < self.every and done < total:
            return
        self._drawn = now
        elapsed = now - self.start
        rate = done / elapsed if elapsed > 0 else 0.0
        left = (total - done) / rate if rate > 0 else float("inf")
        filled = int(20 * done / total) if total else 20
        line = (
            f"{self.label}: {done:g}/{total:g} {self.unit} [{'#' * filled}{'.' * (20 - filled)}] "
            f"{self._rate(rate)}, {duration(left)} left" + (f"; {note}" if note else "")
        )
        self.stream.write("\r" + line + " " * max(0, self._width - len(line)))
        self.stream.flush()
        self._width = len(line)

    def _rate(self, per_second: float) -> str:
        if per_second >= 1 or self.unit.startswith("s "):
            return f"{per_second:.1f} {self.unit}/s"
        return f"{60 * per_second:.1f} {self.unit}/min"

    def log(self, text: str) -> None:
        """A line that stays (a finished run's result): above the progress line, or in a log."""
        if self.tty:
            self.stream.write("\r" + text + " " * max(0, self._width - len(text)) + "\n")
            self._width = 0
            self._drawn = -float("inf")  # the next update redraws at once
        else:
            self.stream.write(text + "\n")
        self.stream.flush()

    def stage(self, text: str) -> None:
        """Show a stage without a count (``solving``), on a terminal."""
        if self.tty:
            line = f"{self.label}: {text}"
            self.stream.write("\r" + line + " " * max(0, self._width - len(line)))
            self.stream.flush()
            self._width = len(line)

    def done(self) -> None:
        """End the line (if one was drawn)."""
        if self.tty and self._width:
            self.stream.write("\n")
            self.stream.flush()
            self._width = 0
