"""Drum radii a calibration estimated, used by the software: a robot description's
``[winches] drum_radius_scale`` sets the drives and encoders (``Physics.set_drum_radii``), so
the cable paid out is the cable commanded. Checked end to end on the paper's open loop: a robot
whose only error is its drums' radii misses p1 by millimetres with the nominal model, and by the
model's own residual once its description carries the true radii."""

import tomllib
from pathlib import Path

import numpy as np

from cdpr_twin import MODELS_DIR
from cdpr_twin.calibrate.output import toml_text
from cdpr_twin.campaign.spec import set_dotted
from cdpr_twin.runner import prepare, run
from cdpr_twin.scenario import scenario_from_data

ROOT = Path(__file__).resolve().parent.parent
SOURCE = ROOT / "scenarios" / "paper_open_loop.toml"
DRUMS_ONLY = {  # the robot exactly as modelled but its drums (1 % per drum), ideal otherwise
    "realism.profile": "ideal",
    "realism.winch.drum_radius_error_std": 0.01,
    "truth.exit_point_std": 0.0,
    "truth.anchor_point_std": 0.0,
    "truth.es_scale_std": 0.0,
    "truth.pulley_radius_std": 0.0,
    "truth.camera_position_std": 0.0,
    "truth.camera_rotation_std_deg": 0.0,
    "sensors.tension_noise_std": 0.0,
    "sensors.camera": False,
    "duration": 10.0,  # p0 → p1
}


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
