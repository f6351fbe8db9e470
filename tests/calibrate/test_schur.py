"""The pose blocks' Schur complement against dense linear algebra on the same normal matrix."""

import numpy as np
import pytest
from scipy.sparse import coo_matrix, csc_matrix

from cdpr_twin.calibrate.normal_equations import shared_covariance
from cdpr_twin.calibrate.schur import arrow, damped_step, inverse_parts, leverages

S, K = 7, 5  # shared unknowns, poses


def _arrow_jacobian(seed: int = 0, couple: bool = False) -> np.ndarray:
    """Rows each seeing the shared unknowns and one pose (a few: the shared ones only)."""
    rng = np.random.default_rng(seed)
    rows = []
    for k in range(K):
        for _ in range(9):
            row = np.zeros(S + 6 * K)
            row[:S] = rng.normal(size=S) * (rng.random(S) < 0.6)
            row[S + 6 * k : S + 6 * k + 6] = rng.normal(size=6)
            rows.append(row)
    rows += list(np.hstack([np.eye(S), np.zeros((S, 6 * K))]) * 0.5)  # priors on shared
    J = np.array(rows)
    if couple:  # one row seeing two poses
        J[0, S + 6 : S + 12] = 1.0
    return J


def test_a_damped_step_is_the_dense_solution():
    J = _arrow_jacobian()
    N, g = J.T @ J, J.T @ np.random.default_rng(1).normal(size=len(J))
    damping = 1e-3 * np.diag(N)
    step = damped_step(arrow(N, S), g, damping)
    np.testing.assert_allclose(step, -np.linalg.solve(N + np.diag(damping), g), rtol=1e-9)


def test_the_shared_inverse_and_each_rows_leverage_are_the_dense_ones():
    J = _arrow_jacobian(seed=2)
    N = J.T @ J
    N_inv = np.linalg.inv(N)
    parts = inverse_parts(arrow(N, S))
    np.testing.assert_allclose(parts.S_inv, N_inv[:S, :S], rtol=1e-9, atol=1e-12)
    h = leverages(csc_matrix(J), S, parts)
    np.testing.assert_allclose(h, np.einsum("ij,jk,ik->i", J, N_inv, J), rtol=1e-9, atol=1e-12)
    # the leverages sum to the unknowns' count (the trace of the hat matrix)
    assert h.sum() == pytest.approx(S + 6 * K, rel=1e-9)
    np.testing.assert_allclose(
        shared_covariance(csc_matrix(J), S, 2.0), 2.0 * N_inv[:S, :S], rtol=1e-9, atol=1e-12
    )


def test_a_matrix_coupling_two_poses_is_not_an_arrow():
    N = (lambda J: J.T @ J)(_arrow_jacobian(couple=True))
    assert arrow(N, S) is None
    assert arrow(N[: S + 6 * K - 3, : S + 6 * K - 3], S) is None  # not whole pose blocks


def test_a_singular_pose_block_is_reported_not_solved():
    J = _arrow_jacobian(seed=3)
    J[:, S + 6 * 2 + 4] = 0.0  # nothing sees pose 2's fifth unknown
    N = J.T @ J
    assert damped_step(arrow(N, S), np.ones(len(N)), np.zeros(len(N))) is None
    assert inverse_parts(arrow(N, S)) is None
    assert damped_step(arrow(N, S), np.ones(len(N)), 1e-6 * np.ones(len(N))) is not None


def test_a_stored_zero_in_another_poses_column_does_not_move_a_leverage():
    J = _arrow_jacobian(seed=4)
    N_inv = np.linalg.inv(J.T @ J)
    rows, cols = np.nonzero(J)  # and an entry of pose 3 in a row of pose 0, stored as a zero
    rows, cols = np.append(rows, 0), np.append(cols, S + 6 * 3)
    sparse = coo_matrix((np.append(J[np.nonzero(J)], 0.0), (rows, cols)), shape=J.shape).tocsc()
    assert sparse[:, S + 6 * 3].nnz > np.count_nonzero(J[:, S + 6 * 3])
    h = leverages(sparse, S, inverse_parts(arrow(J.T @ J, S)))
    np.testing.assert_allclose(h, np.einsum("ij,jk,ik->i", J, N_inv, J), rtol=1e-9, atol=1e-12)
