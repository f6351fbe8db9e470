"""A Ctrl-C or SIGTERM that lands inside compiled code still stops the run as such."""

import json

import pytest

from cdpr_twin import runner
from cdpr_twin.interrupts import interruption
from cdpr_twin.outputs import Terminated
from cdpr_twin.scenario import load_scenario


def _through_compiled_code(stop: KeyboardInterrupt) -> SystemError:
    """What CPython raises when a signal's exception is set as a numba function returns."""
    try:
        raise SystemError("CPUDispatcher(...) returned a result with an exception set") from stop
    except SystemError as exc:
        return exc


def test_sigterm_raised_inside_a_compiled_call_ends_the_run_terminated(tmp_path, monkeypatch):
    # truth: the status a SIGTERM gets anywhere else (tests/test_outputs.py), and the exit the
    # command maps Terminated to; here it surfaces as the SystemError seen in a CI run
    real, calls = runner.RunSetup.estimate, []

    def estimate(self, m):
        calls.append(m.time)
        if len(calls) == 3:
            raise _through_compiled_code(Terminated())
        return real(self, m)

    monkeypatch.setattr(runner.RunSetup, "estimate", estimate)
    s = load_scenario("paper_open_loop").with_overrides(camera=False, duration=2.0)
    with pytest.raises(Terminated):
        runner.run(s, tmp_path / "out")
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["status"] == "terminated"


def test_only_an_interrupt_behind_a_system_error_counts():
    assert isinstance(interruption(_through_compiled_code(KeyboardInterrupt())), KeyboardInterrupt)
    assert interruption(_through_compiled_code(Terminated())).__class__ is Terminated
    assert interruption(SystemError("a real one")) is None
    assert interruption(ValueError("x")) is None
