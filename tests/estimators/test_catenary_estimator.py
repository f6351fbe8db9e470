"""``model_catenary`` (eq. 25 with the sagging cable's length–tension relation) on heavy cables.

Truth: the twin with sagging cables (SaggingPhysics: MuJoCo tendons plus Irvine's catenary on
each span, tests/sim/test_sag.py, tests/math/test_catenary.py) on CoGiRo's 0.064 kg/m steel
cables, the encoders reading the true rest lengths (no homing, which would calibrate them with
one model). The straight elastic relation of model_elastic_pulley then misses the sag; the
catenary one not.
"""

import numpy as np
import pytest

from cdpr_twin import MODELS_DIR
from cdpr_twin.math import se3
from cdpr_twin.plugins import make_estimator
from cdpr_twin.sim import Twin
from cdpr_twin.sim.mjcf_from_robot import build_files


@pytest.fixture(scope="module", params=["pulley", "anchor"])
def heavy_cogiro(request, tmp_path_factory):
    """CoGiRo (sag on), its tension sensors at the pulleys (as described) or at the anchors."""
    out = tmp_path_factory.mktemp("heavy_cogiro")
    text = (MODELS_DIR / "cogiro" / "robot.toml").read_text()
    text = text.replace('location = "pulley"', f'location = "{request.param}"')
    texture = MODELS_DIR / "acrobot" / "assets" / "tag36h11_00000.png"
    (out / "robot.toml").write_text(
        text.replace('"../acrobot/assets/tag36h11_00000.png"', f'"{texture}"')
    )
    return build_files(out / "robot.toml", out)[1]


@pytest.mark.parametrize("pose", [[0, 0, 2, 0, 0, 0], [2, -1.5, 1, 0, 0, 0], [-3, 2, 3, 5, -5, 10]])
def test_the_catenary_model_finds_the_pose_the_straight_elastic_one_misses(heavy_cogiro, pose):
    with Twin(heavy_cogiro, camera=False, tension_noise_std=0.0, home_encoders=False) as twin:
        assert twin.nominal.geometry.linear_density == 0.064
        T = se3.pose_from_vector(pose)
        twin.reset(T, settle_time=1.0)
        twin.advance(1.0, np.zeros(8))
        m, truth = twin.sense(), twin.physics.T_base_platform
    errors = {}
    for name in ("model_elastic_pulley", "model_catenary"):
        estimator = make_estimator(name, twin.nominal.geometry)
        estimator.reset(T)
        for _ in range(3):  # the sag correction uses the last estimate's spans
            estimate = estimator.update(m)
        assert estimate.valid
        errors[name] = se3.pose_distance(estimate.T_base_platform, truth)[0]
    # measured: elastic + pulley 0.22, 0.48, 0.26 mm; catenary 2.1, 6.5, 2.1 µm
    assert errors["model_elastic_pulley"] > 1e-4
    assert errors["model_catenary"] < 2e-5
    assert errors["model_catenary"] < errors["model_elastic_pulley"] / 20
