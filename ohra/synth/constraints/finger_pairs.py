"""Finger pairs: different fingers keep apart, by one of two row families (``NLPSettings.finger_pairs``).

``"capsules"`` (default, exact): one separating plane per pair of capsules on different fingers, any
two fingers (see the section comment above :func:`capsule_pairs`); pairs that never come within
``margin`` of touching (:func:`capsule_reach`) are skipped.

``"spheres"`` (the earlier rows): ``|pa - pb|^2 - (ra + rb + gap)^2 >= 0`` between the capsules' end
spheres (and a middle sphere on long links), the thumb against every finger and other fingers against
their neighbours only; skipped: two knuckle spheres (the first sphere of each finger's first
segment, at fixed spacing) and pairs that never come within ``margin`` of touching (:func:`pair_reach`).
The samples leave gaps: on ``recipes/grasp_unified.yaml`` 202 of Shadow's 720 starts converged to
solutions whose capsules intersect (Coal), 84 of them two proximal links between their spheres and
~50 non-neighbour fingers meeting over a curled one (``benchmarks/results/yield.md``). The pipeline
re-checks every solution exactly with Coal either way.
"""

from __future__ import annotations

from typing import Sequence

import casadi as ca
import numpy as np

from ohra.canonical.kinematics import HandModel
from ohra.synth.constraints import ConstraintBlock
from ohra.synth.constraints.variables import Sphere

_REACH_CACHE: dict[tuple, np.ndarray] = {}  # pair_reach per hand (a few hands per process)
_REACH_CACHE_SIZE = 16


def pair_reach(hand: HandModel, spheres: Sequence[tuple[str, int]], n: int = 4096) -> np.ndarray:
    """(S, S) smallest distance [m] between sphere centres over ``n`` seeded configurations within
    the limits; ``spheres`` are ``(link, end)`` with end 0 start, 1 end, 2 middle of the core segment.

    Depends only on the hand, so it is cached per hand params (it is ~half of a solver build).
    """
    if not spheres:
        return np.zeros((0, 0))
    key = None if hand.params is None else (hand.params.to_json(), tuple(spheres), n)
    if key is not None and key in _REACH_CACHE:
        return _REACH_CACHE[key]
    caps = hand.capsules(hand.random_configurations(n, seed=0))
    k_of = {name: k for k, name in enumerate(caps.link)}
    ends = {0: caps.p0, 1: caps.p1, 2: 0.5 * (caps.p0 + caps.p1)}
    pts = np.stack([ends[end][:, k_of[link]] for link, end in spheres], axis=1)  # (n, S, 3)
    d = np.full((len(spheres), len(spheres)), np.inf)
    for i in range(len(spheres)):
        d[i] = np.linalg.norm(pts - pts[:, i : i + 1], axis=-1).min(axis=0)
    if key is not None:
        if len(_REACH_CACHE) >= _REACH_CACHE_SIZE:
            _REACH_CACHE.pop(next(iter(_REACH_CACHE)))
        _REACH_CACHE[key] = d
    return d


def neighbour_pairs(fingers: Sequence[int]) -> set[tuple[int, int]]:
    """Finger pairs ``(low, high)`` that can touch: thumb (0) with every finger, others with neighbours."""
    order = sorted(f for f in set(fingers) if f != 0)
    return {(a, b) for a, b in zip(order, order[1:])} | {(0, f) for f in order}


def select_pairs(spheres: Sequence[Sphere], reach: np.ndarray, gap: float, margin: float) -> list[tuple[int, int]]:
    """Index pairs ``(i, j)``, i < j, of ``spheres`` that get a row (see the module docstring).

    ``reach[i, j]`` is the pair's smallest centre distance over the joint space [m]; a pair is kept
    when it can come within ``margin`` [m] of violating its row (``ra + rb + gap``).
    """
    neighbours = neighbour_pairs([s.finger for s in spheres])
    first: dict[int, str] = {}  # each finger's first segment (spheres come proximal first): its start is the knuckle
    for s in spheres:
        first.setdefault(s.finger, s.link)
    knuckle = [s.end == 0 and s.link == first[s.finger] for s in spheres]
    out = []
    for i, a in enumerate(spheres):
        for j in range(i + 1, len(spheres)):
            b = spheres[j]
            if (min(a.finger, b.finger), max(a.finger, b.finger)) not in neighbours:
                continue
            if knuckle[i] and knuckle[j]:
                continue
            if reach[i, j] > a.radius + b.radius + gap + margin:
                continue  # these two spheres never come close anywhere in the joint space
            out.append((i, j))
    return out


def finger_pairs(spheres: Sequence[Sphere], pairs: Sequence[tuple[int, int]], gap: float) -> ConstraintBlock:
    """One row per pair ``(i, j)``: squared centre distance minus squared touching distance plus
    ``gap`` [m^2], at least 0 (squared: smooth where the distance is not)."""
    rows = []
    for i, j in pairs:
        a, b = spheres[i], spheres[j]
        d = a.centre - b.centre
        rows.append((ca.dot(d, d) - (a.radius + b.radius + gap) ** 2, 0.0, np.inf))
    return ConstraintBlock.of("finger_pairs", rows)


# -- exact capsule pairs: a separating plane per pair ------------------------------------------------
# Sphere samples leave gaps between them: two capsules of radius r whose core samples are Δ apart can
# interpenetrate by up to 2r + gap - sqrt((2r + gap)^2 - Δ^2) while every sample pair keeps its
# distance (Shadow's 17 mm distal cores: 2.4 mm), and non-neighbour fingers (middle and little over a
# curled ring finger) had no rows at all. Two convex bodies are at least ``gap`` apart iff a plane
# separates them with ``gap / 2`` to spare on each side; a capsule is on one side of a plane with a
# margin iff both ends of its core are, by its radius plus the margin. So per capsule pair (A, B) the
# rows ``n.a_k - c >= r_A + gap/2`` (A's two core ends), ``c - n.b_k >= r_B + gap/2`` (B's) and
# ``|n|^2 <= 1`` over free plane variables ``(n, c)`` hold iff the capsules are ``gap`` apart
# (``|n| < 1`` only makes the margin larger): exact, smooth, 5 rows and 4 variables per pair.


def _segment_distance(p0: np.ndarray, p1: np.ndarray, q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
    """(...,) distance [m] between segments ``p0 p1`` and ``q0 q1`` (arrays (..., 3)), exact
    (closest points by clamped parameters, Ericson's Real-Time Collision Detection §5.1.9)."""
    d1, d2, r = p1 - p0, q1 - q0, p0 - q0
    a, e = np.einsum("...i,...i", d1, d1), np.einsum("...i,...i", d2, d2)
    b, c, f = np.einsum("...i,...i", d1, d2), np.einsum("...i,...i", d1, r), np.einsum("...i,...i", d2, r)
    den = a * e - b * b
    s = np.where(den > 1e-18, np.clip((b * f - c * e) / np.where(den > 1e-18, den, 1.0), 0.0, 1.0), 0.0)
    t = (b * s + f) / np.where(e > 1e-18, e, 1.0)
    s = np.where(t < 0.0, np.clip(-c / np.where(a > 1e-18, a, 1.0), 0.0, 1.0), np.where(t > 1.0, np.clip((b - c) / np.where(a > 1e-18, a, 1.0), 0.0, 1.0), s))
    t = np.clip(t, 0.0, 1.0)
    return np.linalg.norm(p0 + s[..., None] * d1 - (q0 + t[..., None] * d2), axis=-1)


def segment_closest(p0: np.ndarray, p1: np.ndarray, q0: np.ndarray, q1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closest points (3,), (3,) of two segments (one pair; used to start the plane variables)."""
    d1, d2, r = p1 - p0, q1 - q0, p0 - q0
    a, e, b, c, f = d1 @ d1, d2 @ d2, d1 @ d2, d1 @ r, d2 @ r
    den = a * e - b * b
    s = float(np.clip((b * f - c * e) / den, 0.0, 1.0)) if den > 1e-18 else 0.0
    t = (b * s + f) / e if e > 1e-18 else 0.0
    if t < 0.0 or t > 1.0:
        t = float(np.clip(t, 0.0, 1.0))
        s = float(np.clip((b * t - c) / a, 0.0, 1.0)) if a > 1e-18 else 0.0
    return p0 + s * d1, q0 + t * d2


_CAPSULE_REACH: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}


def capsule_reach(hand: HandModel, n: int = 4096) -> tuple[np.ndarray, np.ndarray]:
    """(K, K) smallest and largest distance [m] between the cores of the hand's K finger capsules
    (``hand.capsule_specs`` order) over ``n`` seeded configurations within the limits; cached per hand."""
    key = None if hand.params is None else (hand.params.to_json(), n)
    if key is not None and key in _CAPSULE_REACH:
        return _CAPSULE_REACH[key]
    caps = hand.capsules(hand.random_configurations(n, seed=0))
    K = len(caps.link)
    lo, hi = np.full((K, K), np.inf), np.zeros((K, K))
    for i in range(K):
        for j in range(i + 1, K):
            d = _segment_distance(caps.p0[:, i], caps.p1[:, i], caps.p0[:, j], caps.p1[:, j])
            lo[i, j] = lo[j, i] = d.min()
            hi[i, j] = hi[j, i] = d.max()
    if key is not None:
        if len(_CAPSULE_REACH) >= _REACH_CACHE_SIZE:
            _CAPSULE_REACH.pop(next(iter(_CAPSULE_REACH)))
        _CAPSULE_REACH[key] = (lo, hi)
    return lo, hi


def select_capsule_pairs(fingers: Sequence[int], radii: Sequence[float], reach: tuple[np.ndarray, np.ndarray],
                         gap: float, margin: float) -> list[tuple[int, int]]:
    """Capsule index pairs ``(i, j)``, i < j, on different fingers that get a separating plane.

    Every finger pair is considered (not only neighbours: two fingers meet over a third one curled
    out of their way). Skipped: pairs that never come within ``margin`` [m] of violating the gap
    (``reach[0]``), and pairs that are never ``gap`` apart anywhere in the joint space
    (``reach[1]``: built overlapping, e.g. two knuckles closer than the gap; a row could not hold).
    """
    lo, hi = reach
    out = []
    for i in range(len(fingers)):
        for j in range(i + 1, len(fingers)):
            touch = radii[i] + radii[j] + gap
            if fingers[i] != fingers[j] and lo[i, j] <= touch + margin and hi[i, j] > touch:
                out.append((i, j))
    return out


def capsule_pairs(ends: Sequence[tuple], pairs: Sequence[tuple[int, int]], planes: ca.SX,
                  gap: float) -> ConstraintBlock:
    """Separating-plane rows (see the section comment) of capsule ``pairs``; ``ends[k]`` is capsule
    k's core ends (3x1 SX, object frame, m) and radius [m] (further items ignored), ``planes`` the 4 variables per pair
    ``(n, c)`` in pair order. Row values: the two ends' margins [m] each side, then ``1 - |n|^2``."""
    rows = []
    for k, (i, j) in enumerate(pairs):
        n, c = planes[4 * k : 4 * k + 3], planes[4 * k + 3]
        (a0, a1, ra), (b0, b1, rb) = ends[i][:3], ends[j][:3]
        for p in (a0, a1):
            rows.append((ca.dot(n, p) - c - ra - 0.5 * gap, 0.0, np.inf))
        for p in (b0, b1):
            rows.append((c - ca.dot(n, p) - rb - 0.5 * gap, 0.0, np.inf))
        rows.append((1.0 - ca.dot(n, n), 0.0, np.inf))
    return ConstraintBlock.of("finger_pairs", rows)


def initial_planes(ends: np.ndarray, radii: np.ndarray, pairs: Sequence[tuple[int, int]]) -> np.ndarray:
    """Start values of the plane variables: per pair the unit normal from B's closest core point to
    A's and the offset halfway across the free gap (ends (K, 2, 3) [m], radii (K,) [m])."""
    out = np.zeros(4 * len(pairs))
    for k, (i, j) in enumerate(pairs):
        pa, pb = segment_closest(ends[i, 0], ends[i, 1], ends[j, 0], ends[j, 1])
        d = pa - pb
        n = d / np.linalg.norm(d) if np.linalg.norm(d) > 1e-9 else np.array([1.0, 0.0, 0.0])
        out[4 * k : 4 * k + 3] = n
        out[4 * k + 3] = 0.5 * (n @ pa - radii[i] + n @ pb + radii[j])
    return out
