"""Keypoints compared by the fit and the fidelity report: joint origins, joint axes and fingertips.

* :func:`canonical_keypoints`: batched forward kinematics of a canonical hand straight from its
  parameter arrays (mirrors ``ohra/urdf/templates/{base,extended}.urdf.j2``; the least-squares fit
  needs it without rendering a URDF per evaluation). Tested against :class:`ohra.HandModel`.
* :func:`original_keypoints`: the original hand's mapped joint frames and fingertip points for a
  batch of original configurations.

Frames: the canonical palm frame, metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ohra.canonical.params import EXT_ROW_START, FINGERS, JOINT_INDEX, JOINT_NAMES, ExtendedParams, link_presence
from ohra.original.measure import Measurement
from ohra.transforms import axis_angle_to_matrix, invert, inverse_rpy

_X_AXIS_SLOTS = ("thumb_joint1", "thumb_joint3", "index_joint1", "middle_joint1", "ring_joint1", "little_joint1")


# -- canonical forward kinematics from parameter arrays ---------------------------------------------
def _rpy_matrix(rpy: np.ndarray) -> np.ndarray:
    """Rz(yaw) Ry(pitch) Rx(roll) (fixed-axis rpy), without scipy's per-call overhead."""
    cr, sr = np.cos(rpy[0]), np.sin(rpy[0])
    cp, sp = np.cos(rpy[1]), np.sin(rpy[1])
    cy, sy = np.cos(rpy[2]), np.sin(rpy[2])
    return np.array([
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ])


def _T(xyzrpy: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = _rpy_matrix(xyzrpy[3:6])
    T[:3, 3] = xyzrpy[:3]
    return T


def _rot_batch(axis: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(N,4,4) rotations by angles q (N,) about ``axis`` (normalised here; zero -> x)."""
    n = np.linalg.norm(axis)
    axis = axis / n if n > 1e-12 else np.array([1.0, 0.0, 0.0])
    out = np.zeros((q.shape[0], 4, 4))
    out[:, :3, :3] = axis_angle_to_matrix(axis, q)
    out[:, 3, 3] = 1.0
    return out


def _tz(d: float) -> np.ndarray:
    T = np.eye(4)
    T[2, 3] = d
    return T


def _default_axis(k: int) -> np.ndarray:
    """The template's axis of an absent joint k (x for abduction-like slots, else y)."""
    return np.array([1.0, 0.0, 0.0]) if JOINT_NAMES[k] in _X_AXIS_SLOTS else np.array([0.0, 1.0, 0.0])


def ext_arrays_from_base(v: np.ndarray, present: np.ndarray) -> dict[str, np.ndarray]:
    """Extended kinematic arrays of a base parameter vector (as :meth:`BaseParams.to_extended`)."""
    fl = v[2:8].reshape(2, 3)
    fxyz = v[8:23].reshape(5, 3)
    e = v[23:29]
    trpy = v[29:32]
    tax = v[32:38].reshape(2, 3)
    lengths = np.vstack([fl[0], np.tile(fl[1], (4, 1))])
    o = np.zeros((12, 6))
    ax = np.zeros((12, 3))
    o[0, :3], o[0, 3:] = fxyz[0], trpy
    ax[0] = tax[0] if present[0] else (1.0, 0.0, 0.0)
    ax[1] = tax[1] if present[1] else (0.0, 1.0, 0.0)
    if not (present[0] or present[1]):
        o[2, 2] = -fl[0, 0]
    ax[2] = (1.0, 0.0, 0.0)
    for fi in (1, 2, 3):
        r = EXT_ROW_START[fi]
        o[r, :3] = fxyz[fi]
        ax[r], ax[r + 1] = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0)
    o[9] = e
    ax[9] = (0.0, 1.0, 0.0)
    o[10, :3] = fxyz[4]
    o[10, 3:] = inverse_rpy(e[3:])
    ax[10], ax[11] = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0)
    return {"lengths": lengths, "origins": o, "axes": ax}


def ext_arrays(p: ExtendedParams) -> dict[str, np.ndarray]:
    """The kinematic arrays of extended params (lengths (5,3), origins (12,6), axes (12,3))."""
    return {"lengths": p.finger_lengths, "origins": p.joint_origins, "axes": p.joint_axes}


class _Chain:
    """Batched transform chain of one finger: each step places a joint, records its origin, rotates."""

    def __init__(self, ax: np.ndarray, present: np.ndarray, q: np.ndarray, J: np.ndarray) -> None:
        self.ax, self.a, self.q, self.J = ax, present, q, J

    def step(self, T: np.ndarray, placement: np.ndarray, k: int, axis: np.ndarray) -> np.ndarray:
        T = T @ placement
        self.J[:, k] = T[:, :3, 3]
        return T @ _rot_batch(axis if self.a[k] else _default_axis(k), self.q[:, k])


def _thumb(c: _Chain, I: np.ndarray, fl: np.ndarray, o: np.ndarray, links) -> np.ndarray | None:
    a, ax, ey = c.a, c.ax, np.array([0.0, 1.0, 0.0])
    T = c.step(I, _T(o[0]), 0, ax[0])
    T = c.step(T, _T(o[1]), 1, ax[1])
    o2 = o[2].copy()
    o2[2] += fl[0, 0]
    T = c.step(T, _T(o2), 2, ax[2])
    T = c.step(T, np.eye(4), 3, ey)
    T = c.step(T, _tz(fl[0, 1] if (a[2] or a[3]) else 0.0), 4, ey)
    if any(links["thumb"]):
        return (T @ _tz(fl[0, 2] if links["thumb"][2] else 0.0))[:, :3, 3]
    return None


def canonical_keypoints(
    arr: dict[str, np.ndarray], present: np.ndarray, q: np.ndarray, fingers: tuple[str, ...] = FINGERS
) -> tuple[np.ndarray, np.ndarray]:
    """Joint origins (N,22,3) and fingertips (N,5,3) of a canonical hand (standard templates).

    Mirrors ``urdf/templates/{base,extended}.urdf.j2``; tested against :class:`ohra.HandModel`.
    Only ``fingers`` are evaluated (the other rows stay NaN).
    """
    q = np.atleast_2d(q)
    N = q.shape[0]
    fl, o, ax = arr["lengths"], arr["origins"], arr["axes"]
    links = link_presence(present)
    J = np.full((N, 22, 3), np.nan)
    tips = np.full((N, 5, 3), np.nan)
    I = np.broadcast_to(np.eye(4), (N, 4, 4))
    c = _Chain(ax, present, q, J)
    if "thumb" in fingers:
        t = _thumb(c, I, fl, o, links)
        if t is not None:
            tips[:, 0] = t
    for fi, f in ((1, "index"), (2, "middle"), (3, "ring"), (4, "little")):
        if f not in fingers:
            continue
        k = JOINT_INDEX[f"{f}_joint1"]
        if f == "little":
            T = c.step(I, _T(o[9]), 17, ax[9])
            kn = np.zeros(6)  # the j1 frame is given in the palm frame: undo the metacarpal placement
            kn[:3] = _rpy_matrix(o[9, 3:]).T @ (o[10, :3] - o[9, :3])
            kn[3:] = o[10, 3:]
            T = c.step(T, _T(kn), 18, ax[10])
            T = c.step(T, _T(o[11]), 19, ax[11])
            r1 = 11
        else:
            r = EXT_ROW_START[fi]
            T = c.step(I, _T(o[r]), k, ax[r])
            T = c.step(T, _T(o[r + 1]), k + 1, ax[r + 1])
            r1 = r + 1
        # the middle joint sits the proximal length beyond the j1 origin along z (minus the j2 offset)
        T = c.step(T, _tz(fl[fi, 0] - o[r1, 2] if (present[k] or present[k + 1]) else 0.0), k + 2, np.array([0.0, 1.0, 0.0]))
        T = c.step(T, _tz(fl[fi, 1] if present[k + 2] else 0.0), k + 3, np.array([0.0, 1.0, 0.0]))
        if any(links[f]):
            tips[:, fi] = (T @ _tz(fl[fi, 2] if links[f][2] else 0.0))[:, :3, 3]
    return J, tips


# -- original keypoints ----------------------------------------------------------------------------
@dataclass
class OriginalKeypoints:
    """Original-hand keypoints in the palm frame for a batch of configurations."""

    q_orig: np.ndarray  # (N, n)
    q_canon: np.ndarray  # (N, 22)
    joints: np.ndarray  # (N, 22, 3) mapped joint positions (NaN unmapped)
    axes: np.ndarray  # (N, 22, 3) their signed axes
    tips: np.ndarray  # (N, 5, 3) fingertip points (NaN absent)


def tip_points_local(m: Measurement) -> dict[str, tuple[str, np.ndarray]]:
    """The (true) fingertip point of each finger as (link that carries it, point in that link's frame)."""
    poses = m.hand.link_poses(m.q0, passive=m.passive0)
    idx = {l: i for i, l in enumerate(m.hand.links)}
    out = {}
    for f, fm in m.fingers.items():
        link = fm.tip_link or m.tip_links[f][0]
        T = m.T_palm_root @ poses[idx[link]]
        out[f] = (link, invert(T)[:3, :3] @ fm.tip + invert(T)[:3, 3])
    return out


def original_keypoints(m: Measurement, q_orig: np.ndarray) -> OriginalKeypoints:
    """Mapped joint positions/axes and fingertip points of the original hand at ``q_orig`` (N, n)."""
    hand, am = m.hand, m.action_map
    q_orig = np.atleast_2d(q_orig)
    N = q_orig.shape[0]
    slot_links = {s: hand.joints[sm.name].child for s, sm in am.slots.items()}
    tipl = tip_points_local(m)
    want = sorted(set(slot_links.values()) | {l for l, _ in tipl.values()})
    Tp = m.T_palm_root @ hand.link_poses(q_orig, want)
    w = {l: i for i, l in enumerate(want)}
    joints = np.full((N, 22, 3), np.nan)
    axes = np.full((N, 22, 3), np.nan)
    for s, l in slot_links.items():
        T = Tp[:, w[l]]
        joints[:, JOINT_INDEX[s]] = T[:, :3, 3]
        sm = am.slots[s]
        axes[:, JOINT_INDEX[s]] = (T[:, :3, :3] @ hand.joints[sm.name].axis) * sm.sign
    tips = np.full((N, 5, 3), np.nan)
    for f, (l, pt) in tipl.items():
        T = Tp[:, w[l]]
        tips[:, FINGERS.index(f)] = T[:, :3, :3] @ pt + T[:, :3, 3]
    return OriginalKeypoints(q_orig, am.to_canonical(q_orig), joints, axes, tips)


def unmapped_hand_joints(m: Measurement) -> list[str]:
    """Actuated joints that drive no slot but move links below the palm (not a wrist above it)."""
    below = set(m.hand.descendants(m.palm_link))
    mapped = m.action_map.mapped_original
    return [n for n, used in zip(m.hand.movable_joints, mapped)
            if not used and m.hand.joints[n].parent in below and m.hand.joints[n].upper > m.hand.joints[n].lower]


def sample_original(m: Measurement, n: int, seed: int, unmapped: bool = False) -> np.ndarray:
    """(n, dof) original configurations uniform within the actuated joints' limits, preceded by
    canonical zero itself when that lies within the original limits (Barrett's bent distal links,
    e.g., cannot straighten).

    Sampled: the joints that drive a slot (coupled slots' joints then follow their drivers, mimic
    joints through the URDF itself); with ``unmapped`` also the actuated joints inside the hand
    that drive no slot (what the canonical hand cannot follow). Other joints stay at their
    canonical-zero value.
    """
    hand, am = m.hand, m.action_map
    rng = np.random.default_rng(seed)
    q = np.tile(m.q0, (n, 1))
    mapped = am.mapped_original
    if unmapped:
        mapped = mapped | np.isin(np.array(hand.movable_joints), unmapped_hand_joints(m))
    lo, up = hand.lower[mapped], hand.upper[mapped]
    q[:, mapped] = lo + rng.random((n, int(mapped.sum()))) * (up - lo)
    if am.couplings:  # declared couplings between actuated joints: the coupled ones follow their drivers
        keep = q[:, ~am.mapped_original]
        q = am.to_original(am.to_canonical(q))
        q[:, ~am.mapped_original] = keep
    q0 = m.q0[mapped]
    if np.all((q0 >= lo - 1e-9) & (q0 <= up + 1e-9)):
        q = np.vstack([m.q0[None], q])
    return q


def line_distance(points: np.ndarray, line_pts: np.ndarray, line_dirs: np.ndarray) -> np.ndarray:
    """Distance of points to lines (through line_pts along unit line_dirs); (...,3) -> (...)."""
    d = points - line_pts
    return np.linalg.norm(d - np.sum(d * line_dirs, axis=-1, keepdims=True) * line_dirs, axis=-1)


__all__ = [
    "canonical_keypoints", "ext_arrays", "ext_arrays_from_base", "original_keypoints", "OriginalKeypoints",
    "sample_original", "line_distance", "tip_points_local", "unmapped_hand_joints",
]
