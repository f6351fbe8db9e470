"""Drum radii a calibration estimated, used by the software: a robot description's
``[winches] drum_radius_scale`` sets the drives and encoders (``Physics.set_drum_radii``), so
the cable paid out is the cable commanded. Checked end to end on the paper's open loop: a robot
whose only error is its drums' radii misses p1 by millimetres with the nominal model, and by the
model's own residual once its description carries the true radii."""

import os
import tomllib
from pathlib import Path

import numpy as np
import pytest
from conftest import EXACT_OPEN_LOOP

from cdpr_twin import MODELS_DIR
from cdpr_twin.calibrate.output import toml_text
from cdpr_twin.campaign.spec import set_dotted
from cdpr_twin.run.runner import prepare, run
from cdpr_twin.scenario.loading import scenario_from_data

ROOT = Path(__file__).resolve().parents[2]
SOURCE = ROOT / "scenarios" / "paper_open_loop.toml"
DRUMS_ONLY = {**EXACT_OPEN_LOOP, "realism.winch.drum_radius_error_std": 0.01}  # 1 % per drum


def _scenario(nominal: Path | None = None):
    data = tomllib.loads(SOURCE.read_text())
    for key, value in DRUMS_ONLY.items():
        set_dotted(data, key, value)
    if nominal is not None:
        set_dotted(data, "model.nominal", str(nominal))
    return scenario_from_data(data, SOURCE)


def _miss_at_p1(scenario) -> float:
    return run(scenario, None).summary["segment_ends"][0]["truth_vs_waypoint"]["translation_m"]


def test_a_description_with_the_true_drum_radii_removes_their_error_at_p1(tmp_path):
    setup = prepare(_scenario())
    try:
        true_scale = setup.physics.drum_radius_true / setup.physics.winch.drum_radius
    finally:
        setup.close()
    assert np.abs(true_scale - 1).max() > 0.005  # drums off by up to percents
    description = tomllib.loads((MODELS_DIR / "acrobot" / "robot.toml").read_text())
    description["winches"]["drum_radius_scale"] = true_scale.tolist()
    texture = MODELS_DIR / "acrobot" / description["tag"]["texture"]
    description["tag"]["texture"] = str(texture)
    calibrated = tmp_path / "robot.toml"
    calibrated.write_text(toml_text(description))

    nominal, exact = _miss_at_p1(_scenario()), _miss_at_p1(_scenario(calibrated))
    print(f"p1 missed by {nominal * 1e3:.2f} mm (nominal drums), {exact * 1e3:.2f} mm (true)")
    assert nominal > 1e-3 and exact < 0.3e-3 and exact < nominal / 5


def _description(tmp_path: Path, **winches) -> Path:
    """ACROBOT's description with ``[winches]`` fields changed, written to a file."""
    data = tomllib.loads((MODELS_DIR / "acrobot" / "robot.toml").read_text())
    data["winches"].update(winches)
    data["tag"]["texture"] = str(MODELS_DIR / "acrobot" / data["tag"]["texture"])
    path = tmp_path / "robot.toml"
    path.write_text(toml_text(data))
    return path


def test_the_software_sets_its_drums_to_the_described_radius_times_the_scale(tmp_path):
    from cdpr_twin.sim import build_robot

    path = _description(tmp_path, drum_radius_m=0.0201, drum_radius_scale=[1.01] * 8)
    built = build_robot("acrobot", nominal_path=path)
    physics, nominal = built.physics, built.nominal
    np.testing.assert_allclose(nominal.drum_radii, 0.0201 * 1.01, rtol=1e-15)
    np.testing.assert_array_equal(physics.drum_radius_set, nominal.drum_radii)


def test_a_calibration_scales_the_radii_it_read_with_not_the_file_it_copies(tmp_path):
    """s_i is relative to the radius the encoder was set to while recording: r_set·(1 + s_i)
    over the description's drum_radius_m, whatever scale the copied description held."""
    from types import SimpleNamespace

    from cdpr_twin.calibrate.output import calibrated_description
    from cdpr_twin.sim import nominal_robot

    source = _description(tmp_path, drum_radius_scale=[1.1] * 8)  # not what the drums were set to
    g = nominal_robot("acrobot").geometry
    s = np.linspace(-0.004, 0.004, 8)
    model = SimpleNamespace(
        a_base=g.a_base,
        b_platform=g.b_platform,
        scale=s,
        T_platform_cam=g.T_platform_cam,
        T_base_tag=np.eye(4),
    )
    for set_to in (np.full(8, 0.02), np.full(8, 0.021), np.full(8, 0.03)):  # 0.03: an override
        text = calibrated_description(source, SimpleNamespace(model=model), set_to)
        winches = tomllib.loads(text)["winches"]
        radius, written = winches["drum_radius_m"], np.array(winches["drum_radius_scale"])
        np.testing.assert_allclose(radius * written, set_to * (1 + s), rtol=1e-8)
        assert radius == (0.02 if set_to[0] < 0.022 else pytest.approx(0.03, rel=0.01))
        assert np.all(abs(written - 1) < 0.1)  # a file load_robot takes


@pytest.mark.parametrize(
    ("scale", "match"),
    [
        ([0.0201] * 8, "not metres"),
        ([True] * 8, "not metres"),
        ([1.0] * 7, "shape"),
        ([1.0] * 7 + [-1.0], "> 0"),
    ],
    ids=["metres", "booleans", "seven", "negative"],
)
def test_a_drum_scale_that_is_not_one_per_drum_near_1_is_refused(tmp_path, scale, match):
    from cdpr_twin.robot.description import RobotError, load_robot

    with pytest.raises(RobotError, match=match):
        load_robot(_description(tmp_path, drum_radius_scale=scale))


def test_the_physics_refuses_drum_radii_that_are_not_one_positive_number_per_drum():
    from cdpr_twin.sim import build_robot

    physics = build_robot("acrobot").physics
    for bad in (np.full(7, 0.02), np.r_[np.full(7, 0.02), 0.0], np.full(8, np.nan)):
        with pytest.raises(ValueError, match=r"drum radii: 8 within 10 % of 0\.02 m"):
            physics.set_drum_radii(bad)


def test_a_description_without_drum_scales_leaves_the_drives_at_the_robots_radius(tmp_path):
    from cdpr_twin.robot.realism import WinchRealism
    from cdpr_twin.sim import ModelError, build_robot

    winch = WinchRealism(drum_radius=0.03)  # a scenario's override of the robot's 20 mm
    plain = MODELS_DIR / "acrobot" / "robot.toml"
    built = build_robot("acrobot", winch=winch, nominal_path=plain)
    physics, nominal = built.physics, built.nominal
    assert nominal.drum_radii is None and np.all(physics.drum_radius_set == 0.03)
    scaled = _description(tmp_path, drum_radius_scale=[1.0] * 8)  # 20 mm drums, told 30 mm
    with pytest.raises(ModelError, match=r"drum_radius_m × scale: drum radii: 8 within 10 %"):
        build_robot("acrobot", winch=winch, nominal_path=scaled)


def test_a_recording_reads_with_the_radii_its_drives_are_set_to(tmp_path):
    """What the calibration's s_i is relative to: the recording's set radii, and its truth."""
    from cdpr_twin.calibrate.acquire import record

    path = _description(tmp_path, drum_radius_scale=np.linspace(0.99, 1.01, 8).tolist())
    s = _scenario(path)
    s = s.with_overrides(camera=True)
    rec = record(s, [s.start_pose, s.start_pose], frames=1)
    np.testing.assert_allclose(rec.drum_radii, 0.02 * np.linspace(0.99, 1.01, 8), rtol=1e-12)
    setup = prepare(s)  # the same robot: its true drums
    try:
        true = setup.physics.drum_radius_true
    finally:
        setup.close()
    np.testing.assert_allclose(rec.truth.drum_scale, true / rec.drum_radii - 1, rtol=1e-12)


def test_a_calibrated_description_moved_with_its_tree_still_finds_its_tag(tmp_path):
    """The texture is named relative to the calibration's directory: the tree holding both
    (a clone, a copy) can move, and the scene the description builds still compiles with the
    tag — MuJoCo's compiler is the judge."""
    import shutil
    from types import SimpleNamespace

    import mujoco

    from cdpr_twin.calibrate.output import calibrated_description
    from cdpr_twin.sim import nominal_robot
    from cdpr_twin.sim.mjcf_from_robot import build_files

    shutil.copytree(MODELS_DIR / "acrobot", tmp_path / "a" / "models" / "acrobot")
    source, out = tmp_path / "a" / "models" / "acrobot" / "robot.toml", tmp_path / "a" / "cal"
    g = nominal_robot("acrobot").geometry
    model = SimpleNamespace(
        a_base=g.a_base,
        b_platform=g.b_platform,
        scale=np.zeros(8),
        T_platform_cam=g.T_platform_cam,
        T_base_tag=np.eye(4),
    )
    out.mkdir()
    text = calibrated_description(source, SimpleNamespace(model=model), np.full(8, 0.02), out)
    (out / "calibrated_robot.toml").write_text(text)
    assert not Path(tomllib.loads(text)["tag"]["texture"]).is_absolute()
    if Path(os.path.commonpath([MODELS_DIR.resolve(), tmp_path.resolve()])) == Path("/"):
        apart = calibrated_description(  # sharing only the root: the absolute path, which holds
            MODELS_DIR / "acrobot" / "robot.toml",
            SimpleNamespace(model=model),
            np.full(8, 0.02),
            tmp_path,
        )
        texture = Path(tomllib.loads(apart)["tag"]["texture"])
        assert texture.is_absolute() and texture.is_file()
    (tmp_path / "a").rename(tmp_path / "b")
    _, scene = build_files(tmp_path / "b" / "cal" / "calibrated_robot.toml")
    model = mujoco.MjModel.from_xml_path(str(scene))
    tag = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_TEXTURE, "tag36h11_00000")
    assert tag >= 0 and model.tex_width[tag] * model.tex_height[tag] > 0


def test_the_written_description_reads_back_whatever_its_text_holds():
    """Every string a description may hold (TOML allows any escaped) reads back as written.

    Before: DEL (U+007F) went out raw, which TOML forbids: the calibrated description of a
    source whose ``description`` held "\\u007f" could not be read back."""
    import tomllib

    text = "".join(map(chr, range(0x20))) + '\x7f quoted " back\\slash ünïcode ✓ \U0001f600'
    data = {"description": text, "frame": {"name": text, "size_m": [1.0, float("inf")]}}
    assert tomllib.loads(toml_text(data, header="a header\nof two lines")) == data
