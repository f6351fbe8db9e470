"""Est. 3-6, model-based: Algorithm 1 on the six most-tensioned cables (paper §III-C).

The measured lengths are the winch encoders' (unstretched) lengths, corrected for stretch
(eq. 13-14, τ(0) = 0) in the ``elastic`` variants; the model lengths are straight A_i-B_i
segments or pulley lengths (eq. 15-24). The pose is the root of the six length residuals near
the last estimate, using the *nominal* geometry, E·S and r_p (solvers:
:mod:`cdpr_twin.estimators.solvers`).

Option ``selection`` chooses the cables (:mod:`cdpr_twin.estimators.selection`):
``"most_tensioned"`` (the paper's, default), ``"best_conditioned"`` (the six taut cables with
the best-conditioned Jacobian) or ``"all_taut"`` (weighted least squares over every taut cable).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import ClassVar, Literal

import numpy as np
from scipy.optimize import least_squares

from cdpr_twin.estimators import newton
from cdpr_twin.estimators.base import (
    FEW_TAUT_CABLES,
    ILL_CONDITIONED,
    NON_FINITE_INPUT,
    NOT_CONVERGED,
    Estimator,
    SensorWatch,
)
from cdpr_twin.estimators.selection import (
    N_USED,
    SELECTIONS,
    Selection,
    best_conditioned,
    condition_number,
    length_sigma,
    most_tensioned,
)
from cdpr_twin.estimators.solvers import (
    Backend,
    PoseSolution,
    WeightedSolution,
    _cable_tuples,
    _kernel,
    _newton,
    _pose,
    gauss_newton,
    solve_fast,
    solve_scipy,
)
from cdpr_twin.math.geometry import CdprGeometry
from cdpr_twin.math.kinematics import elastic_elongation, lengths_and_jacobian
from cdpr_twin.math.se3 import matrix_from_quat_wxyz, quat_wxyz_from_matrix, transform
from cdpr_twin.options import OptionError, option
from cdpr_twin.types import Measurement, PoseEstimate

__all__ = ["ModelEstimator", "ModelOptions", "solve_fast", "solve_scipy"]


@dataclass(frozen=True)
class ModelOptions:
    """Options of the model-based estimators (Algorithm 1).

    Attributes:
        backend: ``"fast"`` (Newton on SE(3)) or ``"scipy"`` (the paper's formulation).
        taut_threshold: a cable counts as taut above this tension [N]; with fewer than six
            taut cables the estimate is held and flagged (the six would include slack ones).
        tension0: τ(0) of eq. 13, the tension at which the encoders read unstretched lengths [N].
        max_residual: a square solve is accepted when every used length matches within this
            [m]; an ``all_taut`` solve when its step converged and its residuals stay within
            ``max_residual_lsq``.
        selection: ``"most_tensioned"``, ``"best_conditioned"`` or ``"all_taut"``.
        length_noise_std: encoder error std for the ``all_taut`` weights [m].
        tension_noise_std: tension-reading error std for the ``all_taut`` weights [N].
        max_residual_lsq: largest |residual| an ``all_taut`` solution may leave [m].
        max_condition: with ``best_conditioned`` or ``all_taut``, the estimate is held and
            flagged ``ill_conditioned`` when the chosen cables' Jacobian (at the last estimate)
            has a larger condition number (ACROBOT: ≈ 19 typically, ≤ 26 along the paper's
            paths; 10³-10⁴ when only a nearly singular six are taut).
    """

    backend: Literal["fast", "scipy"] = option("fast")
    taut_threshold: float = option(1.0, minimum=0.0, unit="N")
    tension0: float = option(0.0, unit="N")
    max_residual: float = option(1e-9, minimum=1e-15, unit="m")
    selection: Literal["most_tensioned", "best_conditioned", "all_taut"] = option("most_tensioned")
    length_noise_std: float = option(1e-5, minimum=0.0, exclusive=True, unit="m")
    tension_noise_std: float = option(0.24, minimum=0.0, unit="N")
    max_residual_lsq: float = option(0.005, minimum=0.0, exclusive=True, unit="m")
    max_condition: float = option(500.0, minimum=1.0)

    def __post_init__(self) -> None:
        if self.backend not in ("fast", "scipy"):
            raise OptionError("backend", f"must be 'fast' or 'scipy', got {self.backend!r}")
        if self.selection not in SELECTIONS:
            raise OptionError("selection", f"must be one of {SELECTIONS}, got {self.selection!r}")
        for name, low in (
            ("taut_threshold", 0.0),
            ("max_residual", 1e-15),
            ("length_noise_std", 1e-12),
            ("tension_noise_std", 0.0),
            ("max_residual_lsq", 1e-12),
            ("max_condition", 1.0),
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= low):
                raise OptionError(name, f"must be a finite number ≥ {low}, got {value}")
        if not math.isfinite(self.tension0):
            raise OptionError("tension0", f"must be finite, got {self.tension0}")


class ModelEstimator(Estimator):
    """Algorithm 1: least squares on the six most-tensioned cables, warm-started.

    Args:
        geometry: nominal geometry.
        options: :class:`ModelOptions`.
    """

    Options = ModelOptions
    watches = SensorWatch.ENCODERS | SensorWatch.TENSIONS
    elastic: ClassVar[bool] = False
    pulley: ClassVar[bool] = False

    def __init__(self, geometry: CdprGeometry, options: ModelOptions | None = None) -> None:
        super().__init__(geometry, options)
        o = self.options
        self.backend: Backend = o.backend
        self.selection: Selection = o.selection
        self.taut_threshold = float(o.taut_threshold)
        self.tension0 = float(o.tension0)
        self.max_residual = float(o.max_residual)
        radii = geometry.pulley_radius if self.pulley else None
        self._cables = _cable_tuples(geometry.a_base, geometry.b_platform, radii)
        self._cable_array = np.array(self._cables)
        self._chosen: dict[tuple[int, ...], tuple[np.ndarray, np.ndarray]] = {}
        # the compiled Newton treats a zero sheave radius as a point exit: same branch only if
        # every pulley of a pulley model has a sheave
        self._compiled = self.backend == "fast" and (radii is None or bool(np.all(radii > 0)))
        if self._compiled:
            newton.warm_up()

    def corrected_lengths(self, lengths: np.ndarray, tensions: np.ndarray) -> np.ndarray:
        """Encoder lengths, plus the stretch of eq. 14 in the elastic variants. (m,) [m]."""
        if not self.elastic:
            return lengths
        return lengths + elastic_elongation(lengths, tensions, self.geometry.es, self.tension0)

    def _chosen_cables(self, cables: list[int]) -> tuple[np.ndarray, np.ndarray]:
        """The compiled Newton's (k, 7) cables and their indices (k,), built once per set."""
        key = tuple(cables)
        chosen = self._chosen.get(key)
        if chosen is None:
            index = np.array(key, dtype=np.intp)
            chosen = self._chosen[key] = (self._cable_array[index], index)
        return chosen

    def solve(self, targets: np.ndarray, cables: list[int], T0: np.ndarray) -> PoseSolution:
        """Solve for the pose matching ``targets`` on ``cables`` (indices from 0) from ``T0``."""
        if self.backend == "fast":
            if self._compiled:  # the same operations compiled; the reference where it must
                rows, index = self._chosen_cables(cables)
                goal = np.asarray(targets, dtype=float).take(index)
                T, residual, it, outcome = newton.newton(rows, goal, T0, 30, 1e-12)
                if outcome == newton.MAIN:
                    return PoseSolution(T, residual, it)
            goal = np.asarray(targets, dtype=float)[cables]
            return _newton([self._cables[i] for i in cables], self.pulley, goal, T0)
        index = np.asarray(cables)
        g = self.geometry
        r = g.pulley_radius[index] if self.pulley else None
        return solve_scipy(g.a_base[index], g.b_platform[index], r, targets[index], T0)

    def weights(self, lengths: np.ndarray, tensions: np.ndarray) -> np.ndarray:
        """Weights 1/σ_i² of every cable in the ``all_taut`` solve (m,) [1/m²]."""
        o = self.options
        sigma = length_sigma(
            lengths,
            tensions,
            self.geometry.es,
            o.length_noise_std,
            o.tension_noise_std,
            self.elastic,
        )
        return 1.0 / sigma**2

    def solve_weighted(
        self, targets, weights, cables: list[int], T0: np.ndarray
    ) -> WeightedSolution:
        """Weighted least squares over ``cables`` (any number ≥ 6) from ``T0``."""
        idx = np.asarray(cables)
        if self.backend == "fast":
            chosen = [self._cables[i] for i in cables]
            return gauss_newton(chosen, self.pulley, targets[idx], weights[idx], T0)
        g, sw = self.geometry, np.sqrt(weights[idx])
        radii = g.pulley_radius[idx] if self.pulley else None

        def residuals(x: np.ndarray) -> np.ndarray:
            T = transform(matrix_from_quat_wxyz(x[3:]), x[:3])
            lengths, _ = lengths_and_jacobian(g.a_base[idx], g.b_platform[idx], radii, T)
            return np.append(sw * (lengths - targets[idx]), 1e6 * (x[3:] @ x[3:] - 1.0))

        x0 = np.concatenate([T0[:3, 3], quat_wxyz_from_matrix(T0[:3, :3])])
        sol = least_squares(residuals, x0, method="trf", xtol=1e-15, ftol=1e-15, gtol=1e-15)
        T = transform(matrix_from_quat_wxyz(sol.x[3:]), sol.x[:3])
        return WeightedSolution(T, sol.fun[:-1] / sw, int(sol.nfev), bool(sol.success))

    def choose(self, tensions: np.ndarray, taut: np.ndarray) -> tuple[list[int], float]:
        """The cables this update solves on (indices from 0, sorted), by ``selection``.

        Returns:
            ``(cables, condition)``: the cables, and their Jacobian's condition number at the
            last estimate.
        """
        rows = np.asarray(_kernel(self._cables, self.pulley, _pose(self._T))[1])
        cables: list[int]
        if self.selection == "all_taut":
            cables = np.asarray(taut).nonzero()[0].tolist()
        else:
            cables = best_conditioned(rows, tensions, taut)
        return cables, condition_number(rows[cables])

    def _step(
        self,
        measurement: Measurement,
        inputs: Mapping[str, PoseEstimate],
        watch_flags: frozenset[str],
    ) -> PoseEstimate:
        """One pass of Algorithm 1's loop (lines 7-12), with the chosen cable selection."""
        m = measurement
        lengths, tensions = m.cable_lengths, m.tensions
        # Python floats (the tensions are ranked as such too); NaN and inf propagate to the sum
        tl = tensions.tolist()
        if not math.isfinite(sum(lengths.tolist()) + sum(tl)):
            return self._held(m, NON_FINITE_INPUT)
        if self.selection != "most_tensioned":
            return self._update_selected(m, lengths, tensions, watch_flags)
        cables = most_tensioned(tl)  # line 8
        used = tuple(cables)
        taut = 0
        for t in tl:  # (a loop, not a generator: the hot path)
            taut += t > self.taut_threshold
        if taut < N_USED:
            return self._held(m, FEW_TAUT_CABLES, cables=used)
        targets = self.corrected_lengths(lengths, tensions)
        solution = self.solve(targets, cables, self._T)
        T, residual, iterations = solution.T, solution.residual, solution.iterations
        # (NaN and inf propagate to the sum of the pose's sixteen Python floats)
        if not (residual <= self.max_residual and math.isfinite(sum(T.ravel().tolist()))):
            return self._held(
                m,
                NOT_CONVERGED,
                *watch_flags,
                cables=used,
                residual=residual,
                iterations=iterations,
            )
        self._T = T
        self._time = m.time
        return PoseEstimate(
            m.time, T, flags=watch_flags, cables=used, residual=residual, iterations=iterations
        )

    def _update_selected(
        self, m: Measurement, lengths: np.ndarray, tensions: np.ndarray, watch_flags: frozenset[str]
    ) -> PoseEstimate:
        """:meth:`_step` for ``best_conditioned`` and ``all_taut``.

        ``watch_flags``: the flags of the watches, carried by a solved or unconverged estimate.
        """
        taut = tensions > self.taut_threshold
        if taut.sum() < N_USED:
            return self._held(m, FEW_TAUT_CABLES, cables=tuple(taut.nonzero()[0].tolist()))
        cables, condition = self.choose(tensions, taut)
        used = tuple(cables)
        if not condition <= self.options.max_condition:
            return self._held(m, ILL_CONDITIONED, cables=used)
        targets = self.corrected_lengths(lengths, tensions)
        if self.selection == "all_taut":
            w = self.weights(lengths, tensions)
            fit = self.solve_weighted(targets, w, cables, self._T)
            T, residual, iterations = fit.T, fit.largest_residual, fit.iterations
            ok = fit.converged and residual <= self.options.max_residual_lsq
        else:
            solution = self.solve(targets, cables, self._T)
            T, residual, iterations = solution.T, solution.residual, solution.iterations
            ok = residual <= self.max_residual
        if not (ok and math.isfinite(np.add.reduce(T, axis=None))):
            return self._held(
                m,
                NOT_CONVERGED,
                *watch_flags,
                cables=used,
                residual=residual,
                iterations=iterations,
            )
        self._T = T
        self._time = m.time
        return PoseEstimate(
            m.time, T, flags=watch_flags, cables=used, residual=residual, iterations=iterations
        )


class SimpleModelEstimator(ModelEstimator):
    """Est. 3: massless, inextensible, straight cables from A_i to B_i."""

    name = "model_simple"


class ElasticModelEstimator(ModelEstimator):
    """Est. 4: straight cables, lengths corrected for elastic stretch (eq. 13-14)."""

    name = "model_elastic"
    elastic = True


class PulleyModelEstimator(ModelEstimator):
    """Est. 5: inextensible cables over swivelling pulleys (eq. 15-24)."""

    name = "model_pulley"
    pulley = True


class ElasticPulleyModelEstimator(ModelEstimator):
    """Est. 6: pulleys and stretch together (eq. 25)."""

    name = "model_elastic_pulley"
    elastic = True
    pulley = True
