"""The Rerun recording's legends tell the truth: one colour per estimator, the same in the
position and the rotation deviation plots (each had its own default colours before, and one
legend, so the image estimate's noisy series read as ``model_pulley``'s)."""

from pathlib import Path

import rerun as rr

from cdpr_twin.recording.rerun import robot_label
from cdpr_twin.run.runner import run
from cdpr_twin.scenario.loading import load_scenario

ROOT = Path(__file__).resolve().parents[2]


def test_each_estimator_has_one_colour_in_both_deviation_plots(tmp_path, monkeypatch):
    logged: dict[str, object] = {}
    real_log = rr.RecordingStream.log

    def log(self, path, *args, **kwargs):
        if path.startswith("deviation/") and kwargs.get("static"):
            logged[path] = args[0]
        return real_log(self, path, *args, **kwargs)

    monkeypatch.setattr(rr.RecordingStream, "log", log)
    s = load_scenario(ROOT / "scenarios" / "paper_open_loop.toml").with_overrides(
        duration=0.2, camera=False
    )
    run(s, tmp_path / "run")
    assert set(logged) == {"deviation/translation_mm", "deviation/rotation_deg"}
    legends = [
        (
            tuple(lines.names.as_arrow_array().to_pylist()),
            tuple(lines.colors.as_arrow_array().to_pylist()),
        )
        for lines in logged.values()
    ]
    (names, colours), other = legends
    assert other == (names, colours)
    assert names == tuple(s.estimators.names) and len(set(colours)) == len(names)
    assert (tmp_path / "run" / "recording.rrd").stat().st_size > 0


def test_the_3d_view_is_titled_with_the_robots_name():
    assert robot_label(ROOT / "models" / "acrobot" / "scene.xml") == "ACROBOT"
    assert robot_label(ROOT / "models" / "cogiro" / "scene.xml") == "COGIRO"
    assert robot_label(Path("/data/my_cdpr.xml")) == "MY_CDPR"
    assert robot_label(None) == "robot"
