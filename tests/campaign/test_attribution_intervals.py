"""The variance shares of the error at p1 have bootstrap intervals around the true shares.

Truth: a linear model in closed form. The error depends on the exit points only (Y = X_exit +
noise, both unit variance per axis), so the exit points' share of the variance is 3 / (3 + 3)
= 0.5 and every other group's is 0.
"""

import numpy as np

from cdpr_twin.campaign.report import GROUPS, attribution, attribution_intervals, attribution_nulls

M = 1
"""Cables: 9m + 18 = 27 deviation columns."""


def _population(n: int = 300) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(7)
    X = rng.normal(size=(n, 9 * M + 18))
    Y = X[:, :3] + rng.normal(size=(n, 3))
    return X, Y


def test_intervals_hold_the_true_shares_and_repeat():
    X, Y = _population()
    shares, _ = attribution(X, Y, M)
    ci = attribution_intervals(X, Y, M)
    low, high = ci["exit points"]
    assert low < 0.5 < high and low <= shares["exit points"] <= high
    # a group with no effect: its fitted share is overfit noise, about its columns / n
    for g in GROUPS[1:]:
        assert ci[g][1] < 0.1, g
    assert attribution_intervals(X, Y, M) == ci  # a seeded resampling: same numbers


def test_a_group_shared_by_every_run_has_no_interval():
    X, Y = _population()
    X[:, -6:] = 0.0  # the homing offset the same in every run
    low, high = attribution_intervals(X, Y, M)["homing offset"]
    assert np.isnan(low) and np.isnan(high)


def test_only_a_group_that_matters_is_told_apart_from_no_effect():
    # the exit points carry half the variance; the others none: their shares are fitted noise,
    # about columns / n of the unexplained half (3/300 · 0.5 = 0.005 for 3 columns)
    X, Y = _population()
    shares, _ = attribution(X, Y, M)
    null = attribution_nulls(X, Y, M)
    assert shares["exit points"] > 10 * null["exit points"]
    for g in GROUPS[1:]:
        assert 0.0 < null[g] < 0.05, g
    told = [g for g in GROUPS[1:] if shares[g] > null[g]]
    # a 95 % quantile: one null group of seven may exceed it by chance, not most
    assert len(told) <= 1, told
