"""PBVS pieces against independent truths: finite differences of the feature, and the camera
motion that the commanded platform twist produces, with an asymmetric camera mounting."""

import numpy as np
from conftest import A_BASE, B_PLATFORM
from hypothesis import given, settings
from hypothesis import strategies as st

from cdpr_twin.controllers.pbvs import interaction_matrix
from cdpr_twin.estimators.base import PoseEstimate
from cdpr_twin.math import se3
from cdpr_twin.math.geometry import CdprGeometry
from cdpr_twin.math.kinematics import jacobian
from cdpr_twin.plugins import make_controller
from cdpr_twin.types import Measurement
from cdpr_twin.vision.detection import TagDetection

# A camera mounting that is not its own inverse (the nominal one, diag(−1, 1, −1), is).
T_PLATFORM_CAM = se3.transform(se3.so3_exp([0.3, -0.2, 2.9]), [0.02, -0.01, -0.04])


def _geometry():
    return CdprGeometry(
        np.array(A_BASE),
        np.array(B_PLATFORM),
        0.0045,
        3.5e5,
        3.5,
        np.zeros(3),
        T_platform_cam=T_PLATFORM_CAM,
    )


def _pose(seed):
    rng = np.random.default_rng(seed)
    return se3.transform(
        se3.so3_exp(rng.normal(0, 0.4, 3)), rng.normal(0, 0.03, 3) + np.array([0.0, 0.0, 0.2])
    )


@settings(max_examples=50, deadline=None)
@given(seed=st.integers(0, 10**6))
def test_interaction_matrix_matches_finite_differences(seed):
    """ṡ = L_s ᶜv_c, with s(ᶜT_o) = (ᶜt_o, θu of ᶜ*R_c) and the camera moving by exp(ξh)."""
    goal, T_co = _pose(seed), _pose(seed + 1)
    ctrl = make_controller("pbvs", _geometry(), goal_T_cam_tag=goal)
    L = interaction_matrix(T_co[:3, 3], ctrl.error(T_co)[3:])
    h = 1e-6
    fd = np.zeros((6, 6))
    for k in range(6):
        xi = np.zeros(6)
        xi[k] = h
        # the camera moves by exp(ξ) in its own frame: ᶜT_o ← exp(ξ)⁻¹ ᶜT_o
        plus = ctrl.error(se3.se3_exp(-xi) @ T_co)
        minus = ctrl.error(se3.se3_exp(xi) @ T_co)
        fd[:, k] = (plus - minus) / (2 * h)
    np.testing.assert_allclose(L, fd, atol=2e-6)


def test_commanded_platform_twist_moves_the_camera_as_pbvs_asked():
    """Eq. 3-4 with an asymmetric mounting: the platform twist, applied to the platform, moves
    the camera by the camera twist of eq. 2, and the error decays at rate λ."""
    geom = _geometry()
    goal = se3.transform(se3.rot_z(np.pi) @ se3.rot_x(np.pi), [0, 0, 0.09])
    ctrl = make_controller(
        "pbvs", geom, goal_T_cam_tag=goal, gain=0.5, max_linear_speed=10, max_angular_speed=10
    )
    T_bp = se3.transform(se3.so3_exp([0.05, -0.03, 0.2]), [0.2, -0.1, 0.25])
    T_base_tag = (
        T_bp @ T_PLATFORM_CAM @ se3.transform(se3.so3_exp([0.1, 0.05, -0.2]), [0.02, -0.01, 0.15])
    )
    dt = 1e-4
    errors = []
    for k in range(2):
        T_co = se3.inverse(T_bp @ T_PLATFORM_CAM) @ T_base_tag
        tag = TagDetection(0, np.zeros((4, 2)), T_co, 100.0, 0.0)
        m = Measurement(k * dt, np.ones(8), np.ones(8), tag=tag)
        cmd = ctrl.command(k * dt, dt, PoseEstimate(0.0, T_bp), m)
        errors.append(cmd.error)
        # the rates realise the platform twist (l̇ = A ᵖv_p, eq. 5)
        A = jacobian(geom, T_bp, "platform", "straight")
        np.testing.assert_allclose(cmd.cable_rates, A @ cmd.twist_platform, atol=1e-15)
        T_bp = T_bp @ se3.se3_exp(cmd.twist_platform * dt)
    # ė = −λ e (eq. 1): one small step of the closed loop shrinks e by exp(−λ dt)
    np.testing.assert_allclose(errors[1], errors[0] * np.exp(-0.5 * dt), atol=1e-9)


def test_platform_goal_puts_the_camera_on_the_goal():
    ctrl = make_controller("pbvs", _geometry(), goal_T_cam_tag=_pose(7))
    T_base_tag = se3.transform(se3.so3_exp([0.2, -0.1, 0.4]), [0.3, -0.2, -0.04])
    T_goal = ctrl.platform_goal(T_base_tag)
    seen = se3.inverse(T_goal @ T_PLATFORM_CAM) @ T_base_tag
    np.testing.assert_allclose(seen, _pose(7), atol=1e-12)
    np.testing.assert_allclose(ctrl.error(seen), 0.0, atol=1e-12)
