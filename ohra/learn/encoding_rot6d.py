"""The 70-D morphology encoding (``rot6d70``): every hand as a right hand plus a handedness flag,
the thumb mount as a continuous rotation, and plausible stand-in values for parts a hand lacks.

Layout (canonical key order of :class:`ohra.canonical.params.BaseParams`, as the 66-D reference
encoding in :mod:`ohra.learn.encoding`, except for the thumb rotation and the last value):

=========  ====  ================================================================================
slice      size  content (of the hand mirrored to a right hand when it is a left one)
=========  ====  ================================================================================
[0:29]     29    palm_radius, finger_radius, finger_lengths (6), finger_xyz (15),
                 little_extra_origin (6) -- metres / radians
[29:35]    6     thumb mounting rotation as rot6d: the z then the x column of ``R(thumb_rpy)``
[35:41]    6     one-hot of thumb_axes[0] over (+x, -x, +y, -y, +z, -z); a zero axis encodes as +x
[41:47]    6     one-hot of thumb_axes[1]
[47:69]    22    flags, 1 where joint_lowers != joint_uppers (the VAE's "present" = movable)
[69]       1     1 for a left hand (mirrored through the palm's x-z plane to encode it)
=========  ====  ================================================================================

Why (numbers in the README's VAE section):

* Euler angles wrap at +-pi and are singular at pitch +-pi/2, where most registered thumbs sit, so
  a regression on them cannot be accurate; rot6d is continuous (Zhou et al., CVPR 2019). The z column
  (the thumb's direction) comes first: Gram-Schmidt keeps it exact, so the thumb's direction, which
  alone places the thumb tip at q = 0, is three numbers; with the (x, y) columns a latent path
  between two thumbs of similar direction but different roll passes near a zero first column and
  the thumb swings round (measured: thumb tips moving 10-20 cm in one of 15 steps).
* Left and right hands are mirror images; encoding both as right hands lets the VAE spend its
  capacity on one family of shapes, and keeps a path between two left hands away from right-hand
  shapes (where the thumb sits on the other side and would swing across the palm).
* Where the 66-D encoding writes zeros for parts a hand lacks, this one writes stand-ins
  (:func:`fill_absent`): an absent finger's knuckle between or beyond its neighbours, an absent
  segment's length the mean of the hand's other segments, an absent little metacarpal frame the
  middle of the sampler's range. They are functions of the rest of the hand (no information to
  carry), and when a latent interpolation turns a finger on, it appears where a finger belongs
  instead of at the palm's origin.

Decoding yields valid params (:func:`ohra.learn.encoding.project_vectors`) that also obey the
plausibility rules of :mod:`ohra.learn.geometry` (:func:`project_plausible`; the rules are
mirror-symmetric, so it runs on the right-hand form).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ohra.canonical.params import SIDE_TOLERANCE
from ohra.learn.encoding import (
    AXIS_CATEGORIES, DECODE_LOWER, DECODE_UPPER, LatentError, _as_batch, _decode_discrete, _encode_discrete,
    _spread_knuckles, project_vectors,
)
from ohra.learn.geometry import (
    FINGER_ROWS, KNUCKLE_MIN_Z, finger_cores, finger_reach, matrix_from_rot6d, palm_centre, rot6d_from_matrix,
    rotation_about, segment_distance, thumb_clearance, thumb_inwardness,
)
from ohra.learn.sampler import (
    DEFAULT_CONFIG, EXTRA, FINGER_RADIUS, LENGTHS, LOWERS, PALM, THUMB_AXES, THUMB_RPY, UPPERS, XYZ,
    mirror_vectors,
)
from ohra.transforms import matrix_to_rpy, rpy_to_matrix

ENCODING_DIM = 70
CONT_DIM = 35
CONT = slice(0, 35)
ROT6D = slice(29, 35)
AXIS1 = slice(35, 41)
AXIS2 = slice(41, 47)
FLAGS = slice(47, 69)
LEFT = slice(69, 70)
CONT_NAMES: tuple[str, ...] = (
    "palm_radius", "finger_radius",
    *(f"finger_lengths[{r}][{c}]" for r in range(2) for c in range(3)),
    *(f"finger_xyz[{r}][{c}]" for r in range(5) for c in range(3)),
    *(f"little_extra_origin[{c}]" for c in range(6)),
    *(f"thumb_rot6d[{c}]" for c in range(6)),
)
THUMB_OUTWARD_EPS = 1e-6  # cosine the projection leaves between the thumb and the palm-centre direction
CLEARANCE_MARGIN = 1e-6  # m of free space the projection leaves between two fingers' q = 0 cores
_PASSES = 20  # projection rounds (turn the thumb out, push it off the fingers) before the fallback
THUMB_Y = XYZ.start + 1  # the thumb base's y in the base vector
# Decoding box of a hand in right-hand form: its thumb base on the thumb side, y >= 0 (as in the
# sampler). A base at y < 0 would make the decoded hand's handedness (BaseParams.handedness: by the
# thumb base's side first) disagree with the left flag; Barrett's thumb sits at y = 0, and the
# latent path from it to a left hand flipped between "left" and "right" that way (a 125 mm step).
RIGHT_FORM_LOWER = DECODE_LOWER.copy()
RIGHT_FORM_LOWER[THUMB_Y] = 0.0


# -- stand-ins for absent parts ----------------------------------------------------------------------
def is_left(v82: Any) -> np.ndarray:
    """(N,) True for left hands: by the thumb base's side (+y: right), else by the little finger's
    (-y: right), else by the index's (+y: right), as :attr:`BaseParams.handedness` (a base within
    ``SIDE_TOLERANCE`` of y = 0 decides nothing); right if none."""
    v = np.atleast_2d(np.asarray(v82, dtype=float))
    _, fingers = finger_reach(v)
    y = v[:, XYZ].reshape(-1, 5, 3)[:, :, 1]
    side = np.zeros(len(v))
    for f, right_sign in ((1, 1.0), (4, -1.0), (0, 1.0)):  # lowest priority first, overwritten by higher ones
        ok = fingers[:, f] & (np.abs(y[:, f]) > SIDE_TOLERANCE)
        side[ok] = right_sign * np.sign(y[ok, f])
    return side < 0


def _virtual_knuckles(xyz: np.ndarray, fingers: np.ndarray, r: np.ndarray, side: np.ndarray) -> None:
    """In place: knuckles (N, 5, 3) of absent non-thumb fingers, interpolated between the nearest
    present neighbours (in slot order index..little), or continued past the end of the row by the
    row's mean step per slot (2.5 r towards the little side when only one finger is present)."""
    n = len(xyz)
    k = xyz[:, 1:]
    pres = fingers[:, 1:]
    slots = np.arange(4)
    big = 99
    first = np.where(pres.any(1), np.argmax(pres, 1), 0)
    last = np.where(pres.any(1), 3 - np.argmax(pres[:, ::-1], 1), 0)
    span = np.maximum(last - first, 1)
    step = (k[np.arange(n), last] - k[np.arange(n), first]) / span[:, None]  # (N, 3) per slot
    single = (last == first)
    step[single] = 0.0
    step[single, 1] = -2.5 * r[single] * side[single]
    for s in range(4):
        todo = ~pres[:, s] & pres.any(1)
        if not todo.any():
            continue
        lo = np.where(pres & (slots < s), slots, -big).max(1)
        hi = np.where(pres & (slots > s), slots, big).min(1)
        both = todo & (lo >= 0) & (hi < big)
        if both.any():
            i = np.flatnonzero(both)
            t = ((s - lo[i]) / (hi[i] - lo[i]))[:, None]
            k[i, s] = k[i, lo[i]] + t * (k[i, hi[i]] - k[i, lo[i]])
        for mask, end in ((todo & (lo >= 0) & (hi >= big), lo), (todo & (lo < 0) & (hi < big), hi)):
            i = np.flatnonzero(mask)
            if i.size:
                k[i, s] = k[i, end[i]]
                k[i, s, 1] += step[i, 1] * (s - end[i])


def fill_absent(v82: Any) -> np.ndarray:
    """Base vectors (N, 82) with stand-in values for parts without geometry (see module doc).

    Only the encoding uses these values; :func:`decode_vectors` zeroes them again.
    """
    v = np.array(np.atleast_2d(v82), dtype=float, copy=True)
    n = len(v)
    present = (v[:, LOWERS] != 0.0) | (v[:, UPPERS] != 0.0)
    _, fingers = finger_reach(v)
    side = np.where(is_left(v), -1.0, 1.0)
    L = v[:, LENGTHS].reshape(n, 2, 3)
    has = L > 0
    count = has.sum(2)  # (N, 2): thumb, non-thumb
    mean = (L * has).sum(2) / np.maximum(count, 1)
    none = count == 0
    mean[none[:, 0], 0] = mean[none[:, 0], 1]  # a group without segments borrows the other's mean
    mean[none[:, 1], 1] = mean[none[:, 1], 0]
    mean[none.all(1)] = np.mean(DEFAULT_CONFIG.finger_lengths)
    L = np.where(has, L, mean[:, :, None])
    v[:, LENGTHS] = L.reshape(n, 6)
    xyz = v[:, XYZ].reshape(n, 5, 3)
    _virtual_knuckles(xyz, fingers, v[:, FINGER_RADIUS], side)
    v[:, XYZ] = xyz.reshape(n, 15)
    c = DEFAULT_CONFIG
    mid = np.array([np.mean(c.extra_x), -np.mean(c.extra_y), np.mean(c.extra_z), np.mean(c.extra_roll),
                    np.mean(c.extra_pitch), np.mean(c.extra_yaw)])
    mirror = np.array([1.0, -1.0, 1.0, -1.0, 1.0, -1.0])
    stand_in = np.where(side[:, None] > 0, mid, mid * mirror)
    v[~present[:, 17], EXTRA] = stand_in[~present[:, 17]]
    return v


# -- encoding ---------------------------------------------------------------------------------------
def encode_vectors(v82: Any, warn: bool = True) -> np.ndarray:
    """Base vectors (82,) or (N, 82) -> encodings (70,) or (N, 70) (raw units, see module doc)."""
    v, single = _as_batch(v82, 82, "base vector")
    n = len(v)
    left = is_left(v)
    v = v.copy()
    v[left] = mirror_vectors(v[left])
    f = fill_absent(v)
    out = np.zeros((n, ENCODING_DIM))
    out[:, 0:29] = f[:, 0:29]
    out[:, ROT6D] = rot6d_from_matrix(rpy_to_matrix(v[:, THUMB_RPY]), "zx")
    _encode_discrete(out, v, AXIS1, AXIS2, FLAGS, warn)
    out[:, LEFT.start] = left.astype(float)
    return out[0] if single else out


# -- decoding ---------------------------------------------------------------------------------------
def decode_vectors(x70: Any, limits: Any = None) -> np.ndarray:
    """Encodings (70,) or (N, 70) -> valid, plausible base vectors (82,) or (N, 82).

    Axis groups may hold one-hot vectors, probabilities or logits (argmax); flags and the left flag
    are set when > 0.5; the rot6d block may be any 6 numbers (Gram-Schmidt). ``limits`` as in
    :func:`ohra.learn.encoding.decode_vectors`.
    """
    x, single = _as_batch(x70, ENCODING_DIM, "encoding")
    if not np.all(np.isfinite(x)):
        raise LatentError("encoding has non-finite values")
    n = len(x)
    axes, lo, up = _decode_discrete(x, AXIS1, AXIS2, FLAGS, limits)
    v = np.zeros((n, 82))
    v[:, 0:29] = x[:, 0:29]
    v[:, THUMB_RPY] = matrix_to_rpy(matrix_from_rot6d(x[:, ROT6D], "zx"))
    v[:, THUMB_AXES] = axes
    v[:, LOWERS] = lo
    v[:, UPPERS] = up
    v = project_vectors(v)
    v[:, THUMB_Y] = np.maximum(v[:, THUMB_Y], 0.0)  # see RIGHT_FORM_LOWER
    v = project_plausible(v, RIGHT_FORM_LOWER)
    left = x[:, LEFT.start] > 0.5
    v[left] = mirror_vectors(v[left])
    return v[0] if single else v


def _turn_thumbs_out(v: np.ndarray) -> None:
    """In place: rotate thumbs that point into the palm by the smallest rotation that leaves their
    direction just outside the half-space facing the palm centre (direction cosine -eps)."""
    cos = thumb_inwardness(v)
    rows = np.flatnonzero(cos > -THUMB_OUTWARD_EPS / 2)  # half the target: a turned thumb is not turned again
    rows = rows[finger_reach(v[rows])[1][:, 0]] if rows.size else rows
    if rows.size == 0:
        return
    R = rpy_to_matrix(v[rows, THUMB_RPY])
    d = R[:, :, 2]
    w = palm_centre(v[rows]) - v[rows, XYZ.start : XYZ.start + 3]
    w /= np.maximum(np.linalg.norm(w, axis=1, keepdims=True), 1e-12)
    u = d - np.sum(d * w, 1, keepdims=True) * w  # d's part perpendicular to w
    nu = np.linalg.norm(u, axis=1, keepdims=True)
    perp = np.cross(w, np.where(np.abs(w[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]]))
    u = np.where(nu > 1e-9, u / np.maximum(nu, 1e-12), perp / np.linalg.norm(perp, axis=1, keepdims=True))
    eps = THUMB_OUTWARD_EPS
    target = math.sqrt(1.0 - eps * eps) * u - eps * w  # unit, at cosine exactly -eps to w
    axis = np.cross(d, target)
    s = np.linalg.norm(axis, axis=1)
    angle = np.arctan2(s, np.sum(d * target, 1))
    axis = np.where(s[:, None] > 1e-12, axis / np.maximum(s, 1e-12)[:, None], w)
    v[rows, THUMB_RPY] = matrix_to_rpy(rotation_about(axis, angle) @ R)


def _push_thumbs_off(v: np.ndarray, lower: np.ndarray = DECODE_LOWER) -> bool:
    """In place: translate each thumb away from the finger it overlaps most (q = 0 cores), by the
    overlap plus a margin, staying inside the box ``[lower, DECODE_UPPER]``. Returns whether any
    thumb moved."""
    s, e, present = finger_cores(v)
    two_r = 2.0 * v[:, FINGER_RADIUS]
    worst = np.full(len(v), np.inf)
    push = np.zeros((len(v), 3))
    for j in FINGER_ROWS:
        dist, cp, cq = segment_distance(s[:, 0], e[:, 0], s[:, j], e[:, j])
        gap = dist - two_r
        hit = present[:, 0] & present[:, j] & (gap < CLEARANCE_MARGIN / 2) & (gap < worst)
        if not hit.any():
            continue
        u = cp[hit] - cq[hit]
        nu = np.linalg.norm(u, axis=1, keepdims=True)
        # cores crossing: push sideways, perpendicular to both, towards the thumb's side of the hand
        side = np.cross(e[hit, 0] - s[hit, 0], e[hit, j] - s[hit, j])
        side *= np.sign(np.sum(side * (s[hit, 0] - s[hit, j]), 1, keepdims=True) + 1e-300)
        ns = np.linalg.norm(side, axis=1, keepdims=True)
        side = np.where(ns > 1e-12, side / np.maximum(ns, 1e-12), [[0.0, 1.0, 0.0]])
        u = np.where(nu > 1e-9, u / np.maximum(nu, 1e-12), side)
        worst[hit] = gap[hit]
        push[hit] = u * (CLEARANCE_MARGIN - gap[hit] + 1e-7)[:, None]
    moved = np.isfinite(worst)
    b = slice(XYZ.start, XYZ.start + 3)
    v[moved, b] = np.clip(v[moved, b] + push[moved], lower[b], DECODE_UPPER[b])  # stay in the decoding box
    return bool(moved.any())


def project_plausible(v82: np.ndarray, lower: np.ndarray = DECODE_LOWER) -> np.ndarray:
    """Valid base vectors (N, 82) -> the same hands obeying the rules of :mod:`ohra.learn.geometry`
    (a pushed thumb stays at or above ``lower``, e.g. :data:`RIGHT_FORM_LOWER`).

    1. every present non-thumb knuckle at least as high as the sampler's lowest one (so never
       inside the palm), and neighbouring knuckles more than one finger diameter apart;
    2. a thumb pointing into the palm is turned out by the smallest rotation;
    3. a thumb overlapping a finger at q = 0 is moved off it (repeated, with step 2, some rounds);
    4. a thumb still stuck (jammed between fingers) is tucked below the knuckles, pointing to the
       wrist (:func:`_tuck_stuck_thumbs`; a jump, only for hands far outside the training data).

    Steps 1-3 are continuous in the input, so a smooth latent path stays smooth, and a hand that
    already obeys the rules with these margins comes back unchanged (bit for bit).
    """
    v = np.array(v82, dtype=float, copy=True)
    n = len(v)
    _, fingers = finger_reach(v)
    R = v[:, PALM]
    floor = np.maximum(DEFAULT_CONFIG.knuckle_z_bounds(R)[0], KNUCKLE_MIN_Z * R)
    xyz = v[:, XYZ].reshape(n, 5, 3)
    low = fingers[:, 1:] & (xyz[:, 1:, 2] < floor[:, None])
    if low.any():
        k = xyz[:, 1:, 2]
        k[low] = np.broadcast_to(floor[:, None], k.shape)[low]
        xyz[:, 1:, 2] = k
    _spread_knuckles(xyz, fingers, v[:, FINGER_RADIUS] + CLEARANCE_MARGIN / 2.0, 0.0)
    v[:, XYZ] = xyz.reshape(n, 15)
    for _ in range(_PASSES):
        _turn_thumbs_out(v)
        if not _push_thumbs_off(v, lower):
            break
    _turn_thumbs_out(v)  # the last push may have turned a thumb inwards
    _tuck_stuck_thumbs(v, floor)
    return v


def _tuck_stuck_thumbs(v: np.ndarray, floor: np.ndarray) -> None:
    """In place, the fallback for thumbs the rounds above leave touching a finger or pointing in
    (a thumb jammed between fingers): lower the thumb base below every knuckle and point the thumb
    straight towards the wrist (-z) by the smallest rotation. Such a thumb cannot reach a finger
    (fingers rise from their knuckles) and points away from the palm centre above it."""
    _, fingers = finger_reach(v)
    stuck = fingers[:, 0] & ((thumb_clearance(v) < CLEARANCE_MARGIN / 2) | (thumb_inwardness(v) > -THUMB_OUTWARD_EPS / 2))
    rows = np.flatnonzero(stuck)
    if rows.size == 0:
        return
    z_min = np.where(fingers[rows, 1:], v[rows, XYZ].reshape(-1, 5, 3)[:, 1:, 2], np.inf).min(axis=1)
    z_min = np.minimum(z_min, floor[rows])
    b = XYZ.start + 2
    v[rows, b] = np.maximum(np.minimum(v[rows, b], z_min - v[rows, FINGER_RADIUS] - 2 * CLEARANCE_MARGIN), DECODE_LOWER[b])
    R = rpy_to_matrix(v[rows, THUMB_RPY])
    d = R[:, :, 2]
    down = np.array([0.0, 0.0, -1.0])
    axis = np.cross(d, down)
    s = np.linalg.norm(axis, axis=1)
    angle = np.arctan2(s, d @ down)
    axis = np.where(s[:, None] > 1e-12, axis / np.maximum(s, 1e-12)[:, None], [[1.0, 0.0, 0.0]])
    v[rows, THUMB_RPY] = matrix_to_rpy(rotation_about(axis, angle) @ R)


__all__ = [
    "ENCODING_DIM", "CONT_DIM", "CONT", "ROT6D", "AXIS1", "AXIS2", "FLAGS", "LEFT", "CONT_NAMES", "AXIS_CATEGORIES",
    "is_left", "fill_absent", "encode_vectors", "decode_vectors", "project_plausible",
]
