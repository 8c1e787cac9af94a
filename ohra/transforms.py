"""Rigid transforms: fixed-axis rpy (URDF / scipy ``"xyz"``), axis-angle rotations and 4x4 matrices.

numpy only; the CasADi twin of :func:`axis_angle_to_matrix` is :func:`ohra.synth.fk.rodrigues`.
"""

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


def skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrix ``[v]x`` (``[v]x @ u == v x u``); (...,3) -> (...,3,3)."""
    v = np.asarray(v, dtype=float)
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    o = np.zeros_like(x)
    return np.stack([np.stack([o, -z, y], -1), np.stack([z, o, -x], -1), np.stack([-y, x, o], -1)], -2)


def axis_angle_to_matrix(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rodrigues' rotation ``I + sin(a) K + (1 - cos(a)) K^2``, ``K = [axis]x``, about a unit axis.

    ``axis`` (...,3) unit vectors and ``angle`` (...) radians broadcast against each other ((3,) with
    (N,) gives (N,3,3)); returns (...,3,3).
    """
    K = skew(axis)
    a = np.asarray(angle, dtype=float)[..., None, None]
    return np.eye(3) + np.sin(a) * K + (1.0 - np.cos(a)) * (K @ K)
