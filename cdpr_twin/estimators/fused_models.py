"""The measurement models of the fused filter (numpy only): cable lengths and tag poses.

The filter's error state (:mod:`cdpr_twin.estimators.fused`) is, in this order,

| slice | symbol | meaning |
|---|---|---|
| ``POSE`` (6) | δ | the platform pose error, ``T_true = T · exp(δ)``, δ = [v, ω] in F_p |
| ``START`` (6) | δ₀ | the error of the pose at the reference reading (homing repeatability) |
| ``TAG`` (6) | δ_o | the tag pose's error in F_b, ``T_base_tag_true = T_base_tag · exp(δ_o)`` |
| ``DRUM`` (m) | ρ | each drum's true/nominal radius ratio − 1 (the encoders' scale error) |

Cable model. The encoders are homed at the start pose: each reading counts the paid-out length
since then through the nominal drum radius. With c_i = l_i + l_i τ_i / E·S_i − η l̇_i the
stretch-corrected reading (eq. 13-14, η the cables' damping time: a tension sensor reads the
damping force η E·S/l₀ · l̇ too), the reading since the reference is

    y_i = c_i(t) − c_i(t₀) = L_i(T) − L_i(T₀) − ρ_i Δl_i + n_i,

with L_i the pulley length (eq. 15-24), Δl_i the encoder's count since t₀ and n_i the encoder
quantisation (a floor: mean −q/2, std q/√12) and the tension noise mapped through the
elasticity (δl = l δτ / E·S, at both readings).

Tag model. The detection ᶜT_o (pupil frame) is the tag pose seen from the camera at
``T_lag = T · exp(−ξ d)`` (the latency d of the frame: one tick plus half the exposure):
``z = T_pc⁻¹ T_lag⁻¹ T_base_tag · exp(n)``, n the detection noise in the tag frame, whose
covariance follows from the corners' pixel noise through the projection's Jacobian (it grows
with the distance to the tag).

The compiled filter (:mod:`cdpr_twin.estimators.fused_core`) evaluates the tag residual, the
detection covariance and the Joseph update itself; their plain NumPy references, against which
the tests hold it, are in ``tests/estimators/reference_fused.py``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

POSE, START = slice(0, 6), slice(6, 12)


@dataclass(frozen=True)
class Layout:
    """Where each part of the error state sits.

    Attributes:
        n: the state's dimension.
        drum: (m) drum scale errors ρ.
        exit: (3m) exit-point errors δa_i in F_b, cable after cable (empty when not modelled).
        anchor: (3m) anchor-point errors δb_i in F_p (empty when not modelled).
        cam: (6) camera-mount error, ``T_pc_true = T_pc · exp(δc)`` (empty when not modelled).
        intr: (8) the camera calibration's error δk = calibrated − true (fx, fy, cx, cy [px],
            k1, k2, p1, p2), empty when not modelled.
        tag: (6) the tag pose's error δ_o.
        consider: the states the filter accounts for but never corrects (Schmidt), as a mask.
    """

    n: int
    drum: slice
    exit: slice
    anchor: slice
    cam: slice
    intr: slice
    tag: slice
    consider: np.ndarray

    @classmethod
    def build(
        cls, m: int, geometry: bool, camera: bool, consider_drums: bool, intrinsics: bool = False
    ) -> Layout:
        """The layout for m cables, with or without the geometry and camera-mount states.

        The corrected states come first (pose, start, tag, then the drums unless they are
        considered) and the considered ones last, so that an update touches a leading block.
        """
        sizes = {
            "tag": 6,
            "drum": m,
            "exit": 3 * m * geometry,
            "anchor": 3 * m * geometry,
            "cam": 6 * camera,
            "intr": 8 * intrinsics,
        }
        start, out = 12, {}
        for name, size in sizes.items():
            out[name] = slice(start, start + size)
            start += size
        consider = np.zeros(start, dtype=bool)
        consider[out["drum"].start if consider_drums else out["drum"].stop :] = True
        return cls(n=start, consider=consider, **out)

    def __post_init__(self) -> None:
        c = self.corrected
        if not (self.consider[c:].all() and not self.consider[:c].any()):
            raise ValueError("the considered states must come last (one block at the end)")

    @property
    def corrected(self) -> int:
        """How many leading states an update corrects (the rest are considered)."""
        return int(np.argmax(self.consider)) if self.consider.any() else self.n


def corrected_readings(
    lengths: np.ndarray,
    tensions: np.ndarray,
    rates: np.ndarray,
    es: np.ndarray,
    damping_time: float,
) -> np.ndarray:
    """c_i = l_i + l_i τ_i / E·S_i − η l̇_i: the readings corrected for stretch and damping.

    Args:
        lengths: (m,) encoder lengths [m].
        tensions: (m,) measured tensions [N].
        rates: (m,) commanded winch rates over the last period [m/s] (≈ l̇_i).
        es: (m,) nominal E·S [N].
        damping_time: η, the cables' damping time [s].

    Returns:
        (m,) corrected lengths [m].
    """
    return lengths + lengths * tensions / es - damping_time * rates


def cable_noise_var(
    lengths: np.ndarray,
    tensions: np.ndarray,
    es: np.ndarray,
    quantum: float,
    floor_std: float,
    tension_std: float,
    threshold: float,
) -> np.ndarray:
    """Variance of each cable reading's error n_i [m²], tension-aware.

    Quantisation (q²/12), a floor, the tension noise at both readings mapped through the
    elasticity, and a cable close to slack (below 3× the taut threshold) trusted less: its
    variance grows ×(3·threshold/τ)⁴, for a reading that may come from a sagging cable.

    Args:
        lengths: (k,) encoder lengths [m].
        tensions: (k,) measured tensions [N] (each above ``threshold``).
        es: (k,) nominal E·S [N].
        quantum: encoder count length q [m].
        floor_std: a floor under the noise std [m].
        tension_std: std of a tension reading's random error [N].
        threshold: the taut threshold [N].

    Returns:
        (k,) variances [m²].
    """
    var = quantum**2 / 12.0 + floor_std**2 + 2.0 * (lengths * tension_std / es) ** 2
    near_slack = np.maximum(3.0 * threshold / np.maximum(tensions, 1e-9), 1.0)
    return var * near_slack**4


def _lens(xy: np.ndarray, coeffs) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Brown–Conrady at normalised points: distorted points, ∂/∂point and ∂/∂coefficients.

    Args:
        xy: (n, 2) undistorted normalised coordinates.
        coeffs: (k1, k2, p1, p2).

    Returns:
        (n, 2) distorted points, (n, 2, 2) their Jacobian, (n, 2, 4) ∂/∂(k1, k2, p1, p2).
    """
    k1, k2, p1, p2 = coeffs
    x, y = xy[:, 0], xy[:, 1]
    r2 = x * x + y * y
    a, da = 1.0 + k1 * r2 + k2 * r2 * r2, 2.0 * k1 + 4.0 * k2 * r2  # radial factor, ∂a/∂r² × 2
    xd = np.column_stack(
        [
            x * a + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
            y * a + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y,
        ]
    )
    D = np.empty((len(xy), 2, 2))
    D[:, 0, 0] = a + x * x * da + 2 * p1 * y + 6 * p2 * x
    D[:, 0, 1] = D[:, 1, 0] = x * y * da + 2 * p1 * x + 2 * p2 * y
    D[:, 1, 1] = a + y * y * da + 6 * p1 * y + 2 * p2 * x
    dx = np.column_stack([x * r2, x * r2 * r2, 2 * x * y, r2 + 2 * x * x])
    dy = np.column_stack([y * r2, y * r2 * r2, r2 + 2 * y * y, 2 * x * y])
    dc = np.stack([dx, dy], axis=1)
    return xd, D, dc


def _corner_jacobian(
    T_cam_tag: np.ndarray, tag_size: float, focal_px: float, lens=(0.0, 0.0, 0.0, 0.0)
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The corners' pixel Jacobian through the lens, and what the calibration's needs.

    Returns:
        J (8, 6) ∂(u₀, v₀, u₁, …)/∂n (n the tag-frame twist), the (4, 2) distorted normalised
        coordinates, and the lens's (4, 2, 4) ∂/∂coefficients.
    """
    h = 0.5 * tag_size
    p = np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])
    R, t = T_cam_tag[:3, :3], T_cam_tag[:3, 3]
    X = p @ R.T + t  # (4, 3) corners in the camera frame
    inv_z = 1.0 / X[:, 2]
    # d(x, y)/dX per corner: 1/Z [[1, 0, −X/Z], [0, 1, −Y/Z]], (4, 2, 3)
    d_norm = np.zeros((4, 2, 3))
    d_norm[:, 0, 0] = d_norm[:, 1, 1] = inv_z
    d_norm[:, 0, 2] = -inv_z * X[:, 0] / X[:, 2]
    d_norm[:, 1, 2] = -inv_z * X[:, 1] / X[:, 2]
    # dX/d[v, ω] = R [I, −[p]×] (a tag-frame twist moves the corner by v + ω × p)
    d_point = np.zeros((4, 3, 6))
    d_point[:, :, :3] = R
    cross = np.zeros((4, 3, 3))  # −[p]×
    cross[:, 0, 1], cross[:, 0, 2], cross[:, 1, 2] = p[:, 2], -p[:, 1], p[:, 0]
    cross[:, 1, 0], cross[:, 2, 0], cross[:, 2, 1] = -p[:, 2], p[:, 1], -p[:, 0]
    d_point[:, :, 3:] = R @ cross
    xd, D, dc = _lens(X[:, :2] * inv_z[:, None], lens)
    return (focal_px * D @ d_norm @ d_point).reshape(8, 6), xd, dc


def tag_calibration_jacobian(
    T_cam_tag: np.ndarray, tag_size: float, focal_px: float, lens=(0.0, 0.0, 0.0, 0.0)
) -> np.ndarray:
    """∂n/∂δk: how a calibration error δk moves the detected pose, to first order.

    The detector fits the pose whose projection through the *calibrated* camera (intrinsics
    and Brown–Conrady lens, k̂ = k + δk) meets the corners the true camera saw, so
    J n + Π δk = 0 and n = −(JᵀJ)⁻¹ Jᵀ Π δk, with u = fx x_d + cx (x_d the distorted
    normalised coordinate), J = ∂u/∂n through the lens and Π = ∂u/∂k. Face-on, the tilt is
    nearly unobservable, so the lens's own Jacobian decides how a principal-point error tilts
    the pose: it must be in J. The error is the same at every detection from one view: a
    bias the filter must consider, not noise that averages out.

    Args:
        T_cam_tag: (4, 4) detected tag pose in the camera frame.
        tag_size: edge of the tag's black square [m].
        focal_px: focal length [px].
        lens: the calibrated (k1, k2, p1, p2).

    Returns:
        (6, 8) for δk = (δfx, δfy, δcx, δcy [px], δk1, δk2, δp1, δp2).
    """
    J, xd, dc = _corner_jacobian(T_cam_tag, tag_size, focal_px, lens)
    Pi = np.zeros((4, 2, 8))
    Pi[:, 0, 0], Pi[:, 1, 1], Pi[:, 0, 2], Pi[:, 1, 3] = xd[:, 0], xd[:, 1], 1.0, 1.0
    Pi[:, :, 4:] = focal_px * dc
    return -np.linalg.solve(J.T @ J, J.T @ Pi.reshape(8, 8))


def chi2_gate(dof: int, probability: float) -> float:
    """The χ²(dof) quantile at ``probability``, used as a Mahalanobis gate.

    ``2·P⁻¹(dof/2, p)``, P the regularised lower incomplete gamma function: what
    ``scipy.stats.chi2.ppf`` computes, without importing scipy.stats (0.5 s per process).
    """
    from scipy.special import gammaincinv

    return float(2.0 * gammaincinv(0.5 * dof, probability)) if dof > 0 else math.inf
