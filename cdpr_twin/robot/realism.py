"""How imperfect the simulated robot is: the scenario's ``[realism]`` profile (numpy only).

Each effect is *generated* by the simulation layer (rendered, integrated, quantised), with a
magnitude from ``models/acrobot/README.md`` (its source named there), and each can be switched
off. What is robot data — the drum radius, the tension sensors' range, accuracy and
repeatability — is not here: ``nan`` fields (and ``repeatability_noise``) take it from the
robot description (``robot.toml`` → the model's ``<numeric>``; :func:`for_robot`).
Profiles: ``profile = "ideal"`` is the twin before realism, bit for bit; ``acrobot_full`` is
``acrobot`` with the cables and pulleys as they are (:class:`CableRealism`,
:class:`PulleyRealism`) and the drives and optics as they are (:class:`DriveRealism`,
:class:`OpticsRealism`). Magnitudes come in two kinds, as physics dictates:

- per robot (drawn from the truth seed, fixed across repetitions, like one physical robot):
  intrinsics calibration error (its parts drawn together with the correlations of
  ``[realism.optics]``), drum radius error, tension-sensor bias and gain, each rope's stiffness,
  the pulleys' swivel tilts and sheave offsets, the camera pixels' gains and dark offsets
  (``[realism.optics] prnu_std``, ``dsnu_e``);
- per run (drawn from the run seed): pixel noise, tension repeatability noise, the homing offset
  of the start pose, or each drum's zero error (``[realism.drive]``), the light's flicker
  phase.

The drums, gearboxes and motors (``[realism.drive]``) and the lens and light
(``[realism.optics]``) are fixed by the profile's numbers: ``acrobot_full`` turns them on.

A scenario overrides any field: ``[realism.camera] exposure_s = 0.004``. Every magnitude has an
upper bound here (``MAX_*``, each with the reason it is the limit), which the scenario's other
tables (``[truth]``, ``[sensors]``, events) use too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np

from cdpr_twin.options import OptionError, option

# ---------------------------------------------------------------------------- the limits
# The largest magnitudes a scenario may ask for, each with the reason it is the limit. Real
# robots and cameras stay far inside these: beyond them a draw breaks the physics (a
# non-positive radius), the arithmetic (float32 overflow), the memory, or the detector. The
# robot's calibration errors ([truth]), the tension sensors' noise ([sensors],
# [realism.tension]) and a failed sensor's reading are bounded here too.
MAX_RELATIVE_STD = 0.1
"""The largest per-robot relative std of a positive quantity (a radius, a focal length, a
gain): a non-positive draw is then a 10σ event; built and calibrated parts are within 1 %."""
MAX_FULL_WELL_E = 1e30
"""The largest full well [e-] the float32 frame arithmetic holds without overflow."""
MAX_DSNU_E = 1000.0
"""The largest std of a pixel's dark offset [e-]: a tenth of a 10 ke- full well, 26 steps of an
8-bit frame; a sensor that offset shows its own pattern in every frame, not the scene's."""
MAX_LATENCY_TICKS = 100
"""The longest camera latency [control ticks] (4 s at 25 Hz)."""
MAX_CENTER_ERROR_STD_PX = 20.0
"""The largest per-robot std of the calibrated principal point [px]: calibrations leave
0.3–1.3 px (``models/acrobot/README.md``), and a 10σ draw stays inside a 640×480 frame."""
MAX_DISTORTION_ERROR_STD = 0.1
"""The largest per-robot std of a calibrated distortion coefficient: calibrations leave
3e-4–7e-3; at 0.1 a 10σ draw moves k1 by 1, a different lens."""
MAX_HOMING_POSITION_STD = 0.05
"""The largest homing repeatability [m] per axis: a robot that homes farther off than this
starts somewhere else (set ``start.pose``); CDPRs home within millimetres."""
MAX_HOMING_ROTATION_STD = math.radians(5.0)
"""The largest homing repeatability [rad] per axis (5°; CDPRs home within tenths of one)."""

MAX_POSITION_ERROR_STD = 1.0
"""The largest per-axis std of a point's calibration error [m] (exit and anchor points, camera
mount, tag): assembly and calibration leave millimetres (``paper_open_loop``: 12 mm at the exit
points); a point a metre off is another robot than its description."""
MAX_ROTATION_ERROR_STD = math.radians(10.0)
"""The largest per-axis std of a mount's calibration error [rad] (10°): a hand-eye calibration
and a tag placed by hand are good to 0.3°; at 10° a 3σ draw turns the camera 30° away."""
MAX_PULLEY_RADIUS_STD = 0.01
"""The largest std of a sheave's radius [m] (1 cm): sheaves are machined to ±0.2 mm, and a draw
off by centimetres is another pulley (ACROBOT's sheaves have a 4.5 mm radius)."""
MAX_TENSION_NOISE_STD = 1000.0
"""The largest std of a tension reading's noise or bias [N]: sensors repeat to 0.1 % of their
span or better (ACROBOT 0.01 N of 100 N, COGIRO 5 N of 7 kN); 1 kN is ten times the whole span
of ACROBOT's sensors, a reading that says nothing of the tension."""
TENSION_NOISE_WHY = " N (beyond the span of ACROBOT's sensors tenfold: a reading says nothing)"
"""Why :data:`MAX_TENSION_NOISE_STD` bounds a tension noise, as a message says it."""
MAX_TENSION_READING = 1e6
"""The largest force a failed tension sensor may read [N], either way (1 MN): over 150 times
the top of the largest shipped robot's range (COGIRO's 6 kN); beyond it a reading is no force
a cable robot's sensor outputs (1e300 was accepted, and read for the rest of the run)."""


def check_relative_std(field: str, std: float, what: str) -> None:
    """Refuse a relative std that could draw a non-positive ``what`` (> :data:`MAX_RELATIVE_STD`).

    Raises:
        OptionError: naming ``field``.
    """
    if std > MAX_RELATIVE_STD:
        raise OptionError(
            field,
            f"must be ≤ {MAX_RELATIVE_STD:g} (a relative std: at {std:g} a draw of 1 + std·z "
            f"makes the {what} ≤ 0 once in {1 / _tail(1 / std):.3g} robots), got {std:g}",
        )


def check_at_most(field: str, value: float, bound: float, unit_why: str) -> None:
    """Refuse ``value`` above ``bound``: "must be ≤ {bound}{unit_why}, got {value}".

    Raises:
        OptionError: naming ``field``.
    """
    if value > bound:
        raise OptionError(field, f"must be ≤ {bound:g}{unit_why}, got {value:g}")


def _tail(k: float) -> float:
    """P(z < −k) for a standard normal z."""
    return 0.5 * math.erfc(k / math.sqrt(2.0))


PROFILES = ("ideal", "acrobot", "acrobot_full")


@dataclass(frozen=True)
class CameraRealism:
    """The onboard camera's imperfections (all off: an ideal pinhole, noise-free, instantaneous).

    Attributes:
        noise: simulate photon shot noise and read noise on a linear signal, then gamma and
            8-bit quantisation.
        full_well_e: electrons at the brightest rendered level [e⁻].
        read_noise_e: read noise std [e⁻].
        gamma: encoding gamma from the linear signal to 8-bit values.
        white_level: the fraction of the full well the brightest rendered level (white paper)
            reaches: exposure keeps it below saturation.
        black_level: the fraction of the full well the darkest rendered level (black ink)
            reaches: ink reflects some light.
        exposure_s: exposure time [s]; 0 renders one instant (no motion blur).
        blur_subframes: frames rendered at the true poses during the exposure and averaged.
        supersample: render ``supersample`` × ``supersample`` samples per pixel and average
            them (each pixel integrates light over its area); 1 point-samples the render.
        distortion: true Brown–Conrady coefficients (k1, k2, p1, p2) of the lens.
        focal_error_std: per-robot relative std of the calibrated fx, fy.
        center_error_std_px: per-robot std of the calibrated cx, cy [px].
        distortion_error_std: per-robot std of each calibrated distortion coefficient
            (k1, k2, p1, p2).
        latency_ticks: the tag pose available at tick k comes from the frame exposed at k − d.
    """

    noise: bool = option(False)
    full_well_e: float = option(10_000.0, minimum=1.0, unit="e-")
    read_noise_e: float = option(0.0, minimum=0.0, unit="e-")
    gamma: float = option(1.0, minimum=0.1)
    white_level: float = option(1.0, minimum=0.0, exclusive=True)
    black_level: float = option(0.0, minimum=0.0)
    exposure_s: float = option(0.0, minimum=0.0, unit="s")
    blur_subframes: int = option(1, minimum=1)
    supersample: int = option(1, minimum=1)
    distortion: tuple[float, ...] = option((0.0, 0.0, 0.0, 0.0))
    focal_error_std: float = option(0.0, minimum=0.0)
    center_error_std_px: float = option(0.0, minimum=0.0, unit="px")
    distortion_error_std: tuple[float, ...] = option((0.0, 0.0, 0.0, 0.0), minimum=0.0)
    latency_ticks: int = option(0, minimum=0)

    def __post_init__(self) -> None:
        if not self.black_level < self.white_level <= 1.0:
            raise OptionError("white_level", "need black_level < white_level ≤ 1")
        for name in ("distortion", "distortion_error_std"):
            if len(getattr(self, name)) != 4:
                raise OptionError(name, "must list 4 values, for k1, k2, p1, p2")
        check_relative_std("focal_error_std", self.focal_error_std, "focal length")
        check_at_most(
            "center_error_std_px",
            self.center_error_std_px,
            MAX_CENTER_ERROR_STD_PX,
            " px (calibrations place the principal point within 0.3–1.3 px)",
        )
        check_at_most(
            "distortion_error_std",
            max(self.distortion_error_std),
            MAX_DISTORTION_ERROR_STD,
            " each (calibrations leave 3e-4–7e-3)",
        )
        check_at_most(
            "full_well_e",
            self.full_well_e,
            MAX_FULL_WELL_E,
            " e- (the frame is formed in float32; sensors hold 1e3-1e6)",
        )
        check_at_most(
            "latency_ticks",
            self.latency_ticks,
            MAX_LATENCY_TICKS,
            " (every frame in flight is held in memory; cameras deliver within a few frames)",
        )


@dataclass(frozen=True)
class WinchRealism:
    """Winch servo and encoder imperfections (all off: rates applied instantly, exact encoders).

    Attributes:
        bandwidth_hz: velocity-loop bandwidth (first order, time constant 1/(2π f)); ``inf``
            follows the commanded rate instantly.
        max_accel: acceleration limit of the cable rate [m/s²] (``inf``: none).
        encoder_counts: encoder counts per drum revolution (0: exact encoders).
        drum_radius: nominal drum radius [m] (the length the encoder reports uses it); ``nan``:
            the robot's (``[winches] drum_radius_m``).
        drum_radius_error_std: per-robot relative std of the true drum radius.
    """

    bandwidth_hz: float = option(math.inf, minimum=0.0, exclusive=True, infinite=True, unit="Hz")
    max_accel: float = option(math.inf, minimum=0.0, exclusive=True, infinite=True, unit="m/s2")
    encoder_counts: int = option(0, minimum=0)
    drum_radius: float = option(math.nan, minimum=0.0, exclusive=True, unit="m")
    drum_radius_error_std: float = option(0.0, minimum=0.0)

    def __post_init__(self) -> None:
        check_relative_std("drum_radius_error_std", self.drum_radius_error_std, "drum radius")


@dataclass(frozen=True)
class TensionRealism:
    """Tension-sensor imperfections beyond the per-reading noise ``[sensors] tension_noise_std``.

    Sensor i reads ``(1 + g_i)·τ_i + b_i + n``
    (:class:`cdpr_twin.sim.tension_sensors.TensionSensors`): b_i and g_i are fixed per robot
    (truth seed), n is drawn at each reading (run seed).

    How a datasheet maps onto these fields. A stated *accuracy* (the paper's 0.24 N) is a bound
    on the total error, not a standard deviation: accuracy itself is qualitative (JCGM 200:2012,
    VIM 2.13), and a number given for it is the half-width a of an interval ±a that the error
    stays within. Its random part is the *repeatability* (VIM 2.21; the paper's 0.01 N), so a
    24:1 ratio leaves the error budget almost wholly systematic: an offset that stays put
    between readings, drawn once per sensor, not redrawn per reading. With nothing known but
    the bound, GUM (JCGM 100:2008) 4.3.7 gives the standard uncertainty of a ±a rectangular
    distribution as u = a/√3, so ``bias_std`` = 0.24/√3 ≈ 0.139 N, not 0.24 N (which would
    treat the bound as 1σ and let a third of the sensors exceed their own datasheet).
    ``gain_error_std`` adds a load-proportional part (e.g. 0.1 %: 0.075 N at 75 N), small
    beside the offset. The repeatability 0.01 N is taken as 1σ of the reading noise (the
    conservative reading; as an ISO 5725 repeatability limit r = 2.8 σ it would be 0.004 N).

    Attributes:
        bias_std: per-robot std of each sensor's offset b_i [N] (accuracy a → a/√3); ``nan``:
            the robot's sensor accuracy a/√3 (``[tension_sensors] accuracy_n``).
        gain_error_std: per-robot relative std of each sensor's gain error g_i.
        clip: clip readings to [``range_min``, ``range_max``], and say which did in
            ``Measurement.tensions_clipped`` (and per cable in ``summary.json``).
        range_min: lowest reading [N]; ``nan``: the robot's (``[tension_sensors] range_n``).
        range_max: highest reading [N]; ``nan``: the robot's.
        noise_std: per-reading noise std [N]; ``nan`` keeps ``[sensors] tension_noise_std``
            (the ideal profile: the scenario's value, as before realism), or with
            ``repeatability_noise`` the robot's sensor repeatability.
        repeatability_noise: a ``nan`` noise_std is the robot's repeatability
            (``[tension_sensors] repeatability_n``) instead of ``[sensors] tension_noise_std``.
    """

    bias_std: float = option(0.0, minimum=0.0, unit="N")
    gain_error_std: float = option(0.0, minimum=0.0)
    clip: bool = option(False)
    range_min: float = option(math.nan, unit="N")
    range_max: float = option(math.nan, unit="N")
    noise_std: float = option(math.nan, unit="N")
    repeatability_noise: bool = option(False)

    def __post_init__(self) -> None:
        if not (math.isnan(self.noise_std) or self.noise_std >= 0):
            raise OptionError("noise_std", f"must be ≥ 0 N, got {self.noise_std}")
        if not (math.isnan(self.range_min) or math.isnan(self.range_max)) and not (
            self.range_min < self.range_max
        ):
            raise OptionError("range_max", f"must exceed range_min = {self.range_min} N")
        check_relative_std("gain_error_std", self.gain_error_std, "sensor's gain")
        for name in ("bias_std", "noise_std"):  # (a nan noise_std: [sensors]', bounded there)
            check_at_most(name, getattr(self, name), MAX_TENSION_NOISE_STD, TENSION_NOISE_WHY)


@dataclass(frozen=True)
class HomingRealism:
    """Repeatability of the start pose between repetitions (per run, from the run seed).

    Each run places the *true* platform at the start pose moved by a drawn offset
    (:func:`draw_homing_offset`), while the encoders are homed as if it stood at the nominal
    start pose and every estimator and the controller start from the nominal start pose: the
    robot believes it is where it always starts.

    Attributes:
        position_std: per-axis std of the true start position's offset [m].
        rotation_std: per-axis std of the true start orientation's offset [rad] (file:
            ``rotation_std_deg``).
    """

    position_std: float = option(0.0, minimum=0.0, unit="m")
    rotation_std: float = option(0.0, minimum=0.0, unit="deg")

    def __post_init__(self) -> None:
        why = " (a repeatability: a robot homing farther off starts elsewhere; set start.pose)"
        check_at_most("position_std", self.position_std, MAX_HOMING_POSITION_STD, " m" + why)
        check_at_most(
            "rotation_std_deg",
            math.degrees(self.rotation_std),
            math.degrees(MAX_HOMING_ROTATION_STD),
            "°" + why,
        )


def _check_correlation(name: str, rho: float) -> None:
    """Refuse a correlation outside (−1, 1) (±1 would make the covariance singular)."""
    if not -1.0 < rho < 1.0:
        raise OptionError(name, f"must lie strictly between -1 and 1 (a correlation), got {rho}")


@dataclass(frozen=True)
class OpticsRealism:
    """How the camera's calibration errors go together (all 0: independent draws, as before).

    A calibration (Zhang's method, OpenCV, Kalibr) fits fx, fy, cx, cy and the distortion
    coefficients together, and what it cannot tell apart it leaves correlated: the focal
    lengths move together (the aspect ratio fy/fx is pinned far tighter than either), k1 and
    k2 trade off against each other over the field, and a tangential coefficient trades off
    against the principal point on the same axis. The errors are drawn from one multivariate
    normal with the stds of :class:`CameraRealism` and these correlations
    (:func:`cdpr_twin.sim.onboard_camera.calibrate`).

    The lens and the light (:mod:`cdpr_twin.sim.optics`) act on each formed frame.

    Attributes:
        focal_correlation: ρ between the relative errors of fx and fy; the aspect ratio's
            relative error then has std ``focal_error_std``·√(2(1 − ρ)).
        radial_correlation: ρ between the errors of k1 and k2.
        center_tangential_correlation: (ρ(cx, p2), ρ(cy, p1)): p2 moves points along x as cx
            does, p1 along y as cy does.
        defocus: blur each frame by the thin lens's circle of confusion at the tag's depth.
        focus_distance: where the lens is focused [m].
        focal_length: the lens's focal length [m] (its field is the camera model's).
        f_number: the lens's f-number N (aperture diameter f/N).
        vignetting_power: the exponent of the illumination's fall-off cos^n θ off the axis
            (4: a thin lens's natural vignetting; 0: none).
        flicker_depth: the lighting's relative modulation m, 1 + m·sin(2π f t + φ), φ drawn
            per run (0: steady light).
        flicker_hz: its frequency f [Hz] (lamps on 50 Hz mains: 100 Hz).
        line_time: a rolling shutter's row-to-row delay [s]: row r's exposure ends
            (H − 1 − r)·t_line before the last row's (0: a global shutter). The frame is then
            formed from ``blur_subframes`` + 1 renders spread over the whole readout and
            exposure, each row weighing them by its own window.
        jpeg_quality: the camera delivers each frame JPEG-compressed at this IJG quality
            (1–100; 0: uncompressed), as an MJPEG stream does.
        prnu_std: photo-response non-uniformity: the relative std of each pixel's gain on its
            signal electrons (EMVA 1288's PRNU; 0: every pixel alike). Drawn once per robot.
        dsnu_e: dark-signal non-uniformity: the std of each pixel's offset [e⁻], added to its
            electrons before the read noise (EMVA 1288's DSNU; 0: none). Drawn once per robot.
    """

    focal_correlation: float = option(0.0)
    radial_correlation: float = option(0.0)
    center_tangential_correlation: tuple[float, ...] = option((0.0, 0.0))
    defocus: bool = option(False)
    focus_distance: float = option(0.15, minimum=0.0, exclusive=True, unit="m")
    focal_length: float = option(3.04e-3, minimum=0.0, exclusive=True, unit="m")
    f_number: float = option(2.0, minimum=0.5)
    vignetting_power: float = option(0.0, minimum=0.0)
    flicker_depth: float = option(0.0, minimum=0.0)
    flicker_hz: float = option(100.0, minimum=1.0, unit="Hz")
    line_time: float = option(0.0, minimum=0.0, unit="s")
    jpeg_quality: int = option(0, minimum=0)
    prnu_std: float = option(0.0, minimum=0.0)
    dsnu_e: float = option(0.0, minimum=0.0, unit="e-")

    def __post_init__(self) -> None:
        _check_correlation("focal_correlation", self.focal_correlation)
        _check_correlation("radial_correlation", self.radial_correlation)
        if len(self.center_tangential_correlation) != 2:
            raise OptionError(
                "center_tangential_correlation", "must list 2 values, ρ(cx, p2) and ρ(cy, p1)"
            )
        for rho in self.center_tangential_correlation:
            _check_correlation("center_tangential_correlation", rho)
        if not self.focus_distance > self.focal_length:
            raise OptionError(
                "focus_distance",
                f"must exceed the focal length {self.focal_length} m (a real image), "
                f"got {self.focus_distance} m",
            )
        check_at_most("vignetting_power", self.vignetting_power, 10.0, " (cos⁴ is a thin lens's)")
        check_at_most("jpeg_quality", self.jpeg_quality, 100, " (the IJG scale runs 1–100)")
        check_relative_std("prnu_std", self.prnu_std, "pixel's gain")
        check_at_most(
            "dsnu_e",
            self.dsnu_e,
            MAX_DSNU_E,
            " e- (a tenth of a 10 ke- well: the frame would show the sensor's own pattern)",
        )
        if self.flicker_depth > 1.0:
            raise OptionError(
                "flicker_depth", f"must be ≤ 1 (light is ≥ 0), got {self.flicker_depth}"
            )

    @property
    def correlated(self) -> bool:
        """Whether any calibration errors are drawn together."""
        c = self.center_tangential_correlation
        return bool(self.focal_correlation or self.radial_correlation or any(c))

    @property
    def forms(self) -> bool:
        """Whether the lens, the light, the pixels' pattern or the compression change the frame."""
        return bool(
            self.defocus
            or self.vignetting_power
            or self.flicker_depth
            or self.line_time
            or self.jpeg_quality
            or self.fixed_pattern
        )

    @property
    def fixed_pattern(self) -> bool:
        """Whether the pixels differ from each other in gain or offset."""
        return bool(self.prnu_std or self.dsnu_e)

    def calibration_correlation(self) -> np.ndarray:
        """The correlation matrix of the errors of (fx, fy, cx, cy, k1, k2, p1, p2). Returns (8, 8).

        Each correlation pairs two errors no other one touches: the matrix is block-diagonal in
        2 × 2 blocks, positive definite for every |ρ| < 1.
        """
        c = np.eye(8)
        c[0, 1] = c[1, 0] = self.focal_correlation
        c[4, 5] = c[5, 4] = self.radial_correlation
        c[2, 7] = c[7, 2] = self.center_tangential_correlation[0]
        c[3, 6] = c[6, 3] = self.center_tangential_correlation[1]
        return c


MAX_DRIVE_LENGTH = 0.05
"""The largest drive length a scenario may set [m] (a groove pitch, a backlash, a homing
error's std, a departure offset): a winch's are millimetres; 5 cm is another machine."""


MAX_ZERO_ERROR_STD = 0.005
"""The largest std of a drum's zero error [m]: 5 mm on ACROBOT's cables is 1.5 kN, a robot
homed that badly hangs on a few cables or tears them."""


@dataclass(frozen=True)
class DriveRealism:
    """The winches' drums, gearboxes and motors, and how each drum is zeroed (all off: ideal).

    :mod:`cdpr_twin.sim.drive` generates each effect as the physics steps.

    Attributes:
        helix_pitch: the drum's helical groove pitch [m] (0: a plain drum): the cable lies on a
            helix (√(r² + (p/2π)²) per radian) and its departure point walks p per turn along
            the drum.
        guide_distance: from the drum's axis to the first fixed guide the cable runs to [m],
            square to the drum axis.
        departure_offset: where along the drum the cable departs at the zero of its drum angle,
            from the foot of the guide's perpendicular [m].
        winding_compliance: relative shrink of the effective winding radius per newton of
            cable force [1/N] (the rope flattens on the drum): r(τ) = r'·(1 − κ·τ).
        backlash: the gearbox's play, as cable length at the drum [m].
        drum_holding_force: the cable force [N] that turns the drum against its bearing
            friction: below it the drum stays where it is inside the play; above it the cable
            pulls the drum against the flank that holds it.
        friction_rate: the motor's Coulomb friction over the velocity loop's gain, as a cable
            rate [m/s]: a winch at rest does not start below it, a moving one lags its command
            by it (needs a finite ``[realism.winch] bandwidth_hz``).
        zero_error_std: per-run std of each drum's zero [m of cable]: each winch is homed
            against its own reference with its own error, and the start pose is where the
            eight cables then settle.
    """

    helix_pitch: float = option(0.0, minimum=0.0, unit="m")
    guide_distance: float = option(0.2, minimum=0.0, exclusive=True, unit="m")
    departure_offset: float = option(0.0, unit="m")
    winding_compliance: float = option(0.0, minimum=0.0, unit="1/N")
    backlash: float = option(0.0, minimum=0.0, unit="m")
    drum_holding_force: float = option(0.0, minimum=0.0, unit="N")
    friction_rate: float = option(0.0, minimum=0.0, unit="m/s")
    zero_error_std: float = option(0.0, minimum=0.0, unit="m")

    def __post_init__(self) -> None:
        why = " (a winch's groove, play and homing are millimetres)"
        for name in ("helix_pitch", "backlash"):
            check_at_most(name, getattr(self, name), MAX_DRIVE_LENGTH, " m" + why)
        if abs(self.departure_offset) > MAX_DRIVE_LENGTH:
            raise OptionError(
                "departure_offset",
                f"must lie within ±{MAX_DRIVE_LENGTH:g} m{why}, got {self.departure_offset:g}",
            )
        check_at_most(
            "zero_error_std",
            self.zero_error_std,
            MAX_ZERO_ERROR_STD,
            " m (on a cable of E·S/l ≈ 3e5 N/m each millimetre is 300 N)",
        )
        check_at_most(
            "winding_compliance",
            self.winding_compliance,
            1e-3,
            " /N (at 1e-3 a 1 kN cable would wind on no radius)",
        )

    @property
    def drums(self) -> bool:
        """Whether the drums or gearboxes do anything (the physics then winds them)."""
        return bool(self.helix_pitch or self.winding_compliance or self.backlash)


MAX_WRAP_DIAMETER = 0.05
"""The largest cable diameter [m] added to the sheaves' wrap radius: cable robots run cables
of 1–12 mm; a 5 cm one is a hawser on another machine."""


MAX_BEARING_FRICTION = 0.05
"""The largest bearing friction coefficient μ: a rolling bearing has 0.001–0.002, a plain one
0.01–0.02 (Koyo catalogue, "Friction coefficient of bearings", Table 4-1)."""


@dataclass(frozen=True)
class CableRealism:
    """The cables as ropes (all off: Hooke's law with the robot's E·S, the paper's cable).

    The truth's cable i runs from its drum over the sheave to B_i as two segments: the drum
    segment (``drum_segment`` long, fixed) and the platform segment (A_i over the sheave to
    B_i), which exchange cable over the sheave (:class:`PulleyRealism`). Each segment is a
    standard linear solid of instantaneous stiffness k₀ = ρ_i·E·S/l and relaxed stiffness
    ``relaxed_ratio``·k₀ (:mod:`cdpr_twin.sim.rope`); the estimators keep the robot's E·S.
    Magnitudes and sources: ``models/acrobot/README.md``.

    Attributes:
        rope_stiffness_ratio: the braided rope's instantaneous axial stiffness over the
            robot's E·S (which the paper takes from the fibre's modulus); 1: the fibre's.
        rope_stiffness_std: per-robot relative std of each cable's ratio (truth seed).
        drum_segment: length of cable between the drum and the pulley [m], stretching with the
            cable's tension (0: the paper's cable, which starts at the pulley).
        relaxed_ratio: the rope's relaxed (long-term) stiffness over its instantaneous one
            (1: elastic, no creep).
        creep_time: the retardation time of the rope's creep under a constant tension [s].
        strain_damping: the cable's damping (``damping_time_s`` × its stiffness) acts on its
            strain rate; off, on L̇, the paper's cable's, which pulls k·η·l̇0 more on a cable
            paid out at l̇0 (a steady pay-out strains nothing). Viscoelastic ropes and sheave
            friction need it.
    """

    rope_stiffness_ratio: float = option(1.0, minimum=0.0, exclusive=True)
    rope_stiffness_std: float = option(0.0, minimum=0.0)
    drum_segment: float = option(0.0, minimum=0.0, unit="m")
    relaxed_ratio: float = option(1.0, minimum=0.0, exclusive=True)
    creep_time: float = option(math.inf, minimum=0.0, exclusive=True, infinite=True, unit="s")
    strain_damping: bool = option(False)

    def __post_init__(self) -> None:
        check_relative_std("rope_stiffness_std", self.rope_stiffness_std, "rope's stiffness")
        check_at_most(
            "rope_stiffness_ratio",
            self.rope_stiffness_ratio,
            1.0,
            " (a braid is no stiffer than its fibres laid straight)",
        )
        check_at_most(
            "relaxed_ratio",
            self.relaxed_ratio,
            1.0,
            " (a rope relaxes: its long-term stiffness is at most its instantaneous one)",
        )
        check_at_most(
            "drum_segment",
            self.drum_segment,
            MAX_POSITION_ERROR_STD * 100,
            " m (cable robots route their cables over tens of metres at most)",
        )
        if self.viscoelastic and not self.strain_damping:
            raise OptionError(
                "strain_damping",
                "viscoelastic ropes (relaxed_ratio < 1) need strain_damping = true",
            )

    @property
    def viscoelastic(self) -> bool:
        """Whether the ropes creep (a relaxed stiffness below the instantaneous one)."""
        return self.relaxed_ratio < 1.0 and math.isfinite(self.creep_time)


@dataclass(frozen=True)
class PulleyRealism:
    """The pulleys as built (all off: the paper's pulley, a frictionless sheave).

    Attributes:
        sheave_efficiency: the tension ratio across a sheave while the cable slides over it,
            low side over high side (1: frictionless); below it the cable sticks.
        wrap_diameter: the cable's diameter [m]: its centreline wraps the sheave at
            r_p + d/2 (0: the paper's r_p).
        swivel_tilt_std: per-robot std of each swivel axis' tilt about the base x and y axes
            [rad] (file: ``swivel_tilt_std_deg``).
        sheave_offset_std: per-robot std of each sheave centre's offset from its place, along
            the sheave's radius through the swivel axis and along the axis [m].
        swivel_friction: the swivel bearing's friction coefficient μ (Coulomb: the friction
            moment μ·(d/2)·P under the cable's load P on the swivel); the swivel turns toward
            B_i only where the cable's moment about its axis exceeds it (0: it always points
            at B_i, the paper's eq. 20).
        swivel_bore: the swivel bearing's bore d [m].
    """

    sheave_efficiency: float = option(1.0, minimum=0.0, exclusive=True)
    wrap_diameter: float = option(0.0, minimum=0.0, unit="m")
    swivel_tilt_std: float = option(0.0, minimum=0.0, unit="deg")
    sheave_offset_std: float = option(0.0, minimum=0.0, unit="m")
    swivel_friction: float = option(0.0, minimum=0.0)
    swivel_bore: float = option(0.008, minimum=0.0, exclusive=True, unit="m")

    def __post_init__(self) -> None:
        check_at_most(
            "sheave_efficiency", self.sheave_efficiency, 1.0, " (a sheave adds no tension)"
        )
        check_at_most(
            "wrap_diameter",
            self.wrap_diameter,
            MAX_WRAP_DIAMETER,
            " m (cable robots run cables of 1–12 mm)",
        )
        check_at_most(
            "swivel_tilt_std_deg",
            math.degrees(self.swivel_tilt_std),
            math.degrees(MAX_ROTATION_ERROR_STD),
            "° (swivels are mounted within a degree of plumb)",
        )
        check_at_most(
            "sheave_offset_std",
            self.sheave_offset_std,
            MAX_PULLEY_RADIUS_STD,
            " m (sheaves are placed within tenths of a millimetre; set the exit points)",
        )
        check_at_most(
            "swivel_friction",
            self.swivel_friction,
            MAX_BEARING_FRICTION,
            " (rolling bearings 0.001–0.002, plain bearings 0.01–0.02)",
        )
        check_at_most(
            "swivel_bore", self.swivel_bore, 0.05, " m (a small pulley's swivel turns on mm bores)"
        )

    @property
    def geometric(self) -> bool:
        """Whether the pulleys' geometry differs from the paper's model."""
        return self.wrap_diameter > 0 or self.swivel_tilt_std > 0 or self.sheave_offset_std > 0


@dataclass(frozen=True)
class Realism:
    """The whole profile.

    Attributes:
        profile: the named profile the fields start from.
        camera: camera imperfections.
        winch: winch and encoder imperfections.
        tension: tension-sensor imperfections.
        homing: start-pose repeatability.
        optics: how the camera's calibration errors are correlated.
        drive: drums, gearboxes, motors and how each drum is zeroed.
        cable: the cables as ropes.
        pulley: the pulleys as mechanisms and as built.
    """

    profile: str = "ideal"
    camera: CameraRealism = field(default_factory=CameraRealism)
    winch: WinchRealism = field(default_factory=WinchRealism)
    tension: TensionRealism = field(default_factory=TensionRealism)
    homing: HomingRealism = field(default_factory=HomingRealism)
    optics: OpticsRealism = field(default_factory=OpticsRealism)
    drive: DriveRealism = field(default_factory=DriveRealism)
    cable: CableRealism = field(default_factory=CableRealism)
    pulley: PulleyRealism = field(default_factory=PulleyRealism)

    @property
    def is_ideal(self) -> bool:
        """Whether every effect is off."""
        return self == Realism(profile=self.profile)


PARTS: dict[str, type] = {
    "camera": CameraRealism,
    "winch": WinchRealism,
    "tension": TensionRealism,
    "homing": HomingRealism,
    "optics": OpticsRealism,
    "drive": DriveRealism,
    "cable": CableRealism,
    "pulley": PulleyRealism,
}
"""The profile's parts, by their table name in ``[realism.<part>]``."""


ACROBOT: dict[str, dict[str, Any]] = {
    "camera": {
        "noise": True,
        "full_well_e": 10_000.0,
        "read_noise_e": 10.0,
        "gamma": 1.0,
        "white_level": 0.7,
        "black_level": 0.035,
        "exposure_s": 0.008,
        "blur_subframes": 2,
        "distortion": (-0.20, 0.08, 0.002, -0.002),
        "focal_error_std": 0.003,
        "center_error_std_px": 1.5,
        "distortion_error_std": (0.01, 0.02, 0.0005, 0.0005),
        "latency_ticks": 1,
    },
    "winch": {
        "bandwidth_hz": 20.0,
        "max_accel": 2.0,
        "encoder_counts": 4096,
        "drum_radius_error_std": 0.005,
    },
    "tension": {
        "bias_std": math.nan,  # the robot's accuracy a/√3 (ACROBOT: 0.24 N, paper §IV-A)
        "gain_error_std": 0.001,
        "clip": True,
        "repeatability_noise": True,  # the robot's repeatability (ACROBOT: 0.01 N)
    },
    "homing": {"position_std": 0.001, "rotation_std": math.radians(0.2)},
}
"""The ``acrobot`` profile: each magnitude and its source in ``models/acrobot/README.md``."""

ACROBOT_FULL_OPTICS: dict[str, Any] = {
    "focal_correlation": 0.98,
    "radial_correlation": -0.90,
    "center_tangential_correlation": (0.71, 0.45),
    "defocus": True,
    "focus_distance": 0.15,
    "focal_length": 3.04e-3,
    "f_number": 2.0,
    "vignetting_power": 4.0,
    "flicker_depth": 0.05,
    "flicker_hz": 100.0,
    "line_time": 3448 / 182.4e6,
    "prnu_std": 0.007,
    "dsnu_e": 0.0,
}
"""The ``acrobot_full`` profile's optics: calibration correlations, lens, light, shutter and
pixels (``models/acrobot/README.md``)."""

ACROBOT_FULL_DRIVE: dict[str, Any] = {
    "zero_error_std": 1e-5,
    "helix_pitch": 0.0022,
    "guide_distance": 0.2,
    "departure_offset": 0.0,
    "winding_compliance": 4e-5,
    "backlash": 3.5e-4,
    "drum_holding_force": 0.5,
    "friction_rate": 5e-4,
}
"""The ``acrobot_full`` profile's drives (``models/acrobot/README.md``)."""

ACROBOT_FULL: dict[str, dict[str, Any]] = {
    **ACROBOT,
    # each drum is zeroed on its own (drive.zero_error_std): no rigid offset of the pose
    "homing": {"position_std": 0.0, "rotation_std": 0.0},
    "optics": ACROBOT_FULL_OPTICS,
    "drive": ACROBOT_FULL_DRIVE,
    "cable": {
        "rope_stiffness_ratio": 0.6,
        "rope_stiffness_std": 0.05,
        "drum_segment": 1.2,
        "relaxed_ratio": 0.6,
        "creep_time": 1800.0,
        "strain_damping": True,
    },
    "pulley": {
        "sheave_efficiency": 0.95,
        "wrap_diameter": 0.002,
        "swivel_tilt_std": math.radians(0.5),
        "sheave_offset_std": 0.0002,
        "swivel_friction": 0.0015,
        "swivel_bore": 0.008,
    },
}
"""The ``acrobot_full`` profile: ``acrobot`` with the drives, the optics, the cables and the
pulleys as they are (each magnitude and its source in ``models/acrobot/README.md``)."""


def profile(name: str, **parts: dict[str, Any]) -> Realism:
    """A named profile with some fields overridden (SI units).

    Args:
        name: one of :data:`PROFILES`.
        **parts: per part (``camera=…``), the fields to override.

    Raises:
        ValueError: for an unknown profile, part or field.
    """
    if name not in PROFILES:
        raise ValueError(f"unknown realism profile {name!r}; choose one of {', '.join(PROFILES)}")
    out = Realism(profile=name)
    for part in PARTS:
        out = replace(out, **{part: profile_part(name, part, **parts.get(part, {}))})
    _check_one_homing(out)
    return out


def profile_part(name: str, part: str, **values: Any) -> Any:
    """One part of a named profile with some of its fields overridden (SI units).

    Raises:
        ValueError: for an unknown field, or a value out of its bounds (naming it).
    """
    base = {"acrobot": ACROBOT, "acrobot_full": ACROBOT_FULL}.get(name, {})
    cls = PARTS[part]
    values = {**base.get(part, {}), **values}
    unknown = sorted(set(values) - {f.name for f in fields(cls)})
    if unknown:
        raise ValueError(f"realism.{part}: unknown field {unknown[0]!r}")
    return cls(**values)


def _check_one_homing(realism: Realism) -> None:
    """A run starts from one homing: drums zeroed on their own, or the pose's rigid offset.

    Raises:
        OptionError: naming ``realism.drive.zero_error_std``.
    """
    homing = realism.homing.position_std > 0.0 or realism.homing.rotation_std > 0.0
    if realism.drive.zero_error_std > 0.0 and homing:
        raise OptionError(
            "realism.drive.zero_error_std",
            "each drum homed on its own replaces the rigid homing offset of the pose; "
            "set [realism.homing] position_std and rotation_std_deg to 0",
        )


_STREAMS = {
    "camera": 1,
    "winch": 2,
    "tension": 3,
    "homing": 4,
    "cable": 5,
    "pulley": 6,
    "drive": 7,
}


def robot_rng(robot_seed: int, part: str) -> np.random.Generator:
    """The generator of one part's per-robot draws, from the truth seed.

    Independent of the truth deviations' own stream and of the other parts'.
    """
    return np.random.default_rng(np.random.SeedSequence([int(robot_seed), 1, _STREAMS[part]]))


def run_rng(run_seed: int, part: str) -> np.random.Generator:
    """The generator of one part's per-run draws, from the run seed.

    The tension sensors' reading noise keeps the run seed's own stream, as before realism.
    """
    return np.random.default_rng(np.random.SeedSequence([int(run_seed), 2, _STREAMS[part]]))


def draw_homing_offset(h: HomingRealism, rng: np.random.Generator) -> np.ndarray:
    """A start-pose offset [δp (m), δθ (rad)] in the base frame. Returns (6,).

    The true start pose is ᵇT_p0' = (exp([δθ]×) ᵇR_p0, ᵇp_p0 + δp)
    (:func:`cdpr_twin.run.homing_and_teaching.true_start_pose`).
    Draws, in order: 3 positions (``position_std``), 3 rotations (``rotation_std``).

    Args:
        h: the homing repeatability.
        rng: the run's homing generator (``run_rng(seed, "homing")``).
    """
    return np.concatenate([rng.normal(0.0, h.position_std, 3), rng.normal(0.0, h.rotation_std, 3)])


RUN_SOURCES = ("pixel_noise", "tension_noise", "homing")
"""What changes between repetitions of a run on one robot: the camera's pixel noise, the
tension sensors' reading noise (``[sensors] tension_noise_std``) and the homing offset."""


def without_source(realism: Realism, source: str) -> Realism:
    """The profile with one per-run source of variation off.

    ``tension_noise`` lives in the scenario's ``[sensors]`` table: see
    :meth:`cdpr_twin.scenario.loading.Scenario.without`.

    Raises:
        ValueError: for an unknown source.
    """
    if source == "pixel_noise":
        return replace(realism, camera=replace(realism.camera, noise=False))
    if source == "homing":
        # the homing is the pose offset's, or each drum's zero when drums are homed on their own
        drive = replace(realism.drive, zero_error_std=0.0)
        return replace(realism, homing=HomingRealism(), drive=drive)
    if source == "tension_noise":
        return replace(realism, tension=replace(realism.tension, noise_std=0.0))
    raise ValueError(f"unknown source of variation {source!r}; choose one of {RUN_SOURCES}")


# ----------------------------------------------------------- the robot's own sensing data
# What a robot description says of its sensing, filled into a profile: a profile's nan fields
# (the drum radius, the tension sensors' range and accuracy) and its repeatability_noise take
# the robot's data (robot.toml → the model's <numeric>).
@dataclass(frozen=True)
class RobotSensing:
    """What a robot description says of its winches and tension sensors (SI units).

    Attributes:
        drum_radius: the drums' radius [m].
        tension_range: (min, max) the sensors' calibrated range [N].
        accuracy: the sensors' accuracy, a bound ±a on the error [N].
        repeatability: 1σ of their reading noise [N].
    """

    drum_radius: float
    tension_range: tuple[float, float]
    accuracy: float
    repeatability: float


def for_robot(realism: Realism, robot: RobotSensing) -> Realism:
    """The profile with its robot-data fields (``nan``, ``repeatability_noise``) filled in.

    The accuracy becomes a rectangular bias, std a/√3 (GUM 4.3.7; see :class:`TensionRealism`).

    Raises:
        OptionError: naming ``realism.tension.range_min``/``range_max`` when the scenario sets
            one and the range, with the robot's value for the other, does not hold 0 N.
    """
    w, t = realism.winch, realism.tension
    if math.isnan(w.drum_radius):
        w = replace(w, drum_radius=robot.drum_radius)
    lo, hi = robot.tension_range
    filled: dict[str, Any] = {
        "range_min": lo if math.isnan(t.range_min) else t.range_min,
        "range_max": hi if math.isnan(t.range_max) else t.range_max,
        "bias_std": robot.accuracy / math.sqrt(3.0) if math.isnan(t.bias_std) else t.bias_std,
    }
    if t.repeatability_noise and math.isnan(t.noise_std):
        filled["noise_std"] = robot.repeatability
    low, high = filled["range_min"], filled["range_max"]
    set_min, set_max = not math.isnan(t.range_min), not math.isnan(t.range_max)
    # a slack cable reads 0 N: every load cell's range holds it (the model's own range is the
    # model's data, checked in robot descriptions; a scenario's is checked here)
    if (set_min or set_max) and not low <= 0.0 < high:
        given = "range_max" if (set_max and not high > 0.0) or not set_min else "range_min"
        raise OptionError(
            f"realism.tension.{given}",
            f"the readings' range {low:g}…{high:g} N (the robot's {lo:g}…{hi:g} N where not "
            "set) must hold 0 N, the slack cable's reading, with range_min ≤ 0 < range_max",
        )
    return replace(realism, winch=w, tension=replace(t, **filled))
