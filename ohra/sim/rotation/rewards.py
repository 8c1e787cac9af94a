"""Reward terms of the rotation task: one unweighted function per term; total = sum_k w_k * term_k.

The rotation term is the object's angular velocity about world +z over the control step, taken
from the orientation change (the rotation vector of ``R_t R_{t-1}^T`` divided by the step time),
not PyBullet's instantaneous velocity at the last sub-step: it is what the object actually turned.
Penalty terms are >= 0 and enter with negative weights (``RewardWeights``); ``fall`` is 1 on the
step the object falls or leaves the hand, else 0 (weight 0 unless a run sets it).
"""

from __future__ import annotations

import math

import numpy as np

from ohra.sim.rotation.config import RewardWeights

TERMS = ("rotation", "drift", "pose", "torque", "work", "linvel", "fall")
DROPPED = ("fell", "left")  # terminations the fall term counts (not "broken": the simulation diverged)


def delta_yaw(quat_prev: np.ndarray, quat_now: np.ndarray) -> float:
    """Rotation about world +z [rad] from orientation ``quat_prev`` to ``quat_now`` (xyzw, world frame).

    The z component of the rotation vector of ``R_now R_prev^T`` (exact for a pure turn about z; for
    small steps it is the integral of omega_z).
    """
    x1, y1, z1, w1 = (float(v) for v in quat_now)
    x0, y0, z0, w0 = -float(quat_prev[0]), -float(quat_prev[1]), -float(quat_prev[2]), float(quat_prev[3])
    # q = q_now * conj(q_prev)
    x = w1 * x0 + x1 * w0 + y1 * z0 - z1 * y0
    y = w1 * y0 - x1 * z0 + y1 * w0 + z1 * x0
    z = w1 * z0 + x1 * y0 - y1 * x0 + z1 * w0
    w = w1 * w0 - x1 * x0 - y1 * y0 - z1 * z0
    if w < 0.0:  # the short way round
        x, y, z, w = -x, -y, -z, -w
    s = math.sqrt(x * x + y * y + z * z)
    if s < 1e-12:
        return 2.0 * z  # first order: angle * axis = 2 * vector part
    angle = 2.0 * math.atan2(s, w)
    return angle * z / s


def rotation(dyaw: float, dt: float, clip: float) -> float:
    """Angular velocity about world +z [rad/s], clipped to [-clip, clip]."""
    return float(np.clip(dyaw / dt, -clip, clip))


def drift(obj_pos: np.ndarray, obj_start: np.ndarray) -> float:
    """Distance of the object from its start position [m]."""
    return float(np.linalg.norm(np.asarray(obj_pos) - np.asarray(obj_start)))


def pose(q: np.ndarray, q_start: np.ndarray) -> float:
    """Squared joint deviation from the episode's start pose [rad^2]."""
    d = np.asarray(q) - np.asarray(q_start)
    return float(d @ d)


def torque(tau: np.ndarray) -> float:
    """Sum of squared motor torques [N^2 m^2]."""
    t = np.asarray(tau)
    return float(t @ t)


def work(tau: np.ndarray, dq: np.ndarray) -> float:
    """Squared mechanical power of the motors, (sum_i tau_i dq_i)^2 [W^2]."""
    return float(np.asarray(tau) @ np.asarray(dq)) ** 2


def linvel(v: np.ndarray) -> float:
    """Object speed, L1 norm of the linear velocity [m/s]."""
    return float(np.abs(np.asarray(v)).sum())


def fall(why: str | None) -> float:
    """1 when the episode ends because the object fell or left the hand (``why`` from
    :func:`ohra.sim.rotation.termination.reason`), else 0."""
    return 1.0 if why in DROPPED else 0.0


def total(terms: dict[str, float], weights: RewardWeights) -> float:
    """sum_k w_k * term_k over :data:`TERMS`."""
    return float(sum(getattr(weights, k) * terms[k] for k in TERMS))
