"""Pose-based visual servoing of the platform camera (paper §II, §IV-C, eq. 1-8)."""

from __future__ import annotations

import numpy as np

from cdpr_twin.controllers.base import Command, Controller
from cdpr_twin.estimators.base import PoseEstimate
from cdpr_twin.geometry import CdprGeometry
from cdpr_twin.kinematics import CableModel, jacobian
from cdpr_twin.measurement import Measurement
from cdpr_twin.se3 import adjoint, inverse, skew, so3_log


def interaction_matrix(t_cam_tag: np.ndarray, theta_u: np.ndarray) -> np.ndarray:
    """L_s of s = (ᶜt_o, θu), with θu that of ᶜ*R_c (Chaumette & Hutchinson 2006, §IV).

    ṡ = L_s ᶜv_c for the camera twist ᶜv_c = [v, ω] in F_c (ViSP's ``vpFeatureThetaU`` for
    ᶜ*R_c: L_θu = I + θ/2 [u]× + (1 − sinc θ / sinc²(θ/2)) [u]×²). θu is an eigenvector of L_θu
    with eigenvalue 1, so the commanded ω = −λ θu either way.

    Args:
        t_cam_tag: (3,) current tag position in the camera frame [m].
        theta_u: (3,) rotation vector of ᶜ*R_c [rad].

    Returns:
        (6, 6) interaction matrix.
    """
    theta = float(np.linalg.norm(theta_u))
    L = np.zeros((6, 6))
    L[:3, :3] = -np.eye(3)
    L[:3, 3:] = skew(t_cam_tag)
    if theta < 1e-12:
        L[3:, 3:] = np.eye(3)
        return L
    u = skew(theta_u / theta)
    coeff = 1.0 - np.sinc(theta / np.pi) / np.sinc(theta / (2 * np.pi)) ** 2
    L[3:, 3:] = np.eye(3) + 0.5 * theta * u + coeff * (u @ u)  # L_θu of ᶜ*R_c
    return L


class PbvsController(Controller):
    """ᶜv_c = −λ L̂⁺ e (eq. 2), ᵖv_p = Â_d ᶜv_c (eq. 3-4), l̇ = Â ᵖv_p (eq. 5-6).

    Â is evaluated at the in-loop estimator's pose estimate: the only place the estimate
    enters (eq. 8). The feature is measured from the current tag detection.

    Args:
        geometry: nominal geometry (its ``T_platform_cam`` is Â_d's ᵖT_c).
        goal_T_cam_tag: (4, 4) desired tag pose in the camera frame, pupil-apriltags tag frame.
        gain: λ [1/s].
        max_linear_speed: camera translation speed cap [m/s]; the twist is scaled down
            uniformly (direction kept) when exceeded.
        max_angular_speed: camera rotation speed cap [rad/s].
        converged_translation: ‖ᶜt_o − ᶜ*t_o‖ below which translation has converged [m].
        converged_rotation: θ below which rotation has converged [rad].
        jacobian_model: cable model of Â (``"straight"``: eq. 6, as in the paper).
    """

    name = "pbvs"

    def __init__(
        self,
        geometry: CdprGeometry,
        goal_T_cam_tag: np.ndarray,
        gain: float = 0.5,
        max_linear_speed: float = 0.03,
        max_angular_speed: float = np.deg2rad(10.0),
        converged_translation: float = 5e-4,
        converged_rotation: float = np.deg2rad(0.1),
        jacobian_model: CableModel = "straight",
    ) -> None:
        super().__init__(geometry)
        goal = np.asarray(goal_T_cam_tag, dtype=float)
        if goal.shape != (4, 4) or not np.all(np.isfinite(goal)) or goal[2, 3] <= 0:
            raise ValueError(
                "pbvs: goal_T_cam_tag must be a finite 4×4 pose in front of the camera (z > 0)"
            )
        for name, value in (
            ("gain", gain),
            ("max_linear_speed", max_linear_speed),
            ("max_angular_speed", max_angular_speed),
            ("converged_translation", converged_translation),
            ("converged_rotation", converged_rotation),
        ):
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"pbvs: {name} must be > 0, got {value}")
        self.goal = goal
        self.gain = float(gain)
        self.max_linear_speed = float(max_linear_speed)
        self.max_angular_speed = float(max_angular_speed)
        self.converged_translation = float(converged_translation)
        self.converged_rotation = float(converged_rotation)
        self.jacobian_model = jacobian_model
        self._Ad = adjoint(geometry.T_platform_cam)

    def reset(self, T_base_platform0: np.ndarray) -> None:
        """Nothing to plan: PBVS reacts to each detection."""

    def platform_goal(self, T_base_tag: np.ndarray) -> np.ndarray:
        """The platform pose at which the camera sees a tag at ``T_base_tag`` as the goal.

        ᵇT_p* = ᵇT_o · (ᶜ*T_o)⁻¹ · (ᵖT_c)⁻¹, with this controller's (nominal) camera mounting.
        """
        return T_base_tag @ inverse(self.goal) @ inverse(self.geometry.T_platform_cam)

    def error(self, T_cam_tag: np.ndarray) -> np.ndarray:
        """E = s − s* = (ᶜt_o − ᶜ*t_o, θu of ᶜ*R_c). Returns (6,) [m, rad]."""
        R_goal_cur = self.goal[:3, :3] @ T_cam_tag[:3, :3].T  # ᶜ*R_c = ᶜ*R_o ᶜR_oᵀ
        return np.concatenate([T_cam_tag[:3, 3] - self.goal[:3, 3], so3_log(R_goal_cur)])

    def command(
        self, t: float, period: float, estimate: PoseEstimate, measurement: Measurement
    ) -> Command:
        """One PBVS step; zero velocity while the tag is not detected."""
        zero8, zero6 = np.zeros(self.geometry.n_cables), np.zeros(6)
        if measurement.tag is None:
            return Command(zero8, zero6, status="tag_lost")
        T_co = measurement.tag.T_cam_tag
        e = self.error(T_co)
        if (
            np.linalg.norm(e[:3]) < self.converged_translation
            and np.linalg.norm(e[3:]) < self.converged_rotation
        ):
            return Command(zero8, zero6, done=True, status="converged", error=e)
        v_cam = -self.gain * np.linalg.pinv(interaction_matrix(T_co[:3, 3], e[3:])) @ e
        scale = max(
            1.0,
            np.linalg.norm(v_cam[:3]) / self.max_linear_speed,
            np.linalg.norm(v_cam[3:]) / self.max_angular_speed,
        )
        v_cam = v_cam / scale
        twist_platform = self._Ad @ v_cam  # eq. 3-4
        A = jacobian(self.geometry, estimate.T_base_platform, "platform", self.jacobian_model)
        status = "saturated" if scale > 1.0 else "servoing"
        return Command(A @ twist_platform, twist_platform, status=status, error=e)
