"""Canonical geometry of base-form hands at q = 0, vectorised over batches of 82-vectors.

Everything here reads the flat base vector (canonical key order, see :mod:`ohra.learn.sampler`) in
the canonical palm frame (metres; +x palm normal, +y thumb side of a right hand, +z finger-forward;
palm disc of radius ``R`` centred at ``(0, 0, R)`` with its axis along x).

At q = 0 every finger of the base template is a straight chain: a non-thumb finger runs from its
knuckle ``finger_xyz[f]`` along +z (the little finger's metacarpal frame is undone at its knuckle),
and the thumb runs from ``finger_xyz[0]`` along the z axis of its mounting rotation ``thumb_rpy``.
So the q = 0 fingertips, capsules and the plausibility rules below need no kinematic model; the tests
hold them to :class:`ohra.canonical.kinematics.HandModel` (Pinocchio) and Coal.

Plausibility rules (every registered hand and every sampled hand satisfies them; the VAE's decoder
enforces them, see :func:`ohra.learn.encoding_rot6d.project_plausible`):

* **finger base inside the palm**: a present non-thumb knuckle lower than ``KNUCKLE_MIN_Z * R``
  (in the wrist half of the palm disc; registered knuckles sit at >= 0.99 R, Barrett's).
* **thumb pointing into the palm**: the thumb's direction at q = 0 has a positive component towards
  the palm centre seen from the thumb base, ``d . (c - b) > 0``.
* **fingers intersecting at q = 0**: capsules of two different fingers overlap (the benchmark checks
  this with Coal through :meth:`HandModel.self_collision`).
"""

from __future__ import annotations

import numpy as np

from ohra.learn.sampler import FINGER_RADIUS, LENGTHS, LOWERS, PALM, THUMB_RPY, UPPERS, XYZ
from ohra.transforms import rpy_to_matrix

KNUCKLE_MIN_Z = 0.5  # x palm radius: a knuckle below this height is "inside the palm" (rule above)
FINGER_ROWS = (1, 2, 3, 4)  # index, middle, ring, little in finger_xyz


# -- rotations --------------------------------------------------------------------------------------
def rot6d_from_matrix(R: np.ndarray, order: str = "xy") -> np.ndarray:
    """(..., 3, 3) rotations -> (..., 6): two columns, one after the other.

    ``order="xy"``: the first two columns (DESIGN's 6-D rotation, used for grasps). ``"zx"``: the
    third, then the first column; Gram-Schmidt keeps the first column's direction exactly, so for
    the thumb mount (whose z axis is the thumb's direction at q = 0) the thumb direction depends on
    three numbers only, and a blend of two encodings blends the thumb directions.
    """
    R = np.asarray(R, dtype=float)
    i, j = _ORDERS[order]
    return np.concatenate([R[..., :, i], R[..., :, j]], axis=-1)


_ORDERS = {"xy": (0, 1), "zx": (2, 0)}


def matrix_from_rot6d(x: np.ndarray, order: str = "xy") -> np.ndarray:
    """(..., 6) -> (..., 3, 3) by Gram-Schmidt, the inverse of :func:`rot6d_from_matrix` for the
    same ``order`` (any 6 numbers with independent halves give a rotation; a degenerate input falls
    back to a fixed perpendicular so the result is always a rotation)."""
    x = np.asarray(x, dtype=float)
    a, b = x[..., 0:3], x[..., 3:6]
    na = np.linalg.norm(a, axis=-1, keepdims=True)
    e1 = np.where(na > 1e-12, a / np.where(na > 1e-12, na, 1.0), np.array([1.0, 0.0, 0.0]))
    b = b - np.sum(e1 * b, axis=-1, keepdims=True) * e1
    nb = np.linalg.norm(b, axis=-1, keepdims=True)
    # b parallel to a: any unit vector orthogonal to e1
    alt = np.cross(e1, np.where(np.abs(e1[..., :1]) < 0.9, np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])))
    alt /= np.linalg.norm(alt, axis=-1, keepdims=True)
    e2 = np.where(nb > 1e-12, b / np.where(nb > 1e-12, nb, 1.0), alt)
    e3 = np.cross(e1, e2)
    if order == "xy":
        return np.stack([e1, e2, e3], axis=-1)
    return np.stack([e2, e3, e1], axis=-1)  # zx: e1 = z, e2 = x, y = z cross x


def geodesic(Ra: np.ndarray, Rb: np.ndarray) -> np.ndarray:
    """Angle [rad] of the rotation between ``Ra`` and ``Rb`` (..., 3, 3), in [0, pi]."""
    c = (np.einsum("...ij,...ij->...", Ra, Rb) - 1.0) / 2.0
    return np.arccos(np.clip(c, -1.0, 1.0))


def rotation_about(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rodrigues: rotations (N, 3, 3) about unit axes (N, 3) by angles (N,)."""
    k = np.asarray(axis, dtype=float)
    K = np.zeros(k.shape[:-1] + (3, 3))
    K[..., 0, 1], K[..., 0, 2], K[..., 1, 2] = -k[..., 2], k[..., 1], -k[..., 0]
    K = K - np.swapaxes(K, -1, -2)
    s, c = np.sin(angle)[..., None, None], np.cos(angle)[..., None, None]
    return np.eye(3) + s * K + (1.0 - c) * (K @ K)


# -- q = 0 chains -----------------------------------------------------------------------------------
def _present(v: np.ndarray) -> np.ndarray:
    return (v[:, LOWERS] != 0.0) | (v[:, UPPERS] != 0.0)


def finger_reach(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Length of each finger's straight chain at q = 0 (N, 5) [m] and which fingers are present (N, 5).

    A segment counts when its link carries geometry (template link rules); absent segments have
    length 0 in valid vectors anyway.
    """
    p = _present(v)
    L = v[:, LENGTHS].reshape(-1, 2, 3)
    seg_t = np.stack([p[:, 0] | p[:, 1], p[:, 2] | p[:, 3], p[:, 4]], axis=1)
    reach = np.zeros((len(v), 5))
    fingers = np.zeros((len(v), 5), dtype=bool)
    reach[:, 0] = np.sum(L[:, 0] * seg_t, axis=1)
    fingers[:, 0] = seg_t.any(axis=1)
    for f, start in zip(FINGER_ROWS, (5, 9, 13, 18)):
        j = p[:, start : start + 4]
        seg = np.stack([j[:, 0] | j[:, 1], j[:, 2], j[:, 3]], axis=1)
        reach[:, f] = np.sum(L[:, 1] * seg, axis=1)
        fingers[:, f] = seg.any(axis=1)
    return reach, fingers


def thumb_frames(v: np.ndarray) -> np.ndarray:
    """Thumb mounting rotations (N, 3, 3) from ``thumb_rpy`` (fixed-axis xyz, URDF)."""
    return rpy_to_matrix(v[:, THUMB_RPY])


def finger_directions(v: np.ndarray) -> np.ndarray:
    """Unit direction of every finger's chain at q = 0 (N, 5, 3): thumb along its mounting z, others +z."""
    d = np.zeros((len(v), 5, 3))
    d[:, 1:, 2] = 1.0
    d[:, 0] = thumb_frames(v)[:, :, 2]
    return d


def tips_q0(v82: np.ndarray) -> np.ndarray:
    """Fingertip positions at q = 0, (N, 5, 3) [m] in the palm frame; NaN rows for absent fingers."""
    v = np.atleast_2d(np.asarray(v82, dtype=float))
    reach, fingers = finger_reach(v)
    base = v[:, XYZ].reshape(-1, 5, 3)
    tips = base + finger_directions(v) * reach[..., None]
    tips[~fingers] = np.nan
    return tips


def palm_centre(v: np.ndarray) -> np.ndarray:
    """Centre of the palm disc (N, 3): ``(0, 0, R)``."""
    c = np.zeros((len(v), 3))
    c[:, 2] = v[:, PALM]
    return c


# -- rules ------------------------------------------------------------------------------------------
def knuckles_inside_palm(v82: np.ndarray) -> np.ndarray:
    """(N, 4) True where a present index/middle/ring/little knuckle is below ``KNUCKLE_MIN_Z * R``."""
    v = np.atleast_2d(np.asarray(v82, dtype=float))
    _, fingers = finger_reach(v)
    z = v[:, XYZ].reshape(-1, 5, 3)[:, 1:, 2]
    return fingers[:, 1:] & (z < KNUCKLE_MIN_Z * v[:, PALM][:, None])


def thumb_inwardness(v82: np.ndarray) -> np.ndarray:
    """(N,) cosine between the thumb's q = 0 direction and the direction from its base to the palm
    centre (> 0: the thumb points into the palm); 0 where the base is at the centre."""
    v = np.atleast_2d(np.asarray(v82, dtype=float))
    w = palm_centre(v) - v[:, XYZ][:, 0:3]
    n = np.linalg.norm(w, axis=1)
    d = thumb_frames(v)[:, :, 2]
    return np.where(n > 1e-12, np.sum(d * w, axis=1) / np.where(n > 1e-12, n, 1.0), 0.0)


def thumb_into_palm(v82: np.ndarray) -> np.ndarray:
    """(N,) True where a present thumb points into the palm (rule in the module docstring)."""
    v = np.atleast_2d(np.asarray(v82, dtype=float))
    _, fingers = finger_reach(v)
    return fingers[:, 0] & (thumb_inwardness(v) > 0.0)


def segment_distance(p0: np.ndarray, p1: np.ndarray, q0: np.ndarray, q1: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Distance between segments [p0, p1] and [q0, q1] (..., 3), with the closest points on each.

    Closest points of two segments (Ericson, Real-Time Collision Detection, 5.1.9), vectorised;
    degenerate (zero-length) segments are handled.
    """
    d1, d2, r = p1 - p0, q1 - q0, p0 - q0
    a = np.sum(d1 * d1, -1)
    e = np.sum(d2 * d2, -1)
    f = np.sum(d2 * r, -1)
    c = np.sum(d1 * r, -1)
    b = np.sum(d1 * d2, -1)
    eps = 1e-18
    safe = lambda x: np.where(x > eps, x, 1.0)  # noqa: E731
    denom = a * e - b * b
    # general case: closest points of the infinite lines, s clamped, then t from s
    s = np.where(denom > eps, np.clip((b * f - c * e) / safe(denom), 0.0, 1.0), 0.0)
    s = np.where(e <= eps, np.clip(-c / safe(a), 0.0, 1.0), s)  # q degenerate: closest point of p to q0
    s = np.where(a <= eps, 0.0, s)  # p degenerate
    t = np.where(e > eps, (b * s + f) / safe(e), 0.0)
    # t outside [0, 1]: clamp it and recompute s for the clamped t
    t_c = np.clip(t, 0.0, 1.0)
    s = np.where((t < 0.0) | (t > 1.0), np.where(a > eps, np.clip((b * t_c - c) / safe(a), 0.0, 1.0), 0.0), s)
    t = t_c
    cp = p0 + d1 * s[..., None]
    cq = q0 + d2 * t[..., None]
    return np.linalg.norm(cp - cq, axis=-1), cp, cq


def finger_cores(v82: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each finger's chain at q = 0 as one capsule core: start (N, 5, 3), end (N, 5, 3), present (N, 5).

    The core runs from ``r`` past the finger base to ``r`` short of its tip; it contains the core
    segment of every capsule of that finger, so two fingers whose cores are at least ``2 r`` apart
    cannot intersect (a conservative test of the exact per-capsule one).
    """
    v = np.atleast_2d(np.asarray(v82, dtype=float))
    reach, fingers = finger_reach(v)
    r = v[:, FINGER_RADIUS][:, None, None]
    base = v[:, XYZ].reshape(-1, 5, 3)
    d = finger_directions(v)
    start = base + d * np.minimum(r, reach[..., None] / 2.0)
    end = base + d * np.maximum(reach[..., None] - r, reach[..., None] / 2.0)
    return start, end, fingers


def finger_clearance(v82: np.ndarray) -> np.ndarray:
    """(N, 5, 5) surface distance [m] between the q = 0 cores of every pair of present fingers
    (core distance minus 2 r; negative: overlapping), +inf on the diagonal and for absent fingers."""
    v = np.atleast_2d(np.asarray(v82, dtype=float))
    s, e, present = finger_cores(v)
    n = len(v)
    out = np.full((n, 5, 5), np.inf)
    r2 = 2.0 * v[:, FINGER_RADIUS]
    for i in range(5):
        for j in range(i + 1, 5):
            dist, _, _ = segment_distance(s[:, i], e[:, i], s[:, j], e[:, j])
            ok = present[:, i] & present[:, j]
            out[ok, i, j] = out[ok, j, i] = dist[ok] - r2[ok]
    return out


def thumb_clearance(v82: np.ndarray) -> np.ndarray:
    """(N,) smallest surface distance [m] between the thumb's q = 0 core and any other present
    finger's (+inf without a thumb or other fingers); cheaper than :func:`finger_clearance`."""
    v = np.atleast_2d(np.asarray(v82, dtype=float))
    s, e, present = finger_cores(v)
    out = np.full(len(v), np.inf)
    for j in FINGER_ROWS:
        dist, _, _ = segment_distance(s[:, 0], e[:, 0], s[:, j], e[:, j])
        ok = present[:, 0] & present[:, j]
        out[ok] = np.minimum(out[ok], dist[ok] - 2.0 * v[ok, FINGER_RADIUS])
    return out


__all__ = [
    "KNUCKLE_MIN_Z", "rot6d_from_matrix", "matrix_from_rot6d", "geodesic", "rotation_about", "finger_reach",
    "tips_q0", "palm_centre", "knuckles_inside_palm", "thumb_inwardness", "thumb_into_palm", "segment_distance",
    "finger_cores", "finger_clearance", "thumb_clearance",
]
