"""Pose-based visual servoing of the platform camera (paper §II, §IV-C, eq. 1-8)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from cdpr_twin.controllers.base import Controller, RunEnd
from cdpr_twin.math.geometry import CdprGeometry
from cdpr_twin.math.kinematics import jacobian
from cdpr_twin.math.se3 import (
    adjoint,
    check_rigid,
    inverse,
    pose_distance,
    pose_error,
    pose_from_vector,
    skew,
    so3_log,
    vector_from_pose,
)
from cdpr_twin.options import OptionError, OptionSpec, option
from cdpr_twin.types import T_TAGPUPIL_TAGVISP, Command, Measurement, PoseEstimate, Status


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


_TEN_DEGREES = math.radians(10.0)
_TENTH_DEGREE = math.radians(0.1)


def _visp_goal(T_cam_tagvisp: np.ndarray) -> np.ndarray:
    """The paper's goal ᶜp_o (ViSP tag frame) as a pose of pupil-apriltags' tag frame."""
    goal = T_cam_tagvisp @ T_TAGPUPIL_TAGVISP
    goal.flags.writeable = False
    return goal


P1 = (0.284, -0.197, 0.08, 0.0, 0.0, 0.0)
"""The paper's p1 ``[x, y, z, rx, ry, rz]`` (m, deg): where the nominal goal view is seen."""


def _p1() -> np.ndarray:
    out = pose_from_vector(P1)
    out.flags.writeable = False
    return out


@dataclass(frozen=True)
class PbvsOptions:
    """The PBVS task and gains.

    Attributes:
        goal_T_cam_tag: (4, 4) desired tag pose in the camera frame, pupil-apriltags tag frame
            (file: ``goal_tag_pose_visp = [x, y, z, rx, ry, rz]``, m and degrees, ViSP's tag
            frame as in the paper).
        gain: λ [1/s].
        max_linear_speed: camera translation speed cap [m/s]; the twist is scaled down
            uniformly (direction kept) when exceeded.
        max_angular_speed: camera rotation speed cap [rad/s] (file: deg/s).
        converged_translation: ‖ᶜt_o − ᶜ*t_o‖ below which translation has converged [m].
        converged_rotation: θ below which rotation has converged [rad] (file: deg).
        jacobian_model: cable model of Â (``"straight"``: eq. 6, as in the paper).
        goal: where the desired feature s* comes from. ``"nominal"``: ``goal_T_cam_tag``, the
            view the nominal model predicts at the goal pose. ``"taught"``: teach-by-showing,
            the usual visual-servoing practice — before the run the true robot is placed at
            ``teach_pose`` (as experimenters do with their tracker), the camera measures the
            tag there (a real detection: noise, calibration errors and all), and that
            measured ᶜT_o is s* (``goal_T_cam_tag`` is then only reported beside it).
        teach_pose: (4, 4) true platform pose shown with ``goal = "taught"`` (file:
            ``[x, y, z, rx, ry, rz]``, m and degrees; default the paper's p1); it is the
            run's reported goal pose.
    """

    goal_T_cam_tag: np.ndarray = option(  # noqa: RUF009  (a field, required: no default)
        key="goal_tag_pose_visp", pose=True, convert=_visp_goal
    )
    gain: float = option(0.5, minimum=0.0, exclusive=True, unit="1/s")
    max_linear_speed: float = option(0.03, minimum=0.0, exclusive=True, unit="m/s")
    max_angular_speed: float = option(_TEN_DEGREES, minimum=0.0, exclusive=True, unit="deg")
    converged_translation: float = option(5e-4, minimum=0.0, exclusive=True, unit="m")
    converged_rotation: float = option(_TENTH_DEGREE, minimum=0.0, exclusive=True, unit="deg")
    jacobian_model: Literal["straight", "pulley"] = option("straight")
    goal: Literal["nominal", "taught"] = option("nominal")
    teach_pose: np.ndarray = dataclasses.field(
        default_factory=_p1, metadata={"option": OptionSpec(pose=True)}
    )

    def __post_init__(self) -> None:
        goal = np.asarray(self.goal_T_cam_tag, dtype=float)
        if goal.shape != (4, 4) or not np.all(np.isfinite(goal)) or goal[2, 3] <= 0:
            raise OptionError(
                "goal_T_cam_tag", "must be a finite 4×4 pose in front of the camera (z > 0)"
            )
        for name in (
            "gain",
            "max_linear_speed",
            "max_angular_speed",
            "converged_translation",
            "converged_rotation",
        ):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise OptionError(name, f"must be > 0, got {value}")
        if self.jacobian_model not in ("straight", "pulley"):
            raise OptionError(
                "jacobian_model", f"must be 'straight' or 'pulley', got {self.jacobian_model!r}"
            )
        if self.goal not in ("nominal", "taught"):
            raise OptionError("goal", f"must be 'nominal' or 'taught', got {self.goal!r}")
        try:
            check_rigid(np.asarray(self.teach_pose, dtype=float), "teach_pose")
        except ValueError as exc:
            raise OptionError("teach_pose", str(exc)) from None


class PbvsController(Controller):
    """ᶜv_c = −λ L̂⁺ e (eq. 2), ᵖv_p = Â_d ᶜv_c (eq. 3-4), l̇ = Â ᵖv_p (eq. 5-6).

    Â is evaluated at the in-loop estimator's pose estimate: the only place the estimate
    enters (eq. 8). The feature is measured from the current tag detection. With ``goal =
    "taught"`` the desired feature s* is the detection made when the robot is shown
    ``teach_pose`` (:meth:`teach`).

    Args:
        geometry: nominal geometry (its ``T_platform_cam`` is Â_d's ᵖT_c).
        options: :class:`PbvsOptions`.
    """

    name = "pbvs"
    Options = PbvsOptions
    needs_camera = True
    timeout_status = Status.TIME_LIMIT

    def __init__(self, geometry: CdprGeometry, options: PbvsOptions) -> None:
        super().__init__(geometry, options)
        o = options
        self.goal = np.asarray(o.goal_T_cam_tag, dtype=float)
        self.gain = float(o.gain)
        self.max_linear_speed = float(o.max_linear_speed)
        self.max_angular_speed = float(o.max_angular_speed)
        self.converged_translation = float(o.converged_translation)
        self.converged_rotation = float(o.converged_rotation)
        self.jacobian_model = o.jacobian_model
        self._Ad = adjoint(geometry.T_platform_cam)
        self._counts = {Status.TAG_LOST: 0, Status.SATURATED: 0}
        self.taught = False

    def teach(self, show: Callable[[np.ndarray], Measurement]) -> None:
        """With ``goal = "taught"``: s* := the tag pose the camera measures at ``teach_pose``.

        Args:
            show: places the true robot at a pose and returns the sensors' measurement there.

        Raises:
            OptionError: ``teach_pose``, when the camera does not detect the tag there.
        """
        if self.options.goal != "taught":
            return
        m = show(np.asarray(self.options.teach_pose, dtype=float))
        if m.tag is None:
            raise OptionError("teach_pose", "the camera does not see the tag at this pose")
        self.goal = np.array(m.tag.T_cam_tag, dtype=float)
        self.goal.flags.writeable = False
        self.taught = True

    def reset(self, T_base_platform0: np.ndarray) -> None:
        """Nothing to plan: PBVS reacts to each detection (the tick counts restart)."""
        self._counts = {Status.TAG_LOST: 0, Status.SATURATED: 0}

    def platform_goal(self, T_base_tag: np.ndarray) -> np.ndarray:
        """The platform pose at which the camera sees a tag at ``T_base_tag`` as the goal.

        ᵇT_p* = ᵇT_o · (ᶜ*T_o)⁻¹ · (ᵖT_c)⁻¹, with this controller's (nominal) camera mounting.
        """
        return T_base_tag @ inverse(self.goal) @ inverse(self.geometry.T_platform_cam)

    def error(self, T_cam_tag: np.ndarray) -> np.ndarray:
        """E = s − s* = (ᶜt_o − ᶜ*t_o, θu of ᶜ*R_c). Returns (6,) [m, rad]."""
        R_goal_cur = self.goal[:3, :3] @ T_cam_tag[:3, :3].T  # ᶜ*R_c = ᶜ*R_o ᶜR_oᵀ
        return np.concatenate([T_cam_tag[:3, 3] - self.goal[:3, 3], so3_log(R_goal_cur)])

    @property
    def goal_is_taught(self) -> bool:
        """With ``goal = "taught"``: the goal is the view shown at ``teach_pose``."""
        return self.options.goal == "taught"

    def goal_pose(self, T_base_tag: np.ndarray | None) -> np.ndarray | None:
        """The task's end pose.

        ``teach_pose`` when taught; else where the nominal robot sees the goal view (``None``
        without a tag pose).
        """
        if self.options.goal == "taught":
            return np.array(self.options.teach_pose, dtype=float)
        return None if T_base_tag is None else self.platform_goal(T_base_tag)

    @property
    def goal_view(self) -> np.ndarray:
        """The desired tag pose in the camera frame (pupil tag frame)."""
        return self.goal

    def summary(self, end: RunEnd) -> dict[str, Any]:
        """``pbvs``: convergence, detected and true final tag errors, tag-lost/saturated ticks.

        A taught goal adds ``goal``, the taught view ``taught_tag_pose_visp`` (ViSP tag frame,
        m and degrees, like ``goal_tag_pose_visp``) and its distance to the file's view.
        """
        tag_err = None
        if end.last_tag is not None:
            dt, dr = pose_distance(end.last_tag.T_cam_tag, self.goal)
            tag_err = {
                "translation_m": dt,
                "rotation_deg": float(np.degrees(dr)),
                "detected_at_s": end.last_tag_time,
            }
        out: dict[str, Any] = {
            "converged": end.status == Status.CONVERGED,
            "final_tag_error": tag_err,
            "true_final_tag_error": end.true_tag_error,
            "tag_lost_ticks": self._counts[Status.TAG_LOST],
            "saturated_ticks": self._counts[Status.SATURATED],
        }
        if self.taught:  # nominal runs keep the summary they always had
            file_goal = np.asarray(self.options.goal_T_cam_tag, dtype=float)
            out["goal"] = "taught"
            out["taught_tag_pose_visp"] = vector_from_pose(self.goal @ T_TAGPUPIL_TAGVISP).tolist()
            out["taught_vs_file_goal"] = pose_error(self.goal, file_goal)
        return {"pbvs": out}

    def peak_cable_rate(self) -> float:
        """The fastest cable rate the speed caps allow [m/s], whatever the gain and the pose.

        A cable's rate is u·v_p + (b_i × u)·ω with |u| = 1 (eq. 6, straight or pulley), and the
        platform's v_p = R v_c + t_pc × R ω_c: so |l̇_i| ≤ v_max + (|t_pc| + max |b_i|)·ω_max.
        """
        g = self.geometry
        reach = float(np.linalg.norm(g.T_platform_cam[:3, 3]))
        reach += float(np.linalg.norm(g.b_platform, axis=1).max())
        return self.max_linear_speed + reach * self.max_angular_speed

    def command(
        self, t: float, period: float, estimate: PoseEstimate, measurement: Measurement
    ) -> Command:
        """One PBVS step; zero velocity while the tag is not detected."""
        cmd = self._command(estimate, measurement)
        if cmd.status in self._counts:
            self._counts[cmd.status] += 1
        return cmd

    def _command(self, estimate: PoseEstimate, measurement: Measurement) -> Command:
        zero_m, zero6 = np.zeros(self.geometry.n_cables), np.zeros(6)
        if measurement.tag is None:
            return Command(zero_m, zero6, status=Status.TAG_LOST)
        T_co = measurement.tag.T_cam_tag
        e = self.error(T_co)
        if (
            np.linalg.norm(e[:3]) < self.converged_translation
            and np.linalg.norm(e[3:]) < self.converged_rotation
        ):
            return Command(zero_m, zero6, done=True, status=Status.CONVERGED, error=e)
        v_cam = -self.gain * np.linalg.pinv(interaction_matrix(T_co[:3, 3], e[3:])) @ e
        scale = max(
            1.0,
            float(np.linalg.norm(v_cam[:3])) / self.max_linear_speed,
            float(np.linalg.norm(v_cam[3:])) / self.max_angular_speed,
        )
        v_cam = v_cam / scale
        twist_platform = self._Ad @ v_cam  # eq. 3-4
        A = jacobian(self.geometry, estimate.T_base_platform, "platform", self.jacobian_model)
        status = Status.SATURATED if scale > 1.0 else Status.SERVOING
        return Command(A @ twist_platform, twist_platform, status=status, error=e)
