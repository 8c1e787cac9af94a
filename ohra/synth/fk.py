"""Forward kinematics of a canonical hand as CasADi expressions (and the CasADi Rodrigues).

Why this path stays (one of three beside Pinocchio, see ``tests/test_fk_paths.py``): the grasp NLP
needs frame poses as symbolic expressions of the joints, and the PyPI Pinocchio wheels have no
CasADi bindings. The kinematic tree of :class:`HandModel` (joint placements, axes and frame
placements, read from the Pinocchio model of the canonical URDF) is composed symbolically here:
``T_joint = T_parent @ T_placement @ Rot(axis, q)``. As a numeric batch evaluator it is no
substitute for the numpy path (``benchmarks/results/fk_paths.md``: about 6x slower on 4096
configurations). ``tests/test_fk_paths.py`` holds it to Pinocchio to 1e-9 m.
"""

from __future__ import annotations

from typing import Sequence

import casadi as ca
import numpy as np

from ohra.canonical.kinematics import HandModel


def rodrigues(axis: ca.SX | np.ndarray, angle: ca.SX) -> ca.SX:
    """Rotation by ``angle`` [rad] about the unit ``axis`` (3-vector): ``I + sin K + (1 - cos) K^2``.

    The CasADi twin of :func:`ohra.transforms.axis_angle_to_matrix` (one Rodrigues per backend).
    """
    K = ca.skew(ca.SX(axis) if isinstance(axis, np.ndarray) else axis)
    return ca.SX.eye(3) + ca.sin(angle) * K + (1 - ca.cos(angle)) * (K @ K)


def rotvec_matrix(w: ca.SX) -> ca.SX:
    """Rotation matrix of a rotation vector ``w`` (3x1, rad), smooth at 0.

    The angle is regularised (``|w| -> sqrt(|w|^2 + 1e-12)``) so the expression and its derivatives
    stay finite at ``w = 0``, where it gives the identity (the axis ``w / |w|`` vanishes with ``w``).
    """
    th = ca.sqrt(ca.dot(w, w) + 1e-12)
    return rodrigues(w / th, th)


def _rot(axis: np.ndarray, angle: ca.SX) -> ca.SX:
    """Rotation matrix about a fixed unit axis (exact for basis axes, Rodrigues otherwise)."""
    k = np.flatnonzero(np.abs(np.abs(axis) - 1.0) < 1e-12)
    if k.size == 1 and np.count_nonzero(axis) == 1:
        c, s = ca.cos(angle), ca.sin(angle)
        i = int(k[0])
        sg = float(np.sign(axis[i]))
        u, v = (i + 1) % 3, (i + 2) % 3
        R = ca.SX.eye(3)
        R[u, u], R[u, v], R[v, u], R[v, v] = c, -sg * s, sg * s, c
        return R
    return rodrigues(np.asarray(axis, dtype=float), angle)


def frame_transforms(hand: HandModel, q: ca.SX, frames: Sequence[str]) -> list[tuple[ca.SX, ca.SX]]:
    """Symbolic (R 3x3, p 3x1) of each frame in the palm frame, for a 22-vector ``q``."""
    t = hand.tree
    needed = hand._ancestors(tuple(int(t.frame_joint[t.frame_names.index(f)]) for f in frames))
    Rs: dict[int, ca.SX] = {}
    ps: dict[int, ca.SX] = {}
    for j in needed:
        P = t.joint_placement[j]
        pj = int(t.joint_parent[j])
        if pj < 0:
            R0, p0 = ca.SX(P[:3, :3]), ca.SX(P[:3, 3])
        else:
            R0 = Rs[pj] @ ca.SX(P[:3, :3])
            p0 = Rs[pj] @ ca.SX(P[:3, 3]) + ps[pj]
        Rs[j] = R0 @ _rot(t.joint_axis[j], q[int(t.joint_q[j])])
        ps[j] = p0
    out = []
    for f in frames:
        k = t.frame_names.index(f)
        Tf = t.frame_placement[k]
        pj = int(t.frame_joint[k])
        if pj < 0:
            out.append((ca.SX(Tf[:3, :3]), ca.SX(Tf[:3, 3])))
        else:
            out.append((Rs[pj] @ ca.SX(Tf[:3, :3]), Rs[pj] @ ca.SX(Tf[:3, 3]) + ps[pj]))
    return out


def fk_function(hand: HandModel, frames: Sequence[str]) -> ca.Function:
    """CasADi Function ``q (22) -> [R_1, p_1, ..., R_F, p_F]`` in the palm frame."""
    q = ca.SX.sym("q", 22)
    outs = []
    for R, p in frame_transforms(hand, q, frames):
        outs += [R, p]
    return ca.Function("hand_fk", [q], outs)
