"""A run stopped anywhere in a tick leaves files that all end at the same recorded tick.

Before: a Ctrl-C or SIGTERM landing during the physics' advance left
``summary.json`` describing that mid-tick state (``simulated_time_s`` half a tick past the CSV's
last row, ``final_pose`` up to 2.35 mm from it), a state no file recorded; one landing inside the
recording of a tick left it in ``timeseries.csv`` but not in ``recording.rrd``.

Truth: the run's own ``timeseries.csv`` (``%.17g``, exact), read back independently.
"""

import signal
from pathlib import Path

import numpy as np
import pytest

from cdpr_twin.files.transaction import Terminated
from cdpr_twin.math import se3
from cdpr_twin.recording import rerun as record
from cdpr_twin.recording.timeseries import load_timeseries
from cdpr_twin.run import runner
from cdpr_twin.run.interrupts import sigterm_raises
from cdpr_twin.scenario.loading import load_scenario
from cdpr_twin.sim import physics

ROOT = Path(__file__).resolve().parents[2]
STOP_AT = 12
"""The call (of the physics' advance, or of the recording of a tick) in which SIGTERM lands."""


def _stop_inside(monkeypatch, owner, name: str, before: bool) -> list[int]:
    """SIGTERM raised in the ``STOP_AT``-th call of ``owner.name``: ``before`` its work, or
    half way (the physics: half its steps done). Returns the count of calls that completed."""
    original, calls, done = getattr(owner, name), [0], [0]

    def wrapper(self, *args, **kwargs):
        calls[0] += 1
        if calls[0] == STOP_AT and before:
            signal.raise_signal(signal.SIGTERM)  # the handler runs as raise_signal returns
        if calls[0] == STOP_AT and not before:  # the physics: half the period, then the stop
            duration, rates = args
            original(self, duration / 2, rates)
            signal.raise_signal(signal.SIGTERM)
            original(self, duration / 2, rates)
        else:
            original(self, *args, **kwargs)
        done[0] += 1

    monkeypatch.setattr(owner, name, wrapper)
    return done


def _run_stopped(tmp_path: Path) -> tuple[dict, object]:
    import json

    s = load_scenario(ROOT / "scenarios" / "paper_open_loop.toml").with_overrides(camera=False)
    out = tmp_path / "out"
    with pytest.raises(Terminated), sigterm_raises():
        runner.run(s, out)
    return json.loads((out / "summary.json").read_text()), load_timeseries(out / "timeseries.csv")


def test_a_stop_during_the_physics_leaves_the_summary_at_the_last_recorded_tick(
    tmp_path, monkeypatch
):
    _stop_inside(monkeypatch, physics.Physics, "advance", before=False)
    summary, ts = _run_stopped(tmp_path)
    c = ts.columns
    assert summary["status"] == "terminated"
    assert summary["ticks_recorded"] == len(c["t"]) == STOP_AT  # t = 0 and ticks 1…11
    assert summary["simulated_time_s"] == c["t"][-1]
    T_last = se3.transform(
        se3.matrix_from_quat_wxyz(np.array([c[f"true_q{a}"][-1] for a in "wxyz"])),
        np.array([c[f"true_{a}"][-1] for a in "xyz"]),
    )
    final, recorded = np.array(summary["final_pose"]), se3.vector_from_pose(T_last)
    assert final[:3].tolist() == recorded[:3].tolist()  # the same floats
    assert np.abs(final[3:] - recorded[3:]).max() < 1e-9  # [deg] (a quaternion round trip)


def test_a_stop_while_a_tick_is_recorded_leaves_it_in_every_file(tmp_path, monkeypatch):
    rrd_ticks = _stop_inside(monkeypatch, record.RerunRecorder, "tick", before=True)
    summary, ts = _run_stopped(tmp_path)
    assert summary["status"] == "terminated"
    # the tick the stop landed in is whole: in the CSV, the Rerun recording and the summary
    assert rrd_ticks[0] == len(ts.columns["t"]) == summary["ticks_recorded"] == STOP_AT
    assert summary["simulated_time_s"] == ts.columns["t"][-1]


def test_an_event_fired_after_the_last_recorded_tick_is_not_reported_fired(tmp_path, monkeypatch):
    # cable 3 cut at 0.45 s inside the advance a stop cut short (0.44 → 0.48 s): the
    # summary listed the break while its final tensions were those of an intact cable 3
    import json

    text = (ROOT / "scenarios" / "paper_open_loop.toml").read_text()
    text = text.replace('"../models/', f'"{ROOT}/models/')
    path = tmp_path / "cut.toml"
    path.write_text(text + '\n[[events]]\nkind = "cable_break"\nat = 0.45\ncable = 3\n')
    _stop_inside(monkeypatch, physics.Physics, "advance", before=False)
    out = tmp_path / "out"
    with pytest.raises(Terminated), sigterm_raises():
        runner.run(load_scenario(path).with_overrides(camera=False), out)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["simulated_time_s"] == pytest.approx(0.44, abs=1e-9)
    assert "events" not in summary and summary["final_tensions_n"][2] > 1.0  # intact then
    [late] = summary["events_not_reached"]
    assert (late["kind"], late["phase"], late["cable"]) == ("cable_break", "start", 3)
    assert late["due_s"] == pytest.approx(0.45, abs=1e-9)


def test_a_stop_held_by_the_shield_leaves_even_when_the_body_raises_and_a_second_escapes():
    # a SIGTERM held during a tick whose recording then raised was lost (exit 1, not
    # 143); and a body that hangs could only be stopped by SIGKILL
    from cdpr_twin.run.interrupts import shielded

    with pytest.raises(Terminated) as stop, sigterm_raises(), shielded(escape=True):
        signal.raise_signal(signal.SIGTERM)  # held
        raise RuntimeError("a recorder's bug")
    assert isinstance(stop.value.__context__, RuntimeError)  # the stop came first
    after = []
    with pytest.raises(KeyboardInterrupt), shielded(escape=True):
        signal.raise_signal(signal.SIGINT)  # held
        signal.raise_signal(signal.SIGINT)  # a second Ctrl-C: at once
        after.append("ran on")
    assert after == []
    with pytest.raises(KeyboardInterrupt), shielded():  # (the default: held until it ends)
        signal.raise_signal(signal.SIGINT)
        signal.raise_signal(signal.SIGINT)
        after.append("ran on")
    assert after == ["ran on"]
