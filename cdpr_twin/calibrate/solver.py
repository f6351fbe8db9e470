"""Solve a calibration :class:`~cdpr_twin.calibrate.problem.Problem`; uncertainty and rank.

Levenberg–Marquardt on the normal equations (:mod:`cdpr_twin.calibrate.normal_equations`),
whose Jacobian uses the problem's analytic sparsity pattern, part by part
(:class:`~cdpr_twin.calibrate.jacobian.PartJacobian`): each pose's residuals depend on its own
six parameters and the shared ones, and each cable's length residuals on that cable's shared
parameters only. scipy's ``least_squares`` was the solver before: its exact trust-region steps
take an SVD of the whole Jacobian per iteration (112 s at 240 poses), and its sparse route
(LSMR steps) stalled on this problem (seed 19, 24 poses: cost 22.13 after 200 evaluations,
against 20.90 in 14 with exact steps); a test holds the two to the same minimum.

:func:`solve_weighted` solves again with each residual group's noise re-estimated from its own
residuals (variance components, :mod:`cdpr_twin.calibrate.variance`), which is what
:func:`cdpr_twin.calibrate.pipeline.calibrate` does.

Uncertainty: the covariance (JᵀJ)⁻¹ at the solution, scaled by the residuals' variance
χ²/(n − p). Identifiability: the singular values of the *data's* Jacobian (priors left out),
columns scaled by each parameter's prior σ (so that millimetres and degrees compare), from the
eigenvalues of its normal matrix; a direction with a singular value below ``rank_tol`` × the
largest is one the data cannot see — the report names the parameters it moves. The posterior σ
of a shared parameter that stays above half its prior σ is decided by the prior, not by the
data.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np
from scipy.sparse import csc_matrix, diags
from threadpoolctl import threadpool_limits

from cdpr_twin.calibrate.normal_equations import Solution, levenberg_marquardt, shared_covariance
from cdpr_twin.calibrate.problem import Model, Problem
from cdpr_twin.calibrate.variance import Weighting, rescaled, variance_factors

MIN_VARIANCE_RATIO = 1e-4
"""A group's σ is not lowered below 1 % of the one it was told (noise-free readings, as in the
``ideal`` profile, would otherwise weigh it without bound)."""

DAMPING = (1e-6, 1e-8)
"""Levenberg–Marquardt's starting damping (Marquardt's scaling) from the nominal model, and
from the previous solve when only the weights changed. The residuals are nearly linear in
the unknowns within the builder's tolerances, so Gauss–Newton's steps are the right ones; a
textbook start (λ = 1e-3, shrinking at most 3× per step) damps the directions that only the
priors hold (the frame's gauge) for many steps (robot 1, 240 poses, three solves: 45 steps
in 25 s against 13 in 9 s; the exit points agree within 0.01 µm). Steps that do not lower the cost
are still rejected and λ raised, and λ shrinks up to 10× per accepted step."""

GROSS_CHI2 = 22.46
"""A tag view whose squared normalised residual exceeds this after the first solve is a gross
error, left out (χ² with 6 degrees of freedom at 0.1 % false alarms, under the starting noise
model, an upper bound: in a calibration with an earlier drive, robot 1 read one view 86° off the
truth, its 4 frames alike, whose 86 σ inflated the tags' rotation noise 3.9× and put the exit
points 1.08 mm out of shape, 0.72 mm once left out). One at a time, the worst first, each
followed by a solve: a gross error pulls the solution and spreads residuals onto honest views
(Baarda's data snooping)."""

MAX_GROSS = 10
"""Most tag views left out as gross errors."""

POSE_SCALE = 0.01
"""The scale of a pose correction in the rank analysis: 1 cm, 0.01 rad."""


class CalibrationError(RuntimeError):
    """The calibration cannot be solved (one line: what happened, and what to do)."""


@dataclass(frozen=True, eq=False)
class Identifiability:
    """What the data determine.

    Attributes:
        rank: numerical rank of the data Jacobian (priors left out).
        n_params: number of parameters (shared and poses).
        singular_values: (n_params,) of the scaled data Jacobian, descending, relative to the
            largest.
        tolerance: the relative singular value below which a direction counts as unseen.
        null_directions: per unseen direction, the shared parameters it moves most, as
            (name, component) pairs (components of a unit vector in prior-σ units), and the
            share of the direction in the shared parameters (the rest moves the poses).
        prior_determined: names of shared parameters whose posterior σ exceeds half their
            prior σ (the data barely inform them).
    """

    rank: int
    n_params: int
    singular_values: np.ndarray
    tolerance: float
    null_directions: list[dict]
    prior_determined: list[str]


@dataclass(frozen=True, eq=False)
class Calibration:
    """A solved calibration.

    Attributes:
        model: the estimated robot and poses.
        x: (n,) the parameter vector at the solution.
        names: a name per shared parameter.
        estimate: (n_shared,) shared corrections (exit/anchor [m], offset [m], scale [-],
            tension_bias [N], tension_gain [-], camera/tag twists [m, rad], intrinsics).
        sigma: (n_shared,) their 1σ uncertainty (same units).
        prior_sigma: (n_shared,) their prior σ.
        chi2: weighted residual sum of squares of the data (priors left out).
        n_data: number of data residuals.
        dof: residuals (priors included) minus parameters.
        rms_cable: RMS cable residual [m].
        rms_tag: (2,) RMS tag position residual [m] and rotation residual [rad] (nan: no tag).
        nfev: residual evaluations.
        wall_time: solve time [s].
        identifiability: the rank analysis.
    """

    model: Model
    x: np.ndarray
    names: list[str]
    estimate: np.ndarray
    sigma: np.ndarray
    prior_sigma: np.ndarray
    chi2: float
    n_data: int
    dof: int
    rms_cable: float
    rms_tag: np.ndarray
    nfev: int
    wall_time: float
    identifiability: Identifiability


def solve(problem: Problem, max_iterations: int = 100, rank_tol: float = 1e-6) -> Calibration:
    """Solve the calibration.

    Args:
        problem: the residuals.
        max_iterations: most Levenberg–Marquardt steps.
        rank_tol: relative singular value below which the data do not see a direction.

    Raises:
        CalibrationError: too little data, or the solver did not converge.
    """
    started = time.perf_counter()
    res = _minimise(problem, max_iterations, None)
    with threadpool_limits(limits=1, user_api="blas"):
        return _result(problem, res, time.perf_counter() - started, rank_tol)


def solve_weighted(
    problem: Problem,
    rounds: int = 3,
    tol: float = 0.05,
    max_iterations: int = 100,
    rank_tol: float = 1e-6,
) -> tuple[Calibration, Weighting]:
    """Solve, estimate each residual group's noise from its residuals, solve again.

    Variance components (:mod:`cdpr_twin.calibrate.variance`): after each solve every
    group's σ is rescaled to its own scatter and the problem solved again from where it
    stopped, until no group's σ̂/σ differs from 1 by ``tol`` or more, or after ``rounds``
    re-solves. A re-solve that fails keeps the solve before it (and says so).

    Args:
        problem: the residuals, weighted with the noise model to start from.
        rounds: most re-solves.
        tol: relative change of every σ below which the weights count as settled.
        max_iterations: most Levenberg–Marquardt steps per solve.
        rank_tol: see :func:`solve`.

    Returns:
        The calibration (solved with the last weights; ``nfev`` and ``wall_time`` over every
        solve), and how it was weighted.

    Raises:
        CalibrationError: the first solve fails (as :func:`solve`).
    """
    started, told = time.perf_counter(), problem.noise
    res = _minimise(problem, max_iterations, None)
    total: dict = {}
    nfev, history, settled, note = res.nfev, [], False, ""
    pruned = _leave_out_gross_views(problem, res, max_iterations)
    problem, res, gross = pruned.problem, pruned.solution, pruned.left_out
    nfev += pruned.evaluations
    for k in range(rounds + 1):
        with threadpool_limits(limits=1, user_api="blas"):
            factors = variance_factors(problem, res.jac, res.fun)
        history.append(
            {g: None if v is None else round(math.sqrt(v), 4) for g, v in factors.items()}
        )
        seen = {g: v for g, v in factors.items() if v is not None}
        if all(abs(math.sqrt(v) - 1.0) < tol for v in seen.values()):
            settled = True
            break
        if k == rounds:
            note = f"σ̂/σ still beyond 1 ± {tol} after {rounds} re-solves"
            break
        total |= {g: max(total.get(g, 1.0) * v, MIN_VARIANCE_RATIO) for g, v in seen.items()}
        trial = problem.with_noise(rescaled(told, total))
        try:
            res, problem = _minimise(trial, max_iterations, res.x), trial
        except CalibrationError as exc:
            note = f"re-solve {k + 1} failed ({exc}); the solve before it is kept"
            break
        nfev += res.nfev
    with threadpool_limits(limits=1, user_api="blas"):
        cal = _result(problem, res, time.perf_counter() - started, rank_tol)
    weighting = Weighting(problem.noise, tuple(history), settled, note, tuple(sorted(gross)))
    return replace(cal, nfev=nfev), weighting


@dataclass(frozen=True, eq=False)
class _Pruned:
    """A problem's solve once its gross tag views are left out.

    Attributes:
        problem: the problem without those views.
        solution: its solution.
        left_out: the poses whose views were left out, in the order they went.
        evaluations: the residual evaluations the re-solves took.
    """

    problem: Problem
    solution: Solution
    left_out: list[int]
    evaluations: int


def _leave_out_gross_views(problem: Problem, res: Solution, max_iterations: int) -> _Pruned:
    """Leave out the tag views beyond :data:`GROSS_CHI2`, the worst first, solving after each.

    A wrong view pulls the frame and inflates the tags' noise, and smears its error onto
    honest views: one at a time.
    """
    gross: list[int] = []
    nfev = 0
    while len(gross) < MAX_GROSS and len(errors := _tag_errors(problem, res.fun)):
        if errors.max() <= GROSS_CHI2:
            break
        gross.append(int(problem.seen[np.argmax(errors)]))
        problem = problem.without_views(gross[-1:])
        res = _minimise(problem, max_iterations, res.x)
        nfev += res.nfev
    return _Pruned(problem, res, gross, nfev)


def _tag_errors(problem: Problem, r: np.ndarray) -> np.ndarray:
    """Each tag view's squared normalised residual, from the residuals ``r``: (n_seen,)."""
    tags = r[problem.n_cable_rows : problem.n_cable_rows + problem.n_tag_rows].reshape(-1, 6)
    return np.einsum("ij,ij->i", tags, tags)


def _minimise(problem: Problem, max_iterations: int, x0: np.ndarray | None) -> Solution:
    """Levenberg–Marquardt on ``problem`` from ``x0`` (zeros if None); the raw solution."""
    L = problem.layout
    if problem.n_data + problem.n_prior < L.n:
        raise CalibrationError(
            f"{problem.n_data} measurements for {L.n} unknowns: record more poses (--poses)"
        )
    pattern = problem.pattern()
    # One BLAS thread: the factorisations are small enough, a loaded machine (calibrations
    # side by side) makes threaded BLAS spin 10× slower, and the rounding then does not
    # depend on the core count.
    with threadpool_limits(limits=1, user_api="blas"):
        unseen = np.flatnonzero(np.diff(pattern.indptr) == 0)
        if len(unseen):
            names = [*L.names(), *(f"pose{k}" for k in range(L.n_poses) for _ in range(6))]
            raise CalibrationError(
                f"no measurement or prior sees {names[unseen[0]]} ({len(unseen)} parameters); "
                "keep the priors on, or record poses where the tag is seen"
            )
        res = levenberg_marquardt(
            problem.residuals,
            problem.jacobian(),
            np.zeros(L.n) if x0 is None else np.asarray(x0, dtype=float),
            max_iterations=max_iterations,
            lam0=DAMPING[x0 is not None],
            shrink=0.1,
            n_shared=L.n_shared,
        )
    if not res.converged or not np.all(np.isfinite(res.x)):
        raise CalibrationError(
            f"the solver did not converge ({res.message}); record more poses, or raise "
            "max_iterations"
        )
    return res


def _result(problem: Problem, res, wall: float, rank_tol: float) -> Calibration:
    L = problem.layout
    r = res.fun
    n_rows = len(r)
    dof = max(n_rows - L.n, 1)
    s2 = float(r @ r) / dof
    sigma = np.sqrt(np.maximum(np.diag(shared_covariance(res.jac, L.n_shared, s2)), 0.0))
    data = r[: problem.n_data]
    cab = data[: problem.n_cable_rows] * problem.noise.length_std
    rms_tag = np.full(2, np.nan)
    if problem.n_tag_rows:
        rms_tag = _tag_rms(problem, problem.model(res.x))
    ident = identifiability(problem, res.jac[: problem.n_data], sigma, rank_tol)
    return Calibration(
        model=problem.model(res.x),
        x=res.x,
        names=L.names(),
        estimate=res.x[: L.n_shared],
        sigma=sigma,
        prior_sigma=L.sigma,
        chi2=float(data @ data),
        n_data=problem.n_data,
        dof=dof,
        rms_cable=float(np.sqrt(np.mean(cab**2))) if len(cab) else float("nan"),
        rms_tag=rms_tag,
        nfev=int(res.nfev),
        wall_time=wall,
        identifiability=ident,
    )


def _tag_rms(problem: Problem, model: Model) -> np.ndarray:
    """RMS tag position [m] and rotation [rad] residuals at the solution. Returns (2,)."""
    from cdpr_twin.math.se3 import pose_distance

    pred = problem.predicted_tags(model)  # the prediction the solver fitted
    dt, dr = pose_distance(pred, problem.obs.T_cam_tag[problem.seen])
    return np.array([np.sqrt(np.mean(dt**2)), np.sqrt(np.mean(dr**2))])


def identifiability(
    problem: Problem, J_data, sigma: np.ndarray, rank_tol: float = 1e-6
) -> Identifiability:
    """The rank of the data Jacobian and the directions it does not see.

    The scaled Jacobian's singular values and right singular vectors are the square roots
    and eigenvectors of its normal matrix (n × n, where the Jacobian has several times more
    rows); singular values below ≈ 1e-8 of the largest come out as rounding noise, far below
    any useful ``rank_tol``.

    Args:
        problem: the problem (its layout names the parameters).
        J_data: (n_data, n) Jacobian of the data residuals at the solution (dense or sparse).
        sigma: (n_shared,) posterior σ of the shared parameters.
        rank_tol: relative singular value below which a direction is unseen.
    """
    L = problem.layout
    scale = np.concatenate([L.sigma, np.full(6 * L.n_poses, POSE_SCALE)])
    Js = csc_matrix(J_data) @ diags(scale)
    eigenvalues, V = np.linalg.eigh((Js.T @ Js).toarray())
    order = np.argsort(-eigenvalues)
    s_full = np.sqrt(np.maximum(eigenvalues[order], 0.0))
    Vt = V[:, order].T
    rel = s_full / max(s_full[0], 1e-300)
    rank = int(np.sum(rel > rank_tol))
    names, null = L.names(), []
    for v in Vt[rank:]:
        shared = v[: L.n_shared]
        top = np.argsort(-np.abs(shared))[:6]
        null.append(
            {
                "shared_fraction": float(shared @ shared),
                "moves": [(names[j], round(float(shared[j]), 3)) for j in top],
            }
        )
    prior = [n for n, sp, sq in zip(names, sigma, L.sigma, strict=True) if sp > 0.5 * sq]
    return Identifiability(rank, L.n, rel, rank_tol, null, prior)
