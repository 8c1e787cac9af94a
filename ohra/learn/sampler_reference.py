"""The reference (paper) sampler's distribution, kept to reproduce the diagnosis of the 66-D model
trained on it (``benchmarks/diagnose_vae.py``) and to compare old and new models on their own data.

Same joint patterns as :mod:`ohra.learn.sampler` minus Barrett's thumb; the ranges of the reference
(``ohra_reference.md`` §7.1, quirks fixed as DESIGN decision 4); the thumb mounting rotation uniform in
the Euler cube ``[-pi, pi]^3``. Units: metres and radians, canonical palm frame.

:func:`sample_reference_vectors` is the previous ``sample_vectors``: the steps it shares with
:mod:`ohra.learn.sampler` (count check and handedness draw, finger use, joint presence, Dirichlet gaps, thumb axes, segment mask,
vector assembly) are that module's helpers, called in the same order with the same random draws, so
its draws stay bit-identical, seed for seed, to the code the reference model's training data came from.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ohra.learn.sampler import (
    FINGER_PATTERNS, THUMB_PATTERNS, _base_vectors, _dirichlet_gaps, _finger_use, _joint_presence, _segment_mask,
    _start, _thumb_axes,
)

REFERENCE_THUMB_PATTERNS = THUMB_PATTERNS[:6]  # the reference never draws a thumb without joint 1


@dataclass(frozen=True)
class ReferenceSamplerConfig:
    """Ranges of the reference sampler [m, rad]; ``U(a, b)`` unless noted."""

    p_finger: float = 0.75  # each non-thumb finger present (at least 2 of 4 forced)
    p_little_joint0: float = 0.8  # extra little joint, only when >= 20 joints are present
    palm_radius: tuple[float, float] = (0.04, 0.06)
    finger_radius: tuple[float, float] = (0.0075, 0.012)  # upper bound also <= palm_radius / 4
    thumb_lengths: tuple[float, float] = (0.035, 0.07)
    finger_lengths: tuple[float, float] = (0.025, 0.07)
    thumb_x: tuple[float, float] = (-0.02, 0.02)
    thumb_y: tuple[float, float] = (0.0, 0.04)  # |y|, on the thumb side
    thumb_z: tuple[float, float] = (0.015, 0.025)
    knuckle_x_std: float = 0.001  # N(0, std^2), shared by the non-thumb fingers
    knuckle_z_offset: float = -0.01  # N(2 R + offset, std^2) per finger
    knuckle_z_std: float = 0.005
    extra_x: tuple[float, float] = (-0.01, 0.01)
    extra_y: tuple[float, float] = (0.03, 0.04)  # |y|, on the little finger's side
    extra_z: tuple[float, float] = (0.018, 0.025)
    extra_roll: tuple[float, float] = (5 * math.pi / 16, 7 * math.pi / 16)  # |roll|; right hand positive
    joint_upper: float = math.pi / 2


REFERENCE_CONFIG = ReferenceSamplerConfig()


def sample_reference_vectors(n: int, seed: int, config: ReferenceSamplerConfig = REFERENCE_CONFIG,
                             return_handedness: bool = False):
    """``n`` random hands as an (n, 82) array of base vectors (canonical key order).

    Deterministic given ``seed``. With ``return_handedness`` also returns an (n,) bool array, True
    for right hands. Every row is a valid :class:`BaseParams` vector.
    """
    n, rng, right = _start(n, seed)
    c = config
    side = np.where(right, 1.0, -1.0)  # +1: thumb at +y

    # -- fingers: thumb always; >= 2 of the 4 non-thumb fingers --------------------------------
    use = _finger_use(rng, n, c.p_finger)
    k = use.sum(axis=1)  # active non-thumb fingers, 2..4

    # -- joint patterns (uniform, unlike the sampler's odds) -----------------------------------
    thumb_pat = REFERENCE_THUMB_PATTERNS[rng.integers(0, len(REFERENCE_THUMB_PATTERNS), n)]
    finger_pat = FINGER_PATTERNS[rng.integers(0, len(FINGER_PATTERNS), n)]
    present = _joint_presence(rng, thumb_pat, finger_pat, use, c.p_little_joint0)

    # -- sizes -----------------------------------------------------------------------------------
    R = rng.uniform(*c.palm_radius, n)
    r = rng.uniform(c.finger_radius[0], np.minimum(c.finger_radius[1], R / 4.0))
    lengths = np.concatenate([rng.uniform(*c.thumb_lengths, (n, 3)), rng.uniform(*c.finger_lengths, (n, 3))], axis=1)

    # -- positions -------------------------------------------------------------------------------
    xyz = np.zeros((n, 5, 3))
    xyz[:, 0, 0] = rng.uniform(*c.thumb_x, n)
    xyz[:, 0, 1] = rng.uniform(*c.thumb_y, n) * side
    xyz[:, 0, 2] = rng.uniform(*c.thumb_z, n)
    xyz[:, 1:, 0] = rng.normal(0.0, c.knuckle_x_std, n)[:, None]
    xyz[:, 1:, 2] = rng.normal(2.0 * R[:, None] + c.knuckle_z_offset, c.knuckle_z_std, (n, 4))
    # Knuckles across the palm without overlap: k capsules of diameter d = 2r in the span
    # [r - R, R - r] with Dirichlet-distributed free space between them, index first (thumb side).
    d = 2.0 * r
    space = np.maximum(2.0 * (R - r) - (k - 1) * d, 0.0)
    cum = _dirichlet_gaps(rng, k)  # cum[:, i] = share of the first i + 1 of the k + 1 gaps
    order = np.cumsum(use, axis=1) - 1  # rank of each active finger, index -> little
    rank = np.clip(order, 0, 3)
    y_mag = (r - R)[:, None] + np.take_along_axis(cum, rank, axis=1) * space[:, None] + rank * d[:, None]
    # Pre-flip the index finger is most negative; a right hand (side=+1) mirrors to index at +y.
    xyz[:, 1:, 1] = -y_mag * side[:, None]
    finger_present = np.concatenate([np.ones((n, 1), dtype=bool), use], axis=1)
    xyz[~finger_present] = 0.0

    # -- thumb orientation and axes --------------------------------------------------------------
    thumb_rpy = rng.uniform(-math.pi, math.pi, (n, 3))
    axes = _thumb_axes(rng, present)

    # -- little finger metacarpal frame, on the little finger's side (-y for a right hand) -------
    extra = np.zeros((n, 6))
    extra[:, 0] = rng.uniform(*c.extra_x, n)
    extra[:, 1] = -side * rng.uniform(*c.extra_y, n)
    extra[:, 2] = rng.uniform(*c.extra_z, n)
    extra[:, 3] = side * rng.uniform(*c.extra_roll, n)
    extra[~present[:, 17]] = 0.0

    lengths *= _segment_mask(present, finger_pat)
    out = _base_vectors(R, r, lengths, xyz, extra, thumb_rpy, axes, present, c.joint_upper)
    if return_handedness:
        return out, right
    return out
