"""The vectorised SE(3) helpers (used for every logged deviation and quaternion) against the
scalar ones and scipy, including the branch cases near θ = π."""

import numpy as np
from scipy.spatial.transform import Rotation

from cdpr_twin import se3


def _rotations():
    R = Rotation.random(3000, random_state=4).as_matrix()
    special = Rotation.from_rotvec(
        [
            [np.pi - 1e-9, 0, 0],
            [0, np.pi, 0],
            [0, 0, np.pi],
            [0, 0, 0],
            [1e-9, 0, 0],
            [2.0, 1.0, -0.5],
        ]
    ).as_matrix()
    return np.concatenate([R, special])


def test_quat_xyzw_from_matrices_matches_scipy_and_the_scalar_version():
    R = _rotations()
    q = se3.quat_xyzw_from_matrices(R)
    ref = Rotation.from_matrix(R).as_quat()  # xyzw
    same_sign = np.minimum(np.abs(q - ref).max(axis=1), np.abs(q + ref).max(axis=1))
    assert same_sign.max() < 1e-12
    scalar = np.array([se3.quat_wxyz_from_matrix(r)[[1, 2, 3, 0]] for r in R[:200]])
    assert (
        np.minimum(np.abs(q[:200] - scalar).max(1), np.abs(q[:200] + scalar).max(1)).max() < 1e-12
    )


def test_pose_distances_matches_pose_distance():
    rng = np.random.default_rng(0)
    R = _rotations()[-600:]
    Ta = np.tile(np.eye(4), (len(R), 1, 1))
    Tb = np.tile(np.eye(4), (len(R), 1, 1))
    Ta[:, :3, :3], Tb[:, :3, :3] = R, R[::-1]
    Ta[:, :3, 3], Tb[:, :3, 3] = rng.normal(size=(len(R), 3)), rng.normal(size=(len(R), 3))
    dt, dr = se3.pose_distances(Ta, Tb)
    ref = np.array([se3.pose_distance(a, b) for a, b in zip(Ta, Tb, strict=True)])
    np.testing.assert_allclose(dt, ref[:, 0], atol=1e-15)
    np.testing.assert_allclose(dr, ref[:, 1], atol=1e-12)
    # and against the rotation angle from scipy
    angle = Rotation.from_matrix(
        np.einsum("nji,njk->nik", Ta[:, :3, :3], Tb[:, :3, :3])
    ).magnitude()
    np.testing.assert_allclose(dr, angle, atol=1e-9)
