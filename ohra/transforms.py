"""Rigid transforms: fixed-axis rpy (URDF / scipy ``"xyz"``) and 4x4 homogeneous matrices."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation


def rpy_to_matrix(rpy: np.ndarray) -> np.ndarray:
    """Rotation matrix ``Rz(yaw) @ Ry(pitch) @ Rx(roll)`` of URDF fixed-axis rpy; (...,3) -> (...,3,3)."""
    return Rotation.from_euler("xyz", np.asarray(rpy, dtype=float)).as_matrix()


def matrix_to_rpy(R: np.ndarray) -> np.ndarray:
    """Fixed-axis rpy of a rotation matrix; (...,3,3) -> (...,3)."""
    return Rotation.from_matrix(np.asarray(R, dtype=float)).as_euler("xyz")


def inverse_rpy(rpy: np.ndarray) -> np.ndarray:
    """The rpy of the inverse rotation (equals ``-rpy`` only when a single component is non-zero)."""
    rpy = np.asarray(rpy, dtype=float)
    if np.count_nonzero(rpy) <= 1:
        return -rpy + 0.0  # exact, and keeps zeros as +0.0
    return matrix_to_rpy(rpy_to_matrix(rpy).T)


def xyzrpy_to_matrix(xyzrpy: np.ndarray) -> np.ndarray:
    """4x4 transform from ``[x, y, z, roll, pitch, yaw]`` (metres, radians, fixed-axis)."""
    v = np.asarray(xyzrpy, dtype=float)
    T = np.eye(4)
    T[:3, :3] = rpy_to_matrix(v[3:6])
    T[:3, 3] = v[:3]
    return T


def matrix_to_xyzrpy(T: np.ndarray) -> np.ndarray:
    """``[x, y, z, roll, pitch, yaw]`` of a 4x4 transform."""
    T = np.asarray(T, dtype=float)
    return np.concatenate([T[:3, 3], matrix_to_rpy(T[:3, :3])])


def invert(T: np.ndarray) -> np.ndarray:
    """Inverse of a (...,4,4) rigid transform."""
    T = np.asarray(T, dtype=float)
    out = np.zeros_like(T)
    Rt = np.swapaxes(T[..., :3, :3], -1, -2)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, T[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out
