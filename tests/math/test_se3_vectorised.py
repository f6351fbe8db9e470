"""SE(3) functions on one pose or a stack: against scipy, and a stack equal to its elements one by
one (the branch masks of Shepperd's method), including the branch cases near θ = π."""

import numpy as np
from scipy.spatial.transform import Rotation

from cdpr_twin.math import se3


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


def test_quaternions_of_a_stack_match_scipy_and_each_rotation_alone():
    R = _rotations()
    q = se3.quat_wxyz_from_matrix(R)
    assert q.shape == (len(R), 4) and np.all(q[:, 0] >= 0)
    ref = Rotation.from_matrix(R).as_quat()[:, [3, 0, 1, 2]]  # scipy: xyzw
    same_sign = np.minimum(np.abs(q - ref).max(axis=1), np.abs(q + ref).max(axis=1))
    assert same_sign.max() < 1e-12
    one_by_one = np.array([se3.quat_wxyz_from_matrix(r) for r in R[-300:]])
    np.testing.assert_array_equal(q[-300:], one_by_one)
    np.testing.assert_array_equal(se3.quat_xyzw_from_matrix(R), q[:, [1, 2, 3, 0]])
    # leading axes are kept, and matrices come back from the quaternions
    q2 = se3.quat_wxyz_from_matrix(R[:12].reshape(3, 4, 3, 3))
    assert q2.shape == (3, 4, 4)
    np.testing.assert_allclose(se3.matrix_from_quat_wxyz(q2).reshape(12, 3, 3), R[:12], atol=1e-15)


def test_pose_distance_of_a_stack_matches_scipy_and_each_pair_alone():
    rng = np.random.default_rng(0)
    R = _rotations()[-600:]
    Ta = np.tile(np.eye(4), (len(R), 1, 1))
    Tb = np.tile(np.eye(4), (len(R), 1, 1))
    Ta[:, :3, :3], Tb[:, :3, :3] = R, R[::-1]
    Ta[:, :3, 3], Tb[:, :3, 3] = rng.normal(size=(len(R), 3)), rng.normal(size=(len(R), 3))
    dt, dr = se3.pose_distance(Ta, Tb)
    ref = np.array([se3.pose_distance(a, b) for a, b in zip(Ta, Tb, strict=True)])
    np.testing.assert_array_equal(dt, ref[:, 0])
    np.testing.assert_array_equal(dr, ref[:, 1])
    np.testing.assert_allclose(dt, np.linalg.norm(Ta[:, :3, 3] - Tb[:, :3, 3], axis=1), rtol=1e-15)
    angle = Rotation.from_matrix(
        np.einsum("nji,njk->nik", Ta[:, :3, :3], Tb[:, :3, :3])
    ).magnitude()
    np.testing.assert_allclose(dr, angle, atol=1e-9)
    # one pose against a stack broadcasts; single poses give floats
    dt1, _ = se3.pose_distance(Ta, Tb[:1])
    assert dt1.shape == (len(R),)
    assert isinstance(se3.pose_distance(Ta[0], Tb[0])[0], float)
