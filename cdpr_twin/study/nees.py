"""Filter consistency: NEES of an estimator's covariance against the twin's ground truth.

The normalised estimation error squared of one estimate is ε = δᵀ P⁻¹ δ with δ = log(T̂⁻¹ T)
(the pose error in F_p, the convention of ``PoseEstimate.covariance``). Over N Monte Carlo runs
a consistent filter's average ε̄ at each tick has N·ε̄ ~ χ²(6N), so ε̄ lies within
[χ²₀.₀₂₅(6N), χ²₀.₉₇₅(6N)] / N with 95 % probability (Bar-Shalom, Li, Kirubarajan,
*Estimation with Applications to Tracking and Navigation*, 2001, §5.4).

>>> result = monte_carlo(scenario, "fused", runs=50)
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from cdpr_twin.math.se3 import inverse, se3_log
from cdpr_twin.robot.deviations import DeviationSpec
from cdpr_twin.run.episode import Episode
from cdpr_twin.run.runner import prepare
from cdpr_twin.scenario.loading import Scenario


@dataclass(frozen=True)
class NeesResult:
    """NEES of a Monte Carlo campaign.

    Attributes:
        times: (K,) tick times [s].
        nees: (N, K) ε of each run at each tick.
        errors: (N, K, 6) pose errors δ [m, rad].
        sigmas: (N, K, 6) the filter's standard deviations √diag(P).
    """

    times: np.ndarray
    nees: np.ndarray
    errors: np.ndarray
    sigmas: np.ndarray

    @property
    def average(self) -> np.ndarray:
        """ε̄ at each tick, averaged over runs (K,)."""
        return self.nees.mean(axis=0)

    def bounds(self, probability: float = 0.95) -> tuple[float, float]:
        """The two-sided χ² bounds of ε̄ for N runs of a 6-dof error."""
        from scipy.stats import chi2

        n, tail = self.nees.shape[0], 0.5 * (1.0 - probability)
        return chi2.ppf(tail, 6 * n) / n, chi2.ppf(1.0 - tail, 6 * n) / n


def nominal_robot(scenario: Scenario, robot_seed: int) -> Scenario:
    """The scenario on a robot built exactly to the nominal model (no geometric errors).

    The realism profile's per-robot draws (drum radii, tension-sensor bias) still come from
    ``robot_seed``.
    """
    return replace(scenario, truth=DeviationSpec(seed=int(robot_seed)))


def run_errors(scenario: Scenario, name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Run a scenario's episode and return one estimator's errors and covariances at every tick.

    Every tick of the run, from its start (tick 0) to its duration, whatever the controller
    says of being done (a run would end there) or a fault.

    Returns:
        ``(times (K,), errors (K, 6), covariances (K, 6, 6))``.
    """
    setup = prepare(scenario)
    try:
        episode = Episode(setup)
        ticks = [episode.reset()]
        for _ in range(round(scenario.duration / scenario.model.control_period)):
            ticks.append(episode.step())
    finally:
        setup.close()
    estimates = [t.estimates[name] for t in ticks]
    errors = [
        se3_log(inverse(e.T_base_platform) @ t.T_base_platform)
        for e, t in zip(estimates, ticks, strict=True)
    ]
    times = [t.time for t in ticks]
    return np.array(times), np.array(errors), np.array([e.covariance for e in estimates])


def monte_carlo(scenario: Scenario, name: str, runs: int, first_seed: int = 1) -> NeesResult:
    """NEES over ``runs`` runs on nominal robots: run seed and robot seed ``first_seed + i``.

    Args:
        scenario: the scenario (its ``name`` estimator must be among its estimators).
        name: the estimator whose covariance is checked.
        runs: number of runs N.
        first_seed: the first run's seeds.
    """
    nees, errors, sigmas, times = [], [], [], None
    for i in range(runs):
        seed = first_seed + i
        s = nominal_robot(scenario, seed).with_overrides(seed=seed)
        times, err, cov = run_errors(s, name)
        nees.append(np.einsum("ki,kij,kj->k", err, np.linalg.inv(cov), err))
        errors.append(err)
        sigmas.append(np.sqrt(np.einsum("kii->ki", cov)))
    return NeesResult(np.asarray(times), np.array(nees), np.array(errors), np.array(sigmas))
