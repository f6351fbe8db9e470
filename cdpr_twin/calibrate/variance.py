"""A calibration's noise model, and each residual group's noise from its own scatter (numpy, scipy).

A calibration starts from a noise model written down beforehand (:data:`pipeline.NOISE`): the
encoders' count, the tag's error growing with distance, the balance's floor. Those are upper
bounds, chosen before the data existed, and they decide how much each kind of measurement
counts against the others and against the builder's tolerances. Too loose a bound leaves
information unused: in the ``acrobot`` profile the tag positions were weighted as if 3 mm off
where they scatter by under 1 mm after the fit, so the only measurement of metric scale that
no drum radius can absorb (how far the tag moves across the image as the platform moves)
counted for little, and the drums' common scale was left to the priors (robot 4: −0.27 % off,
the exit points 2.0 mm out of shape).

The estimate (Förstner 1979; Koch, *Parameter Estimation and Hypothesis Testing in Linear
Models*, §3.6): for each group g of residuals (already divided by their noise),
σ̂²_g / σ²_g = r_gᵀr_g / ρ_g, where ρ_g = n_g − tr(J_g N⁻¹ J_gᵀ) is the group's share of the
redundancy (N = JᵀJ, priors included). The priors are not re-weighted: they are the
builder's tolerances, not measurements of this calibration.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from scipy.linalg import LinAlgError, cho_factor, cho_solve
from scipy.sparse import csc_matrix

from cdpr_twin.calibrate.schur import arrow, inverse_parts, leverages


@dataclass(frozen=True)
class NoiseModel:
    """The measurements' noise (1σ), which weighs the residuals.

    Attributes:
        length_std: encoder length noise [m] (quantisation 2πr/N/√12 ≈ 9 µm, plus the E·S and
            tension errors in the stretch correction, ≈ 6 µm).
        tag_lateral_std: tag position noise across the optical axis at 0 m [m].
        tag_depth_std: tag position noise along the optical axis at 0 m [m].
        tag_std_per_m: growth of the lateral noise (and of the depth noise, unless
            ``tag_depth_per_m``) with the tag's distance [m per m].
        tag_rotation_std: tag orientation noise [rad].
        force_std: the force balance's residual per axis [N]; ``None``: no wrench balance.
        moment_std: the moment balance's residual per axis [N·m].
        tag_depth_per_m: growth of the depth noise with the distance [m per m]; ``None``:
            ``tag_std_per_m``.
    """

    length_std: float = 15e-6
    tag_lateral_std: float = 0.3e-3
    tag_depth_std: float = 0.5e-3
    tag_std_per_m: float = 4e-3
    tag_rotation_std: float = math.radians(0.3)
    force_std: float | None = None
    moment_std: float = 0.002
    tag_depth_per_m: float | None = None

    @property
    def depth_growth(self) -> float:
        """Growth of the depth noise with the distance [m per m] (``tag_depth_per_m`` if set)."""
        return self.tag_std_per_m if self.tag_depth_per_m is None else self.tag_depth_per_m

    def __post_init__(self) -> None:
        if self.force_std is not None and not self.force_std > 0:
            raise ValueError(f"force_std must be > 0 N (or None: no balance), got {self.force_std}")
        if not self.moment_std > 0:
            raise ValueError(f"moment_std must be > 0 N·m, got {self.moment_std}")


GROUPS = ("cable", "tag_lateral", "tag_depth", "tag_rotation", "force", "moment")
"""The residual groups whose noise is estimated."""

MIN_REDUNDANCY = 10.0
"""A group with less redundancy than this is not estimated that round (too few residuals)."""


@dataclass(frozen=True)
class Weighting:
    """How a calibration's residuals came to be weighted.

    Attributes:
        noise: the noise model of the last solve.
        rounds: per solve, each group's σ̂/σ at its solution (``None``: not estimated, its
            redundancy below :data:`MIN_REDUNDANCY`).
        settled: whether the last solve's σ̂/σ were all within the tolerance of 1.
        note: why it stopped unsettled ("" when settled).
        left_out: the poses (indices into the observations) whose tag view was left out as a
            gross error, one at a time after the first solve (``solver.GROSS_CHI2``).
    """

    noise: NoiseModel
    rounds: tuple[dict[str, float | None], ...]
    settled: bool
    note: str = ""
    left_out: tuple[int, ...] = ()


def group_rows(problem) -> dict[str, np.ndarray]:
    """Row indices of each residual group of ``problem`` (a calibrate ``Problem``).

    Returns:
        Group name → (n_g,) row indices, for the groups the problem has.
    """
    at = problem.n_cable_rows
    tag = at + np.arange(problem.n_tag_rows).reshape(-1, 6)
    at += problem.n_tag_rows
    wrench = at + np.arange(problem.n_force_rows).reshape(-1, 6)
    rows = {
        "cable": np.arange(problem.n_cable_rows),
        "tag_lateral": tag[:, :2].ravel(),
        "tag_depth": tag[:, 2],
        "tag_rotation": tag[:, 3:].ravel(),
        "force": wrench[:, :3].ravel(),
        "moment": wrench[:, 3:].ravel(),
    }
    return {g: r for g, r in rows.items() if len(r)}


def variance_factors(problem, jac: csc_matrix, r: np.ndarray) -> dict[str, float | None]:
    """Each group's variance over the one it was weighted with, at a solution.

    Args:
        problem: the calibrate ``Problem`` solved.
        jac: (n_rows, n) its Jacobian at the solution (priors included).
        r: (n_rows,) its residuals there.

    Returns:
        Group name → σ̂²/σ² (``None`` where the group's redundancy is below
        :data:`MIN_REDUNDANCY`).
    """
    h = _leverages(csc_matrix(jac), problem.layout.n_shared)
    out: dict[str, float | None] = {}
    for g, rows in group_rows(problem).items():
        redundancy = len(rows) - float(h[rows].sum())
        rg = r[rows]
        out[g] = float(rg @ rg) / redundancy if redundancy >= MIN_REDUNDANCY else None
    return out


def _leverages(J: csc_matrix, n_shared: int) -> np.ndarray:
    """Each row's J_j N⁻¹ J_jᵀ (N = JᵀJ), by the pose blocks' Schur complement where it can.

    Where N is singular (directions nothing sees: no priors) its pseudo-inverse: how those
    directions are fixed changes no residual's redundancy.
    """
    N = (J.T @ J).toarray()
    blocks = arrow(N, n_shared)
    parts = None if blocks is None else inverse_parts(blocks)
    if parts is not None:
        return leverages(J, n_shared, parts)
    try:
        N_inv = cho_solve(cho_factor(N, lower=True, check_finite=False), np.eye(len(N)))
    except LinAlgError:
        N_inv = np.linalg.pinv(N, hermitian=True)
    Jr = J.tocsr()
    return np.asarray(Jr.multiply(Jr @ N_inv).sum(axis=1)).ravel()


def rescaled(noise: NoiseModel, factors: dict[str, float]) -> NoiseModel:
    """``noise`` with each group's σ multiplied by √factor.

    The tag's lateral and depth noise each keep their shape in distance (base and growth
    scaled together); the lateral growth and the depth growth become separate.
    """
    f = {g: math.sqrt(factors.get(g, 1.0)) for g in GROUPS}
    return replace(
        noise,
        length_std=noise.length_std * f["cable"],
        tag_lateral_std=noise.tag_lateral_std * f["tag_lateral"],
        tag_std_per_m=noise.tag_std_per_m * f["tag_lateral"],
        tag_depth_std=noise.tag_depth_std * f["tag_depth"],
        tag_depth_per_m=noise.depth_growth * f["tag_depth"],
        tag_rotation_std=noise.tag_rotation_std * f["tag_rotation"],
        force_std=None if noise.force_std is None else noise.force_std * f["force"],
        moment_std=noise.moment_std * f["moment"],
    )
