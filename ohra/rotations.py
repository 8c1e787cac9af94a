"""Rotation representations used by grasps: 6-D (first two matrix columns), quaternions (xyzw).

A grasp is the 31-vector ``[t(3), rot6d(6), q(22)]``: the canonical palm frame in the object frame
(metres) and the canonical joint angles (radians).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from ohra.errors import GraspError

GRASP_DIM = 31


def matrix_to_rot6d(R: np.ndarray) -> np.ndarray:
    """(...,3,3) -> (...,6): the first two columns ``[R00, R10, R20, R01, R11, R21]``."""
    R = np.asarray(R, dtype=float)
    return np.concatenate([R[..., :, 0], R[..., :, 1]], axis=-1)


def rot6d_to_matrix(r6: np.ndarray, tol: float = 1e-6) -> np.ndarray:
    """(...,6) -> (...,3,3) by Gram-Schmidt on the two columns.

    Raises :class:`GraspError` when a column is (near) zero or the two are (near) parallel: such a
    vector names no rotation.
    """
    r6 = np.asarray(r6, dtype=float)
    a, b = r6[..., 0:3], r6[..., 3:6]
    na = np.linalg.norm(a, axis=-1)
    if np.any(na < tol):
        raise GraspError("rot6d first column is zero: not a rotation")
    x = a / na[..., None]
    b = b - (x * b).sum(-1, keepdims=True) * x
    nb = np.linalg.norm(b, axis=-1)
    if np.any(nb < tol):
        raise GraspError("rot6d columns are parallel: not a rotation")
    y = b / nb[..., None]
    z = np.cross(x, y)
    return np.stack([x, y, z], axis=-1)


def pose_to_matrix(t: np.ndarray, R: np.ndarray) -> np.ndarray:
    T = np.zeros(np.shape(t)[:-1] + (4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = t
    T[..., 3, 3] = 1.0
    return T


def grasp_to_pose(g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(...,31) grasps -> ((...,4,4) palm pose in the object frame, (...,22) joints)."""
    g = np.asarray(g, dtype=float)
    if g.ndim == 0 or g.shape[-1] != 31:
        raise GraspError(f"a grasp is 31 numbers (palm position [m] 3, rot6d 6, joints 22), got shape {g.shape}")
    return pose_to_matrix(g[..., :3], rot6d_to_matrix(g[..., 3:9])), g[..., 9:]


def pose_to_grasp(T: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Palm pose(s) in the object frame and joints -> (...,31) grasps."""
    T = np.asarray(T, dtype=float)
    return np.concatenate([T[..., :3, 3], matrix_to_rot6d(T[..., :3, :3]), np.asarray(q, dtype=float)], axis=-1)


def matrix_to_quat(R: np.ndarray) -> np.ndarray:
    """(...,3,3) -> (...,4) quaternion xyzw."""
    return Rotation.from_matrix(np.asarray(R, dtype=float)).as_quat()


def quat_to_matrix(qxyzw: np.ndarray) -> np.ndarray:
    return Rotation.from_quat(np.asarray(qxyzw, dtype=float)).as_matrix()


def check_grasps(grasps: np.ndarray) -> np.ndarray:
    """Validate an (N,31) grasp array (shape, finite values, valid rotations); returns float64."""
    try:
        g = np.asarray(grasps, dtype=float)
    except (TypeError, ValueError):
        raise GraspError("grasps must be a numeric array of shape (N, 31)") from None
    if g.ndim == 1 and g.shape[0] == GRASP_DIM:
        g = g[None]
    if g.ndim != 2 or g.shape[1] != GRASP_DIM:
        raise GraspError(f"grasps must have shape (N, {GRASP_DIM}) = [t(3), rot6d(6), q(22)], got {g.shape}")
    bad = np.flatnonzero(~np.isfinite(g).all(axis=1))
    if bad.size:
        raise GraspError(f"grasp {int(bad[0])} contains NaN or inf")
    for i in range(len(g)):
        try:
            rot6d_to_matrix(g[i, 3:9])
        except GraspError as exc:
            raise GraspError(f"grasp {i}: {exc}") from None
    return g
