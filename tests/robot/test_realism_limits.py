"""What a ``[realism]`` table may ask for: magnitudes no real robot has are refused by name.

Each bound is checked on both sides: the largest accepted value loads (or runs), a value past
it is a one-line error naming ``realism.<part>.<field>``. Before these bounds a principal-point
error std of 1e6 px crashed the process in the AprilTag detector (SIGSEGV, no message), 10⁶
blur sub-frames held a 5-tick run for minutes while its memory grew without end, and a
homing repeatability of 10⁶ degrees started a run 140° from where the robot believed it was.
"""

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from cdpr_twin.cli import main
from cdpr_twin.plugins import OptionError
from cdpr_twin.robot import realism as rl
from cdpr_twin.scenario.loading import ScenarioError, load_scenario
from cdpr_twin.types import CameraIntrinsics

ROOT = Path(__file__).resolve().parents[2]
PBVS = (
    (ROOT / "scenarios" / "paper_pbvs.toml").read_text().replace('"../models/', f'"{ROOT}/models/')
)


def _scenario(tmp_path: Path, part: str, lines: str) -> Path:
    path = tmp_path / "s.toml"
    path.write_text(PBVS + f"\n[realism.{part}]\n{lines}\n")
    return path


@pytest.mark.parametrize(
    ("part", "ok", "bad", "match"),
    [
        (
            "camera",
            "center_error_std_px = 20.0",
            "center_error_std_px = 1e6",
            r"realism\.camera\.center_error_std_px: must be ≤ 20 px",
        ),
        (
            "camera",
            "distortion_error_std = [0.1, 0.1, 0.1, 0.1]",
            "distortion_error_std = [0.01, 10.0, 0.0, 0.0]",
            r"realism\.camera\.distortion_error_std: must be ≤ 0\.1 each",
        ),
        (
            "homing",
            "position_std = 0.05",
            "position_std = 1.0",
            r"realism\.homing\.position_std: must be ≤ 0\.05 m",
        ),
        (
            "homing",
            "rotation_std_deg = 5.0",
            "rotation_std_deg = 1e6",
            r"realism\.homing\.rotation_std_deg: must be ≤ 5°",
        ),
    ],
)
def test_magnitudes_beyond_any_real_robot_are_refused_when_the_file_loads(
    tmp_path, part, ok, bad, match
):
    load_scenario(_scenario(tmp_path, part, ok))
    with pytest.raises(ScenarioError, match=match):
        load_scenario(_scenario(tmp_path, part, bad))


def test_inf_switches_one_winch_effect_off_as_documented(tmp_path):
    """``inf`` is the documented "off" of the velocity loop and of the slew limit: each can be
    switched off alone under the acrobot profile (before: "must be a finite number")."""
    s = load_scenario(_scenario(tmp_path, "winch", "bandwidth_hz = inf"))
    acrobot = rl.profile("acrobot").winch
    assert math.isinf(s.realism.winch.bandwidth_hz)
    assert s.realism.winch.max_accel == acrobot.max_accel and math.isfinite(acrobot.max_accel)
    s = load_scenario(_scenario(tmp_path, "winch", "max_accel = inf"))
    assert math.isinf(s.realism.winch.max_accel)
    for bad in ("max_accel = -inf", "bandwidth_hz = nan", "encoder_counts = inf"):
        with pytest.raises(ScenarioError, match=r"realism\.winch\.\w+: must be"):
            load_scenario(_scenario(tmp_path, "winch", bad))


@pytest.mark.parametrize(
    ("part", "ok", "bad", "match"),
    [
        # the robot's exposure 8 ms at a 0.5 ms step: 16 distinct states to average
        (
            "camera",
            "blur_subframes = 16",
            "blur_subframes = 17",
            r"realism\.camera\.blur_subframes: 17 sub-frames in a 0\.008 s exposure: at most 16",
        ),
        (
            "camera",
            "exposure_s = 0.04",
            "exposure_s = 0.05",
            r"realism\.camera\.exposure_s: 0\.05 s needs the camera's read period",
        ),
        # before: "model: range_max: must exceed range_min", naming a field nobody wrote
        (
            "tension",
            "range_min = 0.0",
            "range_min = 1e6",
            r"realism\.tension\.range_min: the readings' range 1e\+06…75 N .* must hold 0 N",
        ),
        (
            "tension",
            "range_max = 100.0",
            "range_max = -5.0",
            r"realism\.tension\.range_max: the readings' range -25…-5 N .* must hold 0 N",
        ),
    ],
)
def test_what_only_the_built_robot_can_check_names_the_realism_field(
    tmp_path, capsys, part, ok, bad, match
):
    import re

    for lines, code in ((ok, 0), (bad, 2)):
        path = _scenario(tmp_path, part, lines)
        out = tmp_path / f"out{code}"
        assert main(["run", str(path), "--duration", "0.08", "--out", str(out)]) == code
        err = capsys.readouterr().err
        if code == 2:
            assert re.search(f"^cdpr-twin: error: {re.escape(str(path))}: {match}", err), err
            assert err.count("\n") == 1 and not out.exists()


def test_the_detector_refuses_intrinsics_it_cannot_fit_a_pose_with():
    """A principal point far outside the image crashed pupil-apriltags' pose fit (SIGSEGV at
    cx = 1e6 px); a non-positive focal length has no pinhole. Both are refused up front."""
    from cdpr_twin.vision.detection import TagDetector

    K = CameraIntrinsics(640, 480, 600.0, 600.0, 320.0, 240.0)
    TagDetector(K)
    TagDetector(CameraIntrinsics(640, 480, 600.0, 600.0, 640.0, 0.0))  # on the edge: fine
    for bad in ({"cx": 1e6}, {"cy": -1.0}, {"fx": 0.0}, {"fy": np.nan}, {"cx": np.nan}):
        with pytest.raises(ValueError, match=r"need positive focal lengths and the point inside"):
            TagDetector(dataclasses.replace(K, **bad))


def test_a_model_files_own_tension_range_is_the_models_data_not_refused(tmp_path, capsys):
    """A hand-written MJCF whose sensors read 5…75 N (``<numeric tension_sensor_range>``) ran
    before the 0 N rule and runs still, under both profiles: only a range the scenario sets is
    held to it (robot descriptions are checked when read)."""
    import shutil

    shutil.copytree(ROOT / "models" / "acrobot", tmp_path / "robot")
    scene = tmp_path / "robot" / "scene.xml"
    text = scene.read_text()
    assert 'name="tension_sensor_range" size="2" data="-25 75"' in text
    scene.write_text(text.replace('data="-25 75"', 'data="5 75"'))
    path = tmp_path / "s.toml"
    path.write_text(PBVS.replace('robot = "acrobot"', f'file = "{scene}"', 1))
    for profile in ("ideal", "acrobot"):
        out = tmp_path / profile
        code = main(
            ["run", str(path), "--duration", "0.08", "--realism", profile, "--out", str(out)]
        )
        assert code == 0, capsys.readouterr().err
    path.write_text(path.read_text() + "\n[realism.tension]\nrange_max = 100.0\n")
    assert main(["run", str(path), "--duration", "0.08", "--out", str(tmp_path / "set")]) == 2
    assert "realism.tension.range_max: the readings' range 5…100 N" in capsys.readouterr().err


OPEN_LOOP = (
    (ROOT / "scenarios" / "paper_open_loop.toml")
    .read_text()
    .replace('"../models/', f'"{ROOT}/models/')
)
FAIL = '\n[[events]]\nkind = "tension_sensor_fail"\nat = 0.04\ncable = 2\nvalue = {}\n'


@pytest.mark.parametrize(
    ("old", "ok", "bad", "match"),
    [
        # before: ±1e308 and inf tensions written, status "completed"
        (
            "tension_noise_std = 0.24",
            "tension_noise_std = 1000.0",
            "tension_noise_std = 1e308",
            r"sensors\.tension_noise_std: must be ≤ 1000 N \(.*\), got 1e\+308",
        ),
        # before: an 8-line array in the error ("CdprGeometry.a_base contains NaN or inf: [[…")
        (
            "exit_point_std = 0.012",
            "exit_point_std = 1.0",
            "exit_point_std = 1e308",
            r"truth\.exit_point_std: must be ≤ 1 m \(.*\), got 1e\+308",
        ),
        (
            "anchor_point_std = 0.004",
            "anchor_point_std = 1.0",
            "anchor_point_std = 1.5",
            r"truth\.anchor_point_std: must be ≤ 1 m",
        ),
        (
            "pulley_radius_std = 0.0002",
            "pulley_radius_std = 0.01",
            "pulley_radius_std = 0.02",
            r"truth\.pulley_radius_std: must be ≤ 0\.01 m \(sheaves",
        ),
        (
            "es_scale_std = 0.10",
            "es_scale_std = 0.1",
            "es_scale_std = 0.2",
            r"truth\.es_scale_std: must be ≤ 0\.1 \(a relative std",
        ),
        # before: "model: math domain error"
        (
            "camera_rotation_std_deg = 0.3",
            "camera_rotation_std_deg = 10.0",
            "camera_rotation_std_deg = 1e308",
            r"truth\.camera_rotation_std_deg: must be ≤ 10°",
        ),
        (
            "tag_position_std = 0.001",
            "tag_position_std = 1.0",
            "tag_position_std = 2.0",
            r"truth\.tag_position_std: must be ≤ 1 m",
        ),
        (
            "tag_rotation_std_deg = 0.3",
            "tag_rotation_std_deg = 10.0",
            "tag_rotation_std_deg = 10.5",
            r"truth\.tag_rotation_std_deg: must be ≤ 10°",
        ),
        (
            'profile = "acrobot"',
            'profile = "acrobot"\n[realism.tension]\nnoise_std = 1000.0',
            'profile = "acrobot"\n[realism.tension]\nnoise_std = 1e308',
            r"realism\.tension\.noise_std: must be ≤ 1000 N",
        ),
        (
            'profile = "acrobot"',
            'profile = "acrobot"\n[realism.tension]\nbias_std = 1000.0',
            'profile = "acrobot"\n[realism.tension]\nbias_std = 1001.0',
            r"realism\.tension\.bias_std: must be ≤ 1000 N",
        ),
        # before: accepted, and read 1e300 N for the rest of the run
        (
            "[estimators]",
            FAIL.format("-1e6") + "[estimators]",
            FAIL.format("1e300") + "[estimators]",
            r"events\[0\]\.value: must be nan or a force within ±1e\+06 N .*, got 1e\+300",
        ),
    ],
)
def test_noise_calibration_errors_and_fault_readings_beyond_any_robot_are_refused_by_field(
    tmp_path, capsys, old, ok, bad, match
):
    """The largest accepted value loads; one past it is exit 2 and one line naming the field,
    its bound and the value, under the ideal profile too (the noise the file gives is used)."""
    import re

    assert old in OPEN_LOOP
    fine = tmp_path / "ok.toml"
    fine.write_text(OPEN_LOOP.replace(old, ok, 1))
    load_scenario(fine)
    path = tmp_path / "s.toml"
    path.write_text(OPEN_LOOP.replace(old, bad, 1))
    out = tmp_path / "out"
    argv = ["run", str(path), "--duration", "0.08", "--no-camera", "--out", str(out)]
    assert main([*argv, "--realism", "ideal"]) == 2
    err = capsys.readouterr().err
    assert re.search(f"^cdpr-twin: error: {re.escape(str(path))}: {match}", err), err
    assert err.count("\n") == 1 and not out.exists()


@pytest.mark.parametrize(
    "line",
    ["exit_point_std = -0.0", "camera_rotation_std_deg = -0.0", "es_scale_std = -0.0"],
)
def test_minus_zero_in_a_truth_std_is_zero(tmp_path, capsys, line):
    """Before: it passed validation, then failed in numpy ("model: scale < 0")."""
    key = line.split(" = ")[0]
    start = OPEN_LOOP.index(f"{key} = ")
    text = OPEN_LOOP[:start] + line + OPEN_LOOP[OPEN_LOOP.index("\n", start) :]
    path = tmp_path / "s.toml"
    path.write_text(text)
    truth = load_scenario(path).truth
    field = key.replace("_deg", "")
    assert getattr(truth, field) == 0.0 and math.copysign(1.0, getattr(truth, field)) == 1.0
    out = tmp_path / "out"
    argv = ["run", str(path), "--duration", "0.08", "--no-camera", "--out", str(out)]
    assert main(argv) == 0, capsys.readouterr().err
    assert "error" not in capsys.readouterr().err


def test_the_relative_std_bound_keeps_negative_draws_beyond_10_sigma():
    from cdpr_twin.robot.realism import MAX_RELATIVE_STD, WinchRealism

    WinchRealism(drum_radius_error_std=MAX_RELATIVE_STD)
    with pytest.raises(OptionError, match=r"once in 20\.9 robots"):  # P(z < −1/0.6) = 0.0478
        WinchRealism(drum_radius_error_std=0.6)
    assert 0.5 * math.erfc(1 / MAX_RELATIVE_STD / math.sqrt(2)) < 1e-22


def test_a_run_starts_from_one_homing_drums_or_pose_offset():
    """Drums zeroed on their own replace the rigid pose offset: both at once are refused."""
    with pytest.raises(OptionError) as err:
        rl.profile("acrobot", drive={"zero_error_std": 1e-5})
    assert "zero_error_std" in str(err.value) and "\n" not in str(err.value)
    off = {"position_std": 0.0, "rotation_std": 0.0}
    by_drums = rl.profile("acrobot", drive={"zero_error_std": 1e-5}, homing=off)
    assert by_drums.drive.zero_error_std == 1e-5


def test_without_homing_the_full_profiles_drums_are_zeroed_exactly():
    full = rl.profile("acrobot_full")
    assert full.drive.zero_error_std > 0.0
    exact = rl.without_source(full, "homing")
    assert exact.drive.zero_error_std == 0.0 and exact.homing.position_std == 0.0
