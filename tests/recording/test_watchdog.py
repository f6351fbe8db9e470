"""The wait for a writer thread that may have died (:mod:`cdpr_twin.recording.watchdog`)."""

from __future__ import annotations

import threading
import time

import pytest

from cdpr_twin.recording.watchdog import WriterStalledError, call_with_deadline, flush_while_writing


def _timing_out(timeout_s: float) -> None:
    time.sleep(timeout_s)
    raise RuntimeError("Flush timed out - not all log messages were sent")  # Rerun's words


def test_a_writer_that_keeps_writing_is_waited_for_past_the_stall_time(tmp_path):
    path, calls = tmp_path / "f.rrd", []

    def flush(timeout_s: float) -> None:  # writes a little per wait, done after 8 waits
        calls.append(timeout_s)
        with path.open("ab") as f:
            f.write(b"x")
        if len(calls) < 8:
            _timing_out(timeout_s)

    t0 = time.monotonic()
    flush_while_writing(flush, path, stall_s=0.1, poll_s=0.05)
    assert len(calls) == 8 and time.monotonic() - t0 > 0.3  # 3× the stall time, no error


def test_a_writer_that_stops_writing_is_taken_for_dead_after_the_stall_time(tmp_path):
    path = tmp_path / "f.rrd"
    path.write_bytes(b"x" * 100)
    t0 = time.monotonic()
    with pytest.raises(WriterStalledError, match=r"wrote nothing for 0\.3 s"):
        flush_while_writing(_timing_out, path, stall_s=0.3, poll_s=0.05)
    assert 0.3 <= time.monotonic() - t0 < 3.0


def test_the_writers_own_error_comes_through_at_once(tmp_path):
    def flush(timeout_s: float) -> None:
        raise RuntimeError("File-writer thread shut down prematurely")

    with pytest.raises(RuntimeError, match="shut down prematurely"):
        flush_while_writing(flush, tmp_path / "f.rrd", stall_s=10.0)


def test_a_call_that_blocks_is_left_behind_and_reported_late():
    release, late = threading.Event(), []
    t0 = time.monotonic()
    assert not call_with_deadline(release.wait, 0.2, lambda: late.append(True))
    assert late == [True] and time.monotonic() - t0 < 3.0
    release.set()
    assert call_with_deadline(lambda: None, 5.0, lambda: late.append(True))
    assert late == [True]  # a call in time is not late
