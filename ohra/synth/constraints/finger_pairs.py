"""Finger pairs: spheres of different fingers keep apart, ``|pa - pb|^2 - (ra + rb + gap)^2 >= 0``.

Which pairs: the thumb against every finger, other fingers against their neighbours (non-neighbours
cannot meet without passing through the finger between them). Skipped: two knuckle spheres (the
first sphere of each finger's first segment, at fixed spacing), and pairs that never come within
``margin`` of touching anywhere in the joint space (:func:`pair_reach`, about half of them). Long
links add a middle sphere (end spheres alone let two closing fingertips cross: ~20 % of 4-finger
solutions); the pipeline still re-checks every solution exactly with Coal.
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
