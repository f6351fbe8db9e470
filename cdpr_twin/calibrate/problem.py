"""Self-calibration as one sparse nonlinear least-squares problem (numpy only).

Unknowns (all corrections to the nominal model, zero at the start):

- shared: exit points A_i (m × 3, F_b), anchor points B_i (m × 3, F_p), one length offset c_i
  per cable, one drum scale error s_i per cable, with the force balance each tension sensor's
  bias b_i [N] and gain error g_i (a reading is (1 + g_i)·τ_i + b_i), the camera mount ᵖT_c
  (6, a twist applied on the right of the nominal mount), the tag pose ᵇT_o (6, likewise) and
  the error of the intrinsics the tag detector uses (8: fx, fy, cx, cy [px], k1, k2, p1, p2;
  with a :class:`Detector`);
- per recorded pose k: the platform pose ᵇT_p,k (6, a twist on the right of the pose the
  robot was commanded to).

Residuals, each divided by its noise so that they are unitless:

- cable i at pose k (taut cables only): the rest length the elastic pulley model predicts,
  l0 = E·S·l_f / (E·S + τ_ik) with l_f from eq. 15-24 and the measured tension τ_ik, minus
  the rest length the encoder implies, e_ik + c_i + s_i·(e_ik − ē_i) (ē_i: the mean reading,
  which decouples offset and scale; s_i = r'_i/r_i − 1 for a drum whose true radius r'_i
  differs from the nominal r_i);
- the tag at pose k (when detected): the measured ᶜT_o against
  ᵖT_c⁻¹ · ᵇT_p,k⁻¹ · ᵇT_o · exp(G_k δk), position in the camera frame and the rotation's
  axis-angle, their noise growing with the distance to the tag. G_k (6 × 8) is the first-order
  effect of an intrinsics error δk on a detection from that view
  (:func:`cdpr_twin.estimators.fused_models.tag_calibration_jacobian`): a camera calibration
  error biases every detection by an amount that depends on the view, which the other
  parameters would otherwise absorb (it was the largest error left in the exit points);
- the wrench balance at pose k (with a ``force_std``; poses whose cables are all taut): force
  Σ τ_ik·u_ik − m·g and moment about the platform's origin Σ ᵇR_p·b_i × (−τ_ik·u_ik) +
  ᵇR_p·c × m·g, τ_ik = (r_ik − b_i)/(1 + g_i) from the readings r_ik, u_ik the unit vector of
  the cable's free segment (eq. 15-24), m·g the platform's weight at its centre of mass c (as
  the description states them). Gravity is the one direction every recording sees in the
  base frame: a frame tilted by θ leaves m·g·θ (0.6 N per degree on ACROBOT) in every pose's
  force balance, where the length and tag residuals cannot tell it (it is a gauge for them),
  so the balance levels the frame; and anchors placed δ across gravity off the centre of mass
  leave m·g·δ in the moment balance (0.03 N·m per mm), which places the platform frame's
  horizontal position;
- priors: each shared correction over the builder's tolerance (:class:`Priors`). The data
  cannot see the base and platform frames themselves (a rigid motion of exit points, tag and
  poses together, or of anchors, camera and poses, leaves every measurement unchanged; with
  the wrench balance, the base frame's position and its rotation about the vertical and the
  platform frame's orientation stay unseen — a centre of mass on the platform's origin, as on
  ACROBOT, turns with it — and its vertical position is seen only weakly): the priors fix
  those gauges, and :mod:`cdpr_twin.calibrate.solver` reports them.
  Among them, the pose where the encoders were homed (:attr:`Observations.home`): the robot
  stood at the pose it was homed at, within the homing's repeatability — the one reference
  of the base frame's position the robot itself has, beside the builder's tolerances.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, replace

import numpy as np
from scipy.sparse import coo_matrix, csc_matrix

from cdpr_twin.calibrate.jacobian import PartJacobian
from cdpr_twin.calibrate.observations import Observations
from cdpr_twin.calibrate.parameter_layout import BLOCKS, Layout
from cdpr_twin.calibrate.tag_views import (
    exp_stack,
    predicted_tags,
    tag_residuals,
    view_columns,
    view_jacobian,
)
from cdpr_twin.calibrate.variance import NoiseModel
from cdpr_twin.calibrate.wrench_balance import cable_columns, cable_jacobian, wrench_residuals
from cdpr_twin.math.geometry import CdprGeometry
from cdpr_twin.math.kinematics import pulley_vectors
from cdpr_twin.math.se3 import inverse, se3_exp

DEFAULT_NOISE = NoiseModel()
"""The noise model a :class:`Problem` is weighted with when none is given."""


@dataclass(frozen=True)
class Priors:
    """The builder's tolerances (1σ) on each correction, and which blocks are estimated.

    Attributes:
        exit: exit point position [m] per axis.
        anchor: anchor point position [m] per axis.
        offset: length offset [m] (encoders homed at a pose the model misplaces).
        scale: relative drum radius error.
        tension_bias: tension sensor offset [N].
        tension_gain: tension sensor relative gain error.
        camera_position: camera mount position [m] per axis.
        camera_rotation: camera mount orientation [rad] per axis.
        tag_position: tag position [m] per axis.
        tag_rotation: tag orientation [rad] per axis.
        intrinsics: the detector's intrinsics error: fx, fy, cx, cy [px], k1, k2, p1, p2.
        home_position: the homing's repeatability [m] per axis: where the encoders were homed
            the robot stood at the pose it was homed at, within this (and ``home_rotation``).
        home_rotation: the homing's repeatability [rad] per axis.
        estimate: the blocks to estimate (others stay nominal), from :data:`BLOCKS`
            (``intrinsics`` only with a :class:`Detector`, the tension sensors' only with a
            force balance).
        use_priors: add the prior residuals (without them the gauges are free).
    """

    exit: float = 0.012
    anchor: float = 0.004
    offset: float = 0.05
    scale: float = 0.005
    tension_bias: float = 0.24 / math.sqrt(3.0)
    tension_gain: float = 0.001
    camera_position: float = 0.001
    camera_rotation: float = math.radians(0.3)
    tag_position: float = 0.001
    tag_rotation: float = math.radians(0.3)
    intrinsics: tuple[float, ...] = (2.0, 2.0, 1.5, 1.5, 0.01, 0.02, 5e-4, 5e-4)
    home_position: float = 0.001
    home_rotation: float = math.radians(0.2)
    estimate: tuple[str, ...] = BLOCKS
    use_priors: bool = True

    def __post_init__(self) -> None:
        unknown = sorted(set(self.estimate) - set(BLOCKS))
        if unknown:
            raise ValueError(f"unknown parameter block {unknown[0]!r}; choose from {BLOCKS}")
        if len(self.intrinsics) != 8:
            raise ValueError("intrinsics: 8 values (fx, fy, cx, cy, k1, k2, p1, p2)")
        if not (self.home_position > 0 and self.home_rotation > 0):
            raise ValueError("home_position and home_rotation must be > 0 (exact homing: a floor)")


@dataclass(frozen=True)
class Detector:
    """What the tag detector assumes: the first-order effect of its intrinsics' error.

    Attributes:
        tag_size: edge of the tag's black square [m].
        focal_px: its focal length [px].
        lens: its Brown–Conrady (k1, k2, p1, p2).
    """

    tag_size: float
    focal_px: float
    lens: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0)


@dataclass(frozen=True, eq=False)
class Model:
    """The robot the parameters describe (nominal + corrections), and the poses.

    Attributes:
        a_base: (m, 3) exit points [m].
        b_platform: (m, 3) anchor points [m].
        offset: (m,) length offsets c_i [m].
        scale: (m,) drum scale errors s_i.
        tension_bias: (m,) tension sensor offsets b_i [N].
        tension_gain: (m,) tension sensor gain errors g_i.
        T_platform_cam: (4, 4) camera mount.
        T_base_tag: (4, 4) tag pose.
        T_base_platform: (K, 4, 4) platform poses.
        intrinsics: (8,) the detector's intrinsics error (fx, fy, cx, cy [px], k1, k2, p1, p2).
    """

    a_base: np.ndarray
    b_platform: np.ndarray
    offset: np.ndarray
    scale: np.ndarray
    tension_bias: np.ndarray
    tension_gain: np.ndarray
    T_platform_cam: np.ndarray
    T_base_tag: np.ndarray
    T_base_platform: np.ndarray
    intrinsics: np.ndarray


class Problem:
    """The residuals of one calibration, their sparsity, and the model they describe.

    Args:
        nominal: the nominal geometry (its exit and anchor points, radii, E·S, camera mount).
        T_base_tag: (4, 4) the tag pose the nominal model states (pupil frame).
        obs: the recordings.
        priors: tolerances and estimated blocks.
        noise: measurement noise.
        detector: the tag detector's assumptions; with it, its intrinsics' error is estimated
            (if ``priors.estimate`` lists ``intrinsics``).
    """

    def __init__(
        self,
        nominal: CdprGeometry,
        T_base_tag: np.ndarray,
        obs: Observations,
        priors: Priors = Priors(),
        noise: NoiseModel = DEFAULT_NOISE,
        detector: Detector | None = None,
    ) -> None:
        self.nominal, self.T_base_tag, self.obs = nominal, np.asarray(T_base_tag), obs
        self.priors, self.noise, self.detector = priors, noise, detector
        statics = noise.force_std is not None
        self.layout = Layout(nominal.n_cables, obs.n_poses, priors, detector is not None, statics)
        taut = np.asarray(obs.taut, bool)
        self.force_k = np.flatnonzero(taut.all(axis=1)) if statics else np.zeros(0, int)
        counts = np.maximum(taut.sum(axis=0), 1)
        self.e_ref = np.where(taut, obs.encoder, 0.0).sum(axis=0) / counts
        self.rows_k, self.rows_i = np.nonzero(taut)
        self.seen = np.flatnonzero(obs.seen)
        self.intrinsics_jacobian = None  # (n_seen, 6, 8): each detection's, over the intrinsics
        if "intrinsics" in self.layout.blocks:
            from cdpr_twin.estimators.fused_models import tag_calibration_jacobian

            d = detector  # (no view: an empty (0, 6, 8) stack, which every step carries)
            # the layout has an intrinsics block exactly when a detector was given
            assert d is not None
            self.intrinsics_jacobian = np.array(
                [
                    tag_calibration_jacobian(T, d.tag_size, d.focal_px, d.lens)
                    for T in obs.T_cam_tag[self.seen]
                ]
            ).reshape(-1, 6, 8)
        self.n_cable_rows, self.n_tag_rows = len(self.rows_k), 6 * len(self.seen)
        self.n_force_rows = 6 * len(self.force_k)
        self.n_data = self.n_cable_rows + self.n_tag_rows + self.n_force_rows
        self.home_k = np.flatnonzero(obs.homed) if priors.use_priors else np.zeros(0, int)
        self.n_prior = self.layout.n_shared + 6 * len(self.home_k) if priors.use_priors else 0
        self._pattern: csc_matrix | None = None
        self._groups: list | None = None
        self._poses: tuple[np.ndarray, np.ndarray] | None = None  # (pose twists, poses)

    def with_noise(self, noise: NoiseModel) -> Problem:
        """The same problem weighted with another noise model (the balance on or off alike).

        Raises:
            ValueError: ``noise`` turns the wrench balance on or off.
        """
        if (noise.force_std is None) != (self.noise.force_std is None):
            raise ValueError("with_noise cannot turn the wrench balance on or off")
        out = copy.copy(self)
        out.noise = noise
        return out

    def without_views(self, poses: np.ndarray | list[int]) -> Problem:
        """The same problem with the tag views at ``poses`` (indices) left out, as if unseen."""
        seen = np.array(self.obs.seen, dtype=bool)
        seen[poses] = False
        obs = replace(self.obs, seen=seen)
        return Problem(self.nominal, self.T_base_tag, obs, self.priors, self.noise, self.detector)

    def pattern(self) -> csc_matrix:
        """:meth:`sparsity` as CSC, computed once (shared with :meth:`with_noise` copies)."""
        if self._pattern is None:
            self._pattern = self.sparsity().tocsc()
        return self._pattern

    def jacobian(self) -> PartJacobian:
        """Central differences of :meth:`residuals` part by part (column groups computed once)."""
        jac = PartJacobian(self.parts(), self.pattern(), groups=self._groups)
        self._groups = jac.groups
        return jac

    def model(self, x: np.ndarray) -> Model:
        """The robot and poses parameters ``x`` describe."""
        L, g = self.layout, self.nominal
        xi = x[L.n_shared :]
        if self._poses is None or not np.array_equal(self._poses[0], xi):  # the Jacobian's
            poses = self.obs.T_guess @ exp_stack(xi.reshape(-1, 6))  # shared columns keep them
            poses.flags.writeable = False
            self._poses = (xi.copy(), poses)
        poses = self._poses[1]
        return Model(
            a_base=g.a_base + L.get(x, "exit"),
            b_platform=g.b_platform + L.get(x, "anchor"),
            offset=L.get(x, "offset"),
            scale=L.get(x, "scale"),
            tension_bias=L.get(x, "tension_bias"),
            tension_gain=L.get(x, "tension_gain"),
            T_platform_cam=g.T_platform_cam @ se3_exp(L.get(x, "camera")),
            T_base_tag=self.T_base_tag @ se3_exp(L.get(x, "tag")),
            T_base_platform=poses,
            intrinsics=L.get(x, "intrinsics"),
        )

    def residuals(self, x: np.ndarray) -> np.ndarray:
        """All residuals, unitless: cables, tag poses, forces, priors. Returns (n_rows,)."""
        mod = self.model(x)
        return np.concatenate(
            [self._cables(mod), self._tags(mod), wrench_residuals(self, mod), self._priors(x)]
        )

    def parts(self) -> list[tuple]:
        """The residuals in parts, each with its rows: cables, tags, forces, priors.

        Each part reaches fewer parameters than the whole (for
        :class:`~cdpr_twin.calibrate.jacobian.PartJacobian`). The tag views differentiate their
        shared columns themselves, all at once
        (:func:`~cdpr_twin.calibrate.tag_views.view_jacobian`), and the wrench balance each
        cable's own, term by term
        (:func:`~cdpr_twin.calibrate.wrench_balance.cable_jacobian`).
        """
        c, t, f = self.n_cable_rows, self.n_tag_rows, self.n_force_rows
        views = (view_columns(self.layout) if t else [], lambda x, h: view_jacobian(self, x, h))
        terms = (
            cable_columns(self.layout) if f else [],
            lambda x, h: cable_jacobian(self, self.model(x), h),
        )
        return [
            (slice(0, c), lambda x: self._cables(self.model(x))),
            (slice(c, c + t), lambda x: self._tags(self.model(x)), views),
            (slice(c + t, c + t + f), lambda x: wrench_residuals(self, self.model(x)), terms),
            (slice(self.n_data, self.n_data + self.n_prior), self._priors),
        ]

    def _priors(self, x: np.ndarray) -> np.ndarray:
        """The builder's tolerances, and where the robot was homed."""
        if not self.n_prior:
            return np.zeros(0)
        L, p = self.layout, self.priors
        home = np.array([p.home_position] * 3 + [p.home_rotation] * 3)
        homed = [x[L.pose(int(k))] / home for k in self.home_k]
        return np.concatenate([x[: L.n_shared] / L.sigma, *homed])

    def _cables(self, mod: Model) -> np.ndarray:
        k, i, g, o = self.rows_k, self.rows_i, self.nominal, self.obs
        T = mod.T_base_platform[k]
        b = np.einsum("nij,nj->ni", T[:, :3, :3], mod.b_platform[i]) + T[:, :3, 3]
        l_f, _ = pulley_vectors(mod.a_base[i], g.pulley_radius[i], b)
        tau = o.tensions[k, i]
        l0_model = g.es[i] * l_f / (g.es[i] + tau)  # (the raw readings: offsets of 0.24 N
        # move the stretch by under 1 µm here, and the balance alone estimates them)
        e = o.encoder[k, i]
        l0_enc = e + mod.offset[i] + mod.scale[i] * (e - self.e_ref[i])
        return (l0_model - l0_enc) / self.noise.length_std

    def predicted_tags(self, mod: Model) -> np.ndarray:
        """The detections the model predicts where the tag was seen, (n_seen, 4, 4).

        The detector's intrinsics error is included (when estimated).
        """
        T_cam_platform = inverse(mod.T_platform_cam)[None]
        return predicted_tags(
            self, T_cam_platform, mod.T_base_tag[None], mod.intrinsics[None], mod.T_base_platform
        )[0]

    def _tags(self, mod: Model) -> np.ndarray:
        return tag_residuals(self, self.predicted_tags(mod)[None])[0]

    def sparsity(self) -> coo_matrix:
        """Which residual depends on which parameter: (n_rows, n) pattern of ones."""
        L, rows, cols = self.layout, [], []

        def see(r: np.ndarray, c: np.ndarray) -> None:  # each row r sees the columns c
            rows.append(np.repeat(r, len(c)))
            cols.append(np.tile(c, len(r)))

        def pose(k: np.ndarray) -> np.ndarray:  # (len(k), 6) the poses' columns
            return L.n_shared + 6 * np.asarray(k)[:, None] + np.arange(6)

        for i in range(L.m):  # a cable's length: its pose, its own exit, anchor, offset, scale
            r = np.flatnonzero(self.rows_i == i)
            see(
                r,
                np.array(
                    [c for n in ("exit", "anchor", "offset", "scale") for c in L.columns(n, i)],
                    dtype=int,
                ),
            )
            rows.append(np.repeat(r, 6))
            cols.append(pose(self.rows_k[r]).ravel())
        groups = (
            (self.n_cable_rows, self.seen, ("camera", "tag", "intrinsics")),
            (
                self.n_cable_rows + self.n_tag_rows,
                self.force_k,
                ("exit", "anchor", "tension_bias", "tension_gain"),
            ),
        )
        for at, ks, names in groups:  # a tag view's, a balance's six rows
            r = at + np.arange(6 * len(ks))
            see(r, np.array([c for n in names for c in L.columns(n)], dtype=int))
            rows.append(np.repeat(r, 6))
            cols.append(np.repeat(pose(ks), 6, axis=0).ravel())
        n_shared = L.n_shared if self.n_prior else 0
        rows.append(self.n_data + np.arange(n_shared))
        cols.append(np.arange(n_shared))
        home = pose(self.home_k).ravel()
        rows.append(self.n_data + n_shared + np.arange(len(home)))
        cols.append(home)
        r, c = np.concatenate(rows), np.concatenate(cols)
        shape = (self.n_data + self.n_prior, L.n)
        return coo_matrix((np.ones(len(r), dtype=np.int8), (r, c)), shape=shape)
