"""A Ctrl-C or SIGTERM that lands inside compiled code still stops the run as such.

And the first stop decides: a second signal of the other kind, while the first is handled,
changes neither the status the run records nor the exit code.
"""

import json
import os
import signal

import pytest
from conftest import EARLIER_SUMMARY

from cdpr_twin.files.transaction import Terminated
from cdpr_twin.run import runner
from cdpr_twin.run.interrupts import interruption
from cdpr_twin.run.runner import run
from cdpr_twin.scenario.loading import load_scenario


def _through_compiled_code(stop: KeyboardInterrupt) -> SystemError:
    """What CPython raises when a signal's exception is set as a numba function returns."""
    try:
        raise SystemError("CPUDispatcher(...) returned a result with an exception set") from stop
    except SystemError as exc:
        return exc


def test_sigterm_raised_inside_a_compiled_call_ends_the_run_terminated(tmp_path, monkeypatch):
    # truth: the status a SIGTERM gets anywhere else (tests/files/test_transaction.py), and the
    # exit the command maps Terminated to; here it surfaces as the SystemError seen in a CI run
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


def test_a_command_gets_the_stop_not_the_system_error_that_carried_it():
    # truth: the exception raised inside, and CPython's own SystemError left alone
    from cdpr_twin.run.interrupts import sigterm_raises

    with pytest.raises(Terminated), sigterm_raises():
        raise _through_compiled_code(Terminated())
    with pytest.raises(KeyboardInterrupt), sigterm_raises():
        raise _through_compiled_code(KeyboardInterrupt())
    with pytest.raises(SystemError, match="a real one"), sigterm_raises():
        raise SystemError("a real one")


def test_calibrate_stopped_inside_compiled_code_exits_terminated(tmp_path, monkeypatch, capsys):
    # truth: the exit code and line a SIGTERM gets in `cdpr-twin calibrate` anywhere else (143,
    # "terminated"), and nothing left behind in the directory it made
    from cdpr_twin import cli
    from cdpr_twin.cli import calibrate as cli_calibrate

    def solve(*args):
        raise _through_compiled_code(Terminated())

    monkeypatch.setattr(cli_calibrate, "_solve_and_write", solve)
    out = tmp_path / "cal"
    assert cli.main(["calibrate", "paper_open_loop", "--out", str(out)]) == 143
    assert "cdpr-twin calibrate: terminated" in capsys.readouterr().err
    assert not out.exists()


def test_a_sigterm_re_raised_as_a_plain_ctrl_c_is_still_a_sigterm_and_only_within_its_command():
    # truth: the signal actually delivered (raise_signal), against what the code then sees: a
    # library (Ray's signal check) re-raising our Terminated as its base class
    import signal

    from cdpr_twin.run.interrupts import sigterm_raises

    def library_call():
        try:
            signal.raise_signal(signal.SIGTERM)
        except KeyboardInterrupt:
            raise KeyboardInterrupt from None  # what Ray's ray.wait makes of it

    with pytest.raises(Terminated), sigterm_raises():
        library_call()
    assert type(interruption(KeyboardInterrupt())) is KeyboardInterrupt  # a later Ctrl-C
    with pytest.raises(KeyboardInterrupt) as caught, sigterm_raises():
        raise KeyboardInterrupt
    assert type(caught.value) is KeyboardInterrupt


FIRST_DECIDES = [
    (signal.SIGINT, signal.SIGTERM, 130, "interrupted"),
    (signal.SIGTERM, signal.SIGINT, 143, "terminated"),
]


@pytest.mark.parametrize(
    ("first", "second", "code", "status"), FIRST_DECIDES, ids=["INT+TERM", "TERM+INT"]
)
@pytest.mark.parametrize("second_lands", ["as the stop is caught", "as the outputs are saved"])
def test_a_second_signal_of_the_other_kind_does_not_change_the_exit_code(
    tmp_path, monkeypatch, capsys, first, second, code, status, second_lands
):
    # before: SIGINT then SIGTERM 0.05-0.3 s later gave "status": "interrupted" and exit 143.
    # Here the first lands at the 5th physics advance and the second from a hook in the stop's
    # own handling, every time. Truth: summary.json, read back, and the exit code
    from cdpr_twin import cli
    from cdpr_twin.run import summary as tally
    from cdpr_twin.sim import physics

    advance, calls = physics.Physics.advance, [0]

    def advance_then_stop(self, *args):
        advance(self, *args)
        calls[0] += 1
        if calls[0] == 5:
            signal.raise_signal(first)

    def hook(real):
        def with_second_signal(*args):
            signal.raise_signal(second)  # the handler runs here, as raise_signal returns
            return real(*args)

        return with_second_signal

    monkeypatch.setattr(physics.Physics, "advance", advance_then_stop)
    if second_lands == "as the stop is caught":
        monkeypatch.setattr(runner, "interruption", hook(runner.interruption))
    else:
        monkeypatch.setattr(runner, "summarize", hook(tally.summarize))
    out = tmp_path / "out"
    argv = ["run", "paper_open_loop", "--out", str(out), "--duration", "1", "--no-camera"]
    assert cli.main(argv) == code
    assert json.loads((out / "summary.json").read_text())["status"] == status
    said = [line for line in capsys.readouterr().err.splitlines() if line.startswith("cdpr-twin")]
    assert said == [f'cdpr-twin: {status}; partial outputs (flushed, marked "{status}") in {out}']


@pytest.mark.parametrize(
    ("first", "second", "code", "status"), FIRST_DECIDES, ids=["INT+TERM", "TERM+INT"]
)
def test_a_tick_held_by_two_signals_escapes_as_the_first(first, second, code, status):
    # truth: the signals actually delivered, in their order; before, the second one decided
    from cdpr_twin.run.interrupts import shielded, sigterm_raises

    with pytest.raises(KeyboardInterrupt) as stop, sigterm_raises(), shielded(escape=True):
        signal.raise_signal(first)  # held: the tick is being recorded
        signal.raise_signal(second)  # a second signal: the stop escapes at once
    assert isinstance(stop.value, Terminated) == (first == signal.SIGTERM)


def test_a_second_ctrl_c_while_a_stopped_run_saves_cannot_leave_it_half_saved(
    tmp_path, monkeypatch
):
    from cdpr_twin.recording import sinks as recorders

    close = recorders.Recorders.close

    def close_under_fire(self, summary, commit=True):
        os.kill(os.getpid(), signal.SIGINT)  # the impatient user's second Ctrl-C
        return close(self, summary, commit)

    def stop(fraction, t):
        raise KeyboardInterrupt  # the first Ctrl-C, at the first tick

    monkeypatch.setattr(recorders.Recorders, "close", close_under_fire)
    s = load_scenario("paper_open_loop").with_overrides(duration=0.2, camera=False)
    with pytest.raises(KeyboardInterrupt):
        run(s, tmp_path / "out", progress=stop)
    files = sorted(p.name for p in (tmp_path / "out").iterdir())
    assert files == ["recording.rrd", "summary.json", "timeseries.csv"]
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["status"] == "interrupted"


def test_a_stop_before_the_run_claims_its_directory_does_not_claim_an_earlier_runs_files(
    tmp_path, monkeypatch, capsys
):
    from cdpr_twin.cli import main
    from cdpr_twin.files.transaction import Terminated
    from cdpr_twin.run import runner

    out = tmp_path / "out"
    out.mkdir()
    (out / "summary.json").write_text(EARLIER_SUMMARY % "terminated")  # an earlier run's
    os.utime(out / "summary.json", (0, 0))

    def prepare(scenario):
        raise Terminated()  # SIGTERM while the robot is being built

    monkeypatch.setattr(runner, "prepare", prepare)
    assert main(["run", "paper_open_loop", "--out", str(out), "--no-camera"]) == 143
    err = capsys.readouterr().err
    assert "terminated before this run saved any output" in err and "partial" not in err


def test_a_signal_during_a_completed_runs_save_is_delivered_once_the_files_are_whole(
    tmp_path, monkeypatch
):
    from cdpr_twin.recording import sinks as recorders

    close = recorders.Recorders.close

    def close_under_fire(self, summary, commit=True):
        os.kill(os.getpid(), signal.SIGINT)  # Ctrl-C just as the finished run saves
        return close(self, summary, commit)

    monkeypatch.setattr(recorders.Recorders, "close", close_under_fire)
    s = load_scenario("paper_open_loop").with_overrides(duration=0.2, camera=False)
    with pytest.raises(KeyboardInterrupt):  # held off, not lost
        run(s, tmp_path / "out")
    assert json.loads((tmp_path / "out" / "summary.json").read_text())["status"] == "completed"
    assert not list((tmp_path / "out").glob("*.partial")) and not (tmp_path / "out/.lock").exists()


def test_a_sigterm_as_the_run_ends_says_its_outputs_are_complete(tmp_path, monkeypatch, capsys):
    from cdpr_twin.cli import main
    from cdpr_twin.recording import sinks as recorders

    close = recorders.Recorders.close

    def close_under_fire(self, summary, commit=True):
        os.kill(os.getpid(), signal.SIGTERM)  # the supervisor's stop, just as the run saves
        return close(self, summary, commit)

    monkeypatch.setattr(recorders.Recorders, "close", close_under_fire)
    out = tmp_path / "out"
    argv = ["run", "paper_open_loop", "--out", str(out), "--duration", "0.2", "--no-camera"]
    assert main(argv) == 143
    assert f"terminated as the run ended (completed): its outputs in {out} are complete" in (
        capsys.readouterr().err
    )
    assert json.loads((out / "summary.json").read_text())["status"] == "completed"


def test_a_held_signal_of_another_kind_than_the_stop_under_way_is_delivered():
    from cdpr_twin.files.transaction import Terminated
    from cdpr_twin.run.interrupts import shielded, sigterm_raises

    with sigterm_raises(), pytest.raises(Terminated):  # a pool worker told to stop while it
        try:  # saves a run stopped by Ctrl-C: the SIGTERM must still end it
            raise KeyboardInterrupt
        finally:
            with shielded():
                os.kill(os.getpid(), signal.SIGTERM)
    with pytest.raises(KeyboardInterrupt) as stop:  # a second Ctrl-C: absorbed by the first
        try:
            raise KeyboardInterrupt("first")
        finally:
            with shielded():
                os.kill(os.getpid(), signal.SIGINT)
    assert str(stop.value) == "first"


def test_a_library_run_holds_a_signal_in_a_ticks_record_and_hands_it_to_the_callers_handler(
    tmp_path, monkeypatch
):
    # truth: the order in which the sink finished and the caller's own handler ran, and the
    # handler installed after the run (``run`` used as a library: no command's handler)
    from cdpr_twin.recording import sinks as recorders

    seen: list[str] = []

    class StopError(Exception):
        pass

    def callers_handler(signum, frame):
        seen.append(f"handler {signum}")
        raise StopError

    add = recorders.Recorders.add
    calls = {"n": 0}

    def add_under_fire(self, tick):
        calls["n"] += 1
        if calls["n"] == 4:  # inside the shield of the fourth tick's record
            signal.raise_signal(signal.SIGTERM)
            seen.append("signal sent")
        add(self, tick)
        seen.append(f"sink {calls['n']}")

    monkeypatch.setattr(recorders.Recorders, "add", add_under_fire)
    previous = signal.signal(signal.SIGTERM, callers_handler)
    try:
        s = load_scenario("paper_open_loop").with_overrides(duration=0.4, camera=False)
        with pytest.raises(StopError):
            run(s, tmp_path / "run", record_rrd=False)
        assert signal.getsignal(signal.SIGTERM) is callers_handler
    finally:
        signal.signal(signal.SIGTERM, previous)
    # held until the tick was in the sink, then the caller's handler, and nothing after it
    assert seen[-3:] == ["signal sent", "sink 4", f"handler {int(signal.SIGTERM)}"]
    # outside a record, a signal reaches the caller's handler at once
    seen.clear()
    calls["n"] = 0
    monkeypatch.setattr(recorders.Recorders, "add", add)

    def progress(fraction, t):
        calls["n"] += 1
        if calls["n"] == 2:
            signal.raise_signal(signal.SIGTERM)
            seen.append("after the signal")  # not reached: the handler raised

    previous = signal.signal(signal.SIGTERM, callers_handler)
    try:
        with pytest.raises(StopError):
            run(s, tmp_path / "run2", record_rrd=False, progress=progress)
    finally:
        signal.signal(signal.SIGTERM, previous)
    assert seen == [f"handler {int(signal.SIGTERM)}"]
