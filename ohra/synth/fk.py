"""Forward kinematics of a canonical hand as CasADi expressions.

The PyPI Pinocchio wheels have no CasADi bindings, so the kinematic tree of :class:`HandModel`
(joint placements, axes and frame placements, read from the Pinocchio model of the canonical URDF)
is composed symbolically here: ``T_joint = T_parent @ T_placement @ Rot(axis, q)``. Tests check it
against Pinocchio to 1e-9 m.
"""

from __future__ import annotations

from typing import Sequence

import casadi as ca
import numpy as np

from ohra.canonical.kinematics import HandModel


def _rot(axis: np.ndarray, angle: ca.SX) -> ca.SX:
    """Rotation matrix about a fixed unit axis (exact for basis axes, Rodrigues otherwise)."""
    c, s = ca.cos(angle), ca.sin(angle)
    k = np.flatnonzero(np.abs(np.abs(axis) - 1.0) < 1e-12)
    if k.size == 1 and np.count_nonzero(axis) == 1:
        i = int(k[0])
        sg = float(np.sign(axis[i]))
        u, v = (i + 1) % 3, (i + 2) % 3
        R = ca.SX.eye(3)
        R[u, u], R[u, v], R[v, u], R[v, v] = c, -sg * s, sg * s, c
        return R
    x, y, z = (float(a) for a in axis)
    K = ca.SX(np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]]))
    return ca.SX.eye(3) + s * K + (1.0 - c) * (K @ K)


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
