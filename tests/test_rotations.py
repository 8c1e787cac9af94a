"""Rotation representations and the grasp vector: round trips and rejection of non-rotations."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from ohra import GraspError
from ohra.rotations import (check_grasps, grasp_to_pose, matrix_to_quat, matrix_to_rot6d, pose_to_grasp, quat_to_matrix,
                            rot6d_to_matrix)


def test_rot6d_round_trip_is_exact_for_rotations():
    R = Rotation.random(50, random_state=0).as_matrix()
    assert np.allclose(rot6d_to_matrix(matrix_to_rot6d(R)), R, atol=1e-12)


def test_rot6d_is_the_first_two_columns():
    R = Rotation.random(random_state=1).as_matrix()
    assert np.array_equal(matrix_to_rot6d(R), np.concatenate([R[:, 0], R[:, 1]]))


def test_gram_schmidt_orthonormalises_a_perturbed_6d_vector():
    r6 = matrix_to_rot6d(Rotation.random(random_state=2).as_matrix()) + 0.05 * np.random.default_rng(0).normal(size=6)
    R = rot6d_to_matrix(r6)
    assert np.allclose(R.T @ R, np.eye(3), atol=1e-12) and np.linalg.det(R) == pytest.approx(1.0)
    assert np.allclose(R[:, 0], r6[:3] / np.linalg.norm(r6[:3]))  # the first column keeps its direction


def test_quaternions_are_xyzw():
    R = Rotation.from_euler("z", 90, degrees=True).as_matrix()
    assert np.allclose(matrix_to_quat(R), [0, 0, np.sqrt(0.5), np.sqrt(0.5)])
    assert np.allclose(quat_to_matrix(matrix_to_quat(R)), R)


def test_grasp_vector_round_trip():
    T = np.eye(4)
    T[:3, :3] = Rotation.random(random_state=3).as_matrix()
    T[:3, 3] = [0.1, -0.2, 0.3]
    q = np.linspace(-1, 1, 22)
    g = pose_to_grasp(T, q)
    assert g.shape == (31,)
    T2, q2 = grasp_to_pose(g)
    assert np.allclose(T2, T) and np.array_equal(q2, q)


@pytest.mark.parametrize("r6, match", [(np.zeros(6), "zero"), (np.array([1.0, 0, 0, 2.0, 0, 0]), "parallel")])
def test_non_rotations_are_rejected(r6, match):
    with pytest.raises(GraspError, match=match):
        rot6d_to_matrix(r6)
    g = np.zeros((2, 31))
    g[:, 3:9] = [1, 0, 0, 0, 1, 0]
    g[1, 3:9] = r6
    with pytest.raises(GraspError, match="grasp 1"):
        check_grasps(g)


def test_a_grasp_of_the_wrong_length_is_named_as_such():
    with pytest.raises(GraspError, match=r"a grasp is 31 numbers .* got shape \(30,\)"):
        grasp_to_pose(np.zeros(30))
    T, q = grasp_to_pose(np.concatenate([np.zeros(3), [1, 0, 0, 0, 1, 0], np.zeros(22)]))
    assert np.allclose(T, np.eye(4)) and q.shape == (22,)
