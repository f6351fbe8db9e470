"""Cables with mass in the physics (cdpr_twin/sim/sag.py): Irvine's catenary on every free span.

Truth: the massless twin (the same model, the same rest lengths): sagging cables must move the
settled platform by what the issue expects on ACROBOT (< 10 µm: 2.4 g/m Dyneema, ≈ 0.9 mm sag)
and measurably more on CoGiRo (0.064 kg/m steel over ≈ 10 m). The catenary element itself is
checked against a discretised MuJoCo cable in tests/test_catenary.py.
"""

import numpy as np
import pytest
from conftest import PAPER_POSES

from cdpr_twin import DEFAULT_SCENE, MODELS_DIR, se3
from cdpr_twin.sim import Physics, build_model, build_robot
from cdpr_twin.sim.generate import build_files
from cdpr_twin.sim.sag import SaggingPhysics


def _settled_change(scene, pose, rho, settle=1.0, hold=1.0):
    plain = Physics(build_model(scene), 40)
    heavy = SaggingPhysics(build_model(scene), 40, linear_density=rho)
    T = se3.pose_from_vector(pose)
    for p in (plain, heavy):
        p.reset(T, settle_time=settle)
        p.advance(hold, np.zeros(p.n_cables))
    np.testing.assert_array_equal(plain.rest_lengths, heavy.rest_lengths)
    assert np.abs(heavy.data.qvel).max() < 1e-3  # at rest
    return se3.pose_distance(plain.T_base_platform, heavy.T_base_platform)[0], heavy


@pytest.mark.parametrize("name", ["p0", "p1", "p2"])
def test_sag_moves_acrobots_settled_pose_by_less_than_10_um(name):
    dt, heavy = _settled_change(DEFAULT_SCENE, PAPER_POSES[name], 0.0024)
    assert 1e-7 < dt < 1e-5  # measured 0.95, 8.3, 6.2 µm at p0, p1, p2
    # the heavier cable needs more stretch to sag between the same points: it pulls harder
    assert np.all(heavy.sag_force @ np.array([0.0, 0.0, 1.0]) > -0.01)


def test_sag_on_cogiro_moves_the_settled_pose_by_a_fraction_of_a_millimetre():
    dt, _ = _settled_change(MODELS_DIR / "cogiro" / "scene.xml", [2.0, -1.5, 1.0, 0, 0, 0], 0.064)
    assert 1e-4 < dt < 2e-3  # measured 0.45 mm (tensions 160–480 N)


def test_a_description_with_sag_builds_sagging_physics(tmp_path):
    text = (MODELS_DIR / "cogiro" / "robot.toml").read_text()
    assert "linear_density_kg_m = 0.064" in text
    path = tmp_path / "robot.toml"
    text = text.replace("linear_density_kg_m = 0.064", "linear_density_kg_m = 0.064\nsag = true")
    texture = MODELS_DIR / "acrobot" / "assets" / "tag36h11_00000.png"  # from anywhere
    path.write_text(text.replace('"../acrobot/assets/tag36h11_00000.png"', f'"{texture}"'))
    _, scene = build_files(path, tmp_path)
    physics, _, _ = build_robot(scene)
    assert isinstance(physics, SaggingPhysics) and physics.linear_density == 0.064
    physics_plain, _, _ = build_robot(MODELS_DIR / "cogiro" / "scene.xml")
    assert type(physics_plain) is Physics
