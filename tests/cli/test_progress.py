"""The long commands' progress line: rate and time left from a controlled clock; silence off a
terminal (a log gets the commands' own lines, not redraws)."""

import io

from cdpr_twin.cli import progress as progress_mod
from cdpr_twin.cli.progress import Progress, duration


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_the_line_gives_the_rate_and_the_time_left(monkeypatch):
    clock = iter([100.0, 110.0, 130.0])  # start, then 10 s and 30 s later
    monkeypatch.setattr(progress_mod.time, "perf_counter", lambda: next(clock))
    term = _Terminal()
    line = Progress("study", "runs", term)
    line.update(5, 45)  # 5 runs in 10 s: 30 runs/min, 40 left take 80 s
    assert "5/45 runs" in term.getvalue() and "30.0 runs/min, 80 s left" in term.getvalue()
    line.update(15, 45, "1 failed")  # 15 in 30 s: 30 runs/min, 30 left take 60 s
    assert term.getvalue().endswith("30.0 runs/min, 60 s left; 1 failed")
    line.done()
    assert term.getvalue().endswith("\n")


def test_nothing_is_drawn_off_a_terminal():
    log = io.StringIO()
    line = Progress("calibrate", "segments", log)
    line.update(1, 4)
    line.stage("solving")
    line.done()
    assert log.getvalue() == ""
    line.log("[  1/4] kept")  # a finished run's line stays, in a log too
    assert log.getvalue() == "[  1/4] kept\n"


def test_durations_read_as_a_person_reads_them():
    assert [duration(s) for s in (45, 150, 7200, float("inf"))] == ["45 s", "2.5 min", "2.0 h", "?"]
