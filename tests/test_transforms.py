"""Pose helpers: the one-quaternion fast path gives what the array path gives."""

import numpy as np
from pydrake.common.eigen_geometry import Quaternion
from pydrake.math import RotationMatrix

from corn_drake.transforms import quat_wxyz_to_matrix, rotation_angle, yaw_matrix


def test_single_quaternion_matches_the_batched_path_and_drake():
    rng = np.random.default_rng(3)
    q = rng.normal(size=(50, 4)) * rng.uniform(0.1, 10, (50, 1))  # unnormalised on purpose
    batched = quat_wxyz_to_matrix(q)
    for qi, Ri in zip(q, batched):
        single = quat_wxyz_to_matrix(qi)
        np.testing.assert_allclose(single, Ri, atol=1e-12)
        drake = RotationMatrix(Quaternion(qi / np.linalg.norm(qi))).matrix()
        np.testing.assert_allclose(single, drake, atol=1e-12)


def test_degenerate_quaternions_give_nan_as_the_array_path_does():
    assert np.isnan(quat_wxyz_to_matrix(np.zeros(4))).all()
    assert np.isnan(quat_wxyz_to_matrix(np.array([np.nan, 0.0, 0.0, 1.0]))).all()


def test_rotation_angle_of_known_rotations():
    for angle in (0.0, 0.3, 2.0, np.pi):
        assert abs(rotation_angle(yaw_matrix(angle)) - angle) < 1e-7
    assert np.isnan(rotation_angle(np.full((3, 3), np.nan)))
