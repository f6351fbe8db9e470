"""Est. 7, ``fused``: an error-state Kalman filter on SE(3) over every sensor.

Prediction: the control-based model, ``T ← T · exp(ξ Δt)`` with ξ the commanded platform twist
(eq. 9), and process noise from the winch model — a velocity loop of time constant τ_w lags
each change of the command, leaving ≈ τ_w |Δξ| of unmodelled motion, plus a random-walk floor.
Updates (models and error state: :mod:`cdpr_twin.estimators.fused_models`):

- cable lengths — every taut cable (measured tension above ``taut_threshold`` and not clipped),
  elastic and pulley model, relative to the reading at reset (the encoders are homed there, so
  they measure motion; the start pose's own error, the homing repeatability, is a state); the
  drums' radius errors are states too; cables near slack are trusted less, and each cable's
  innovation is gated (Mahalanobis, ``gate_probability``) so a sagging cable cannot pull;
- tag detections — the first one anchors the tag in F_b (a state, correlated with the pose), the
  later ones update pose and tag; the detection's covariance follows the corners' pixel noise
  through the projection (it grows with distance); a detection failing the gate is rejected.

Tag lost, slack cables, rejected readings: the filter predicts and says so in ``flags``; its
covariance (the pose block, ``PoseEstimate.covariance``) grows accordingly.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from cdpr_twin.estimators import fused_core as fc
from cdpr_twin.estimators import fused_models as fm
from cdpr_twin.estimators.base import NON_FINITE_INPUT, TAG_LOST, Estimator
from cdpr_twin.estimators.solvers import _cable_tuples
from cdpr_twin.math.geometry import CdprGeometry
from cdpr_twin.options import OptionError, option
from cdpr_twin.types import Measurement, PoseEstimate

SLACK_CABLES = "slack_cables"
"""Some cables read below the taut threshold (or clipped): their lengths were not used."""
CABLE_OUTLIER = "cable_outlier"
"""A cable's innovation failed the Mahalanobis gate: its length was not used."""
TAG_OUTLIER = "tag_outlier"
"""The tag detection failed the Mahalanobis gate: it was not used."""
PREDICTED = "predicted_only"
"""No measurement was used this tick: the estimate is the prediction."""


@dataclass(frozen=True)
class FusedOptions:
    """Options of the fused filter; defaults: the ``acrobot`` profile's magnitudes.

    Attributes:
        initial_position_std: per-axis std of the start position (homing) [m].
        initial_rotation_std: per-axis std of the start orientation [rad] (file: ``_deg``).
        drum_scale_std: relative std of each drum's radius.
        process_position_std: random-walk std of the position [m/√s].
        process_rotation_std: random-walk std of the orientation [rad/√s] (file: ``_deg``).
        winch_time_constant: τ_w of the winches' velocity loop [s].
        encoder_quantum: length of one encoder count [m] (0: exact encoders).
        length_noise_std: a floor under each reading's noise std [m].
        tension_noise_std: random error of a tension reading [N].
        damping_time: the cables' damping time η [s].
        taut_threshold: the length updates use the cables reading above this tension [N].
        hang_threshold: the prediction takes the platform to hang on the cables reading above
            this [N] (≤ ``taut_threshold``): what a slack cable of the acrobot profile can read
            (0.24 N accuracy + 3 × 0.01 N noise); a noisier sensor needs a higher one.
        pixel_std: std of a detected corner [px].
        focal_px: the camera's focal length [px].
        tag_size: edge of the tag's black square [m].
        tag_latency: age of a detection when it arrives [s] (latency + half the exposure).
        gate_probability: Mahalanobis gate (χ² quantile) for each cable and each detection.
        use_tag: fuse tag detections.
        drum_consider: treat the drum scale errors as consider states (Schmidt): accounted
            for, never estimated. Estimated from the redundant cables, they would learn the
            encoders' quantisation (a floor) as drum errors: the filter grew overconfident.
        exit_point_std: per-axis std of the exit points' calibration error [m]; with this or
            ``anchor_point_std`` above 0 the filter considers both (6m consider states).
        anchor_point_std: per-axis std of the anchor points' calibration error [m].
        camera_position_std: per-axis std of the camera mount's position error [m]; with this
            or ``camera_rotation_std`` above 0 the mount is considered (6 states).
        camera_rotation_std: per-axis std of the camera mount's rotation error [rad].
        focal_error_std: relative std of the calibrated fx, fy; with this, the centre's or a
            distortion coefficient's std above 0 the calibration error is considered (8
            states): a detection's error from it repeats at every frame of one view.
        center_error_std_px: std of the calibrated cx, cy [px].
        distortion_error_std: std of each calibrated (k1, k2, p1, p2).
        lens: the calibrated lens (k1, k2, p1, p2), through which those errors act.
        max_condition: the prediction maps the drums' errors into the pose through the
            Jacobian A of the cables holding the platform (A⁺ ρ⊙l̇ dt) only while A's condition
            number is below this (as the model-based estimators'): a nearly singular set (at a
            servo's start, ≈ 3·10⁴) turns a drum's 0.5 % into 13 mm of std in 40 ms (0.3 mm).
    """

    initial_position_std: float = option(0.001, minimum=0.0, unit="m")
    initial_rotation_std: float = option(math.radians(0.2), minimum=0.0, unit="deg")
    drum_scale_std: float = option(0.005, minimum=0.0)
    process_position_std: float = option(1e-3, minimum=0.0, exclusive=True, unit="m")
    process_rotation_std: float = option(
        math.radians(0.05), minimum=0.0, exclusive=True, unit="deg"
    )
    winch_time_constant: float = option(1.0 / (2.0 * math.pi * 20.0), minimum=0.0, unit="s")
    encoder_quantum: float = option(2.0 * math.pi * 0.02 / 4096, minimum=0.0, unit="m")
    length_noise_std: float = option(2e-6, minimum=0.0, exclusive=True, unit="m")
    tension_noise_std: float = option(0.01, minimum=0.0, unit="N")
    damping_time: float = option(0.0005, minimum=0.0, unit="s")
    taut_threshold: float = option(1.0, minimum=0.0, unit="N")
    hang_threshold: float = option(0.27, minimum=0.0, unit="N")
    pixel_std: float = option(1.0, minimum=0.0, exclusive=True, unit="px")
    focal_px: float = option(415.69219381653056, minimum=0.0, exclusive=True, unit="px")
    tag_size: float = option(0.04, minimum=0.0, exclusive=True, unit="m")
    tag_latency: float = option(0.044, minimum=0.0, unit="s")
    gate_probability: float = option(0.9999, minimum=0.0, exclusive=True)
    use_tag: bool = option(True)
    drum_consider: bool = option(True)
    exit_point_std: float = option(0.0, minimum=0.0, unit="m")
    anchor_point_std: float = option(0.0, minimum=0.0, unit="m")
    camera_position_std: float = option(0.0, minimum=0.0, unit="m")
    camera_rotation_std: float = option(0.0, minimum=0.0, unit="deg")
    focal_error_std: float = option(0.003, minimum=0.0)
    center_error_std_px: float = option(1.5, minimum=0.0, unit="px")
    distortion_error_std: tuple[float, ...] = option((0.01, 0.02, 0.0005, 0.0005), minimum=0.0)
    lens: tuple[float, ...] = option((-0.20, 0.08, 0.002, -0.002))
    max_condition: float = option(500.0, minimum=1.0)

    def __post_init__(self) -> None:
        flags = ("use_tag", "drum_consider", "distortion_error_std", "lens")
        for name, value in vars(self).items():
            if name not in flags and not (math.isfinite(value) and value >= 0):
                raise OptionError(name, f"must be a finite number ≥ 0, got {value}")
            if name.endswith("_std") and name != "distortion_error_std" and value > 1e6:
                raise OptionError(  # (its square and products must stay finite floats)
                    name,
                    f"must be ≤ 1e6 in its unit (a std that says nothing is known), got {value:g}",
                )
        d = self.distortion_error_std
        if len(d) != 4 or not all(math.isfinite(v) and v >= 0 for v in d):
            raise OptionError("distortion_error_std", f"must be 4 finite numbers ≥ 0, got {d}")
        if len(self.lens) != 4 or not all(map(math.isfinite, self.lens)):
            raise OptionError("lens", f"must be 4 finite (k1, k2, p1, p2), got {self.lens}")
        if not self.hang_threshold <= self.taut_threshold:
            raise OptionError("hang_threshold", "must not exceed taut_threshold")
        if not self.max_condition >= 1.0:
            raise OptionError("max_condition", f"must be ≥ 1, got {self.max_condition}")
        if not self.gate_probability < 1.0:
            raise OptionError("gate_probability", "must be below 1")


class FusedEstimator(Estimator):
    """Est. 7: error-state EKF on SE(3) fusing the commanded twist, cable lengths and the tag.

    The arithmetic of each stage is compiled (:mod:`cdpr_twin.estimators.fused_core`); this
    class keeps the state, checks the inputs and says what it did (``flags``).

    Args:
        geometry: nominal geometry (exit and anchor points, sheave radii, E·S, camera mount).
        options: :class:`FusedOptions`.
    """

    name = "fused"
    Options = FusedOptions
    reports_covariance = True

    def __init__(self, geometry: CdprGeometry, options: FusedOptions | None = None) -> None:
        super().__init__(geometry, options)
        m = geometry.n_cables
        o = self.options
        geometry_errors = o.exit_point_std > 0 or o.anchor_point_std > 0
        camera_errors = o.camera_position_std > 0 or o.camera_rotation_std > 0
        intrinsics = o.use_tag and (
            o.focal_error_std > 0 or o.center_error_std_px > 0 or any(o.distortion_error_std)
        )
        L = self.layout = fm.Layout.build(
            m, geometry_errors, camera_errors, o.drum_consider, intrinsics
        )
        self._m, self._n = m, L.n

        def first(block: slice) -> int:
            return block.start if block.stop > block.start else -1

        self._blocks = np.array(
            [
                L.corrected,
                L.drum.start,
                first(L.exit),
                first(L.anchor),
                first(L.cam),
                first(L.intr),
                L.tag.start,
            ]
        )
        self._cables = np.array(  # (m, 7): the model estimators' cables, as one array
            _cable_tuples(geometry.a_base, geometry.b_platform, geometry.pulley_radius)
        )
        self._gate1 = fm.chi2_gate(1, o.gate_probability)
        self._gate6 = fm.chi2_gate(6, o.gate_probability)
        self._es = np.broadcast_to(np.asarray(geometry.es, dtype=float), m).copy()
        # τ_w, then the random walk's variance rate per pose axis: the prediction's noise
        self._process_noise = np.array(
            [o.winch_time_constant]
            + [o.process_position_std**2] * 3
            + [o.process_rotation_std**2] * 3
        )
        self._T_platform_cam = np.array(geometry.T_platform_cam, dtype=float)  # writeable
        self._tag_options = np.array(
            [o.tag_size, o.focal_px, o.pixel_std, o.tag_latency, o.winch_time_constant]
        )
        self._lens = np.array(o.lens, dtype=float)
        self._cable_noise = np.array(
            [
                o.damping_time,
                o.encoder_quantum,
                o.length_noise_std,
                o.tension_noise_std,
                o.taut_threshold,
            ]
        )
        self._max_condition = float(o.max_condition)
        self._no_rates = np.zeros(m)
        # the compiled signature's: a Command's rates
        self._no_rates.flags.writeable = False
        self.P = np.zeros((self._n, self._n))
        fc.warm_up(self._cables, self._n, self._blocks)

    def reset(self, T_base_platform0: np.ndarray, time: float = 0.0) -> None:
        """Start at a known pose, known to the homing repeatability; the tag is forgotten."""
        super().reset(T_base_platform0, time)
        o = self.options
        self._T = np.array(self._T, dtype=float)  # a writeable copy: the compiled signature
        self._T0 = self._T.copy()
        self._rho = np.zeros(self._m)
        self._T_tag = np.eye(4)
        self._anchored = False
        # (2, m): the lengths and corrected readings at t₀
        self._ref: np.ndarray | None = None
        self._last_twist = np.zeros(6)
        P0 = np.diag([o.initial_position_std**2] * 3 + [o.initial_rotation_std**2] * 3)
        self.P = np.zeros((self._n, self._n))
        for a in (fm.POSE, fm.START):
            for b in (fm.POSE, fm.START):
                self.P[a, b] = P0  # the start pose is the current one: fully correlated
        L, P = self.layout, self.P
        P[L.drum, L.drum] = np.eye(self._m) * o.drum_scale_std**2
        P[L.exit, L.exit] = np.eye(L.exit.stop - L.exit.start) * o.exit_point_std**2
        P[L.anchor, L.anchor] = np.eye(L.anchor.stop - L.anchor.start) * o.anchor_point_std**2
        if L.cam.stop > L.cam.start:
            cam = [o.camera_position_std**2] * 3 + [o.camera_rotation_std**2] * 3
            P[L.cam, L.cam] = np.diag(cam)
        if L.intr.stop > L.intr.start:
            k = [o.focal_error_std * o.focal_px] * 2 + [o.center_error_std_px] * 2
            P[L.intr, L.intr] = np.diag(np.square([*k, *o.distortion_error_std]))

    @property
    def T_base_tag(self) -> np.ndarray | None:
        """The tag's estimated pose in F_b (4, 4), or ``None`` before the first detection."""
        return self._T_tag.copy() if self._anchored else None

    def predict(self, twist: np.ndarray, dt: float, rates: np.ndarray, taut) -> None:
        """Propagate with the commanded twist ξ (F_p) over dt [s]; process noise added.

        The winches pay out (1 + ρ_i) times what they are commanded, so the platform moves by
        ξ dt + A⁺ (ρ ⊙ l̇ dt) (A the holding cables' Jacobian): the prediction shares the drum
        errors with the length readings, and the filter knows it. The drums' share enters
        only while A's condition number is below ``max_condition``. The winches' velocity
        loop lags each change of command by τ_w: (τ_w |Δξ|)² of unmodelled motion is added,
        with the random walk's q·dt.

        Args:
            twist: (6,) commanded platform twist [m/s, rad/s].
            dt: time step [s].
            rates: (m,) commanded winch rates [m/s].
            taut: (m,) bools, the cables the platform hangs on (last reading).
        """
        # writeable float copies: the compiled signature (a Command's arrays are read-only)
        twist = np.array(twist, dtype=float)
        self._T = fc.predict(
            self._T,
            self.P,
            twist,
            self._last_twist,
            dt,
            np.array(rates, dtype=float),
            np.asarray(taut, dtype=bool),
            self._process_noise,
            self._cables,
            self._max_condition,
            self._blocks,
        )
        self._last_twist = twist

    def _inject(self, dx: np.ndarray) -> None:  # dx: the corrected states' (c,)
        self._T, self._T0, T_tag, self._rho = fc.inject(
            self._T, self._T0, self._T_tag, self._rho, dx, self._blocks
        )
        if self._anchored:
            self._T_tag = T_tag

    def _taut(self, m: Measurement, threshold: float) -> np.ndarray:
        """(m,) bool: cables reading above ``threshold`` [N], not clipped."""
        taut = m.tensions > threshold
        if m.tensions_clipped is not None:
            taut = taut & ~np.asarray(m.tensions_clipped)
        return np.asarray(taut, dtype=bool)  # the compiled signature's type

    def update_cables(self, m: Measurement, taut=None) -> set[str]:
        """Fuse the taut cables' lengths (taut: m bools, list or array, if known); returns flags."""
        o = self.options
        if self._ref is None:
            c = fm.corrected_readings(
                m.cable_lengths, m.tensions, m.cable_rates, self._es, o.damping_time
            )
            self._ref = np.array([m.cable_lengths, c])
            return set()
        taut = self._taut(m, o.taut_threshold) if taut is None else np.array(taut, dtype=bool)
        flags = set() if np.logical_and.reduce(taut) else {SLACK_CABLES}
        rates = self._no_rates if m.command is None else m.cable_rates
        readings, var = fc.cable_readings(
            m.cable_lengths, m.tensions, rates, self._ref, self._es, self._cable_noise
        )
        outcome, outlier, dx = fc.update_cables(
            self._T,
            self._T0,
            self.P,
            readings,
            self._rho,
            var,
            taut,
            self._cables,
            0.5 * o.encoder_quantum,
            self._gate1,
            self._blocks,
        )
        if outlier:
            flags.add(CABLE_OUTLIER)
        if outcome == fc.CABLES_NONE:
            return flags | {PREDICTED}
        self._inject(dx)
        return flags

    def update_tag(self, m: Measurement) -> set[str]:
        """Fuse a tag detection (the first one anchors the tag); returns the flags raised."""
        if m.tag is None:
            return {TAG_LOST} if m.camera_on else set()
        z = np.array(m.tag.T_cam_tag, dtype=float)  # a writeable copy: the compiled signature
        if not np.isfinite(z).all():
            return {NON_FINITE_INPUT}
        outcome, self._T_tag, dx = fc.update_tag(
            self._T,
            self._T_tag,
            self._anchored,
            self.P,
            z,
            self._last_twist,
            self._T_platform_cam,
            self._tag_options,
            self._lens,
            self._gate6,
            self._blocks,
        )
        if outcome == fc.TAG_GATED:
            return {TAG_OUTLIER}
        if outcome == fc.TAG_ANCHORED:
            self._anchored = True
        else:
            self._inject(dx)
        return set()

    def _step(
        self,
        measurement: Measurement,
        inputs: Mapping[str, PoseEstimate],
        watch_flags: frozenset[str],
    ) -> PoseEstimate:
        """Predict with the last command, then fuse the cables and the tag."""
        m = measurement
        dt = m.time - self._time
        if not dt >= 0:
            raise ValueError(f"fused: measurement time {m.time} s precedes {self._time} s")
        twist = m.twist_platform
        shapes = (m.cable_lengths.shape, m.tensions.shape, m.cable_rates.shape)
        # the compiled stages read m entries of each
        if shapes != ((self._m,),) * 3:
            raise ValueError(
                f"fused: cable_lengths, tensions and the command's cable_rates must have "
                f"{self._m} entries (the geometry's cables), got shapes {shapes}"
            )
        # NaN and inf propagate to one sum of Python floats: a scalar test
        total = sum(m.cable_lengths.tolist()) + sum(m.tensions.tolist())
        if twist is not None:  # (no command yet: no twist, rates)
            total += sum(twist.tolist()) + sum(m.cable_rates.tolist())
        if not math.isfinite(total):
            return self._held(m, NON_FINITE_INPUT, covariance=self.P[fm.POSE, fm.POSE])
        if dt > 0:
            moving = twist is not None
            hanging = self._taut(m, self.options.hang_threshold)
            self.predict(
                twist if twist is not None else np.zeros(6),
                dt,
                m.cable_rates if moving else np.zeros(self._m),
                hanging,
            )
        flags = self.update_cables(m, self._taut(m, self.options.taut_threshold))
        if self.options.use_tag:
            flags |= self.update_tag(m)
        self._time = m.time
        return PoseEstimate(
            m.time, self._T, flags=frozenset(flags), covariance=self.P[fm.POSE, fm.POSE]
        )
