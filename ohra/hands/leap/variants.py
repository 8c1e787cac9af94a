"""The 256 LEAP variants ``leap_ABCD``: digits = links kept on the thumb, index, middle and little finger.

Each variant is the LEAP template (``template.py``) with fingers shortened to their first
A, B, C, D links (0-3); the ring finger is always absent. Rules (reference §10.2): a finger with 0
links loses its radius, lengths, origins and axes; lengths beyond the kept links are zeroed; a
thumb with one link also drops its j3 origin. Joint limits are kept only for these slots:
thumb 1 link {j1, j2}, 2 {j1, j2, j4}, 3 {j1, j2, j4, j5}; index/middle 1 {j1}, 2 {j1, j2, j3},
3 {j1..j4}; little the same on j1..j4 (j0 never).
"""

from __future__ import annotations

import re
from functools import lru_cache

import numpy as np

from ohra.errors import HandNotFoundError
from ohra.canonical.params import EXT_ROW_START, EXT_ROWS_PER_FINGER, FINGER_SLICES, ExtendedParams
from ohra.hands.leap.template import load_leap_template

VARIANT_RE = re.compile(r"^leap_([0-3])([0-3])([0-3])([0-3])$")
# (finger index, canonical slot offsets within the finger kept for 1, 2, 3 links)
_THUMB_SLOTS = {1: (0, 1), 2: (0, 1, 3), 3: (0, 1, 3, 4)}
_FINGER_SLOTS = {1: (0,), 2: (0, 1, 2), 3: (0, 1, 2, 3)}
_VARIANT_FINGERS = (0, 1, 2, 4)  # thumb, index, middle, little


def variant_names() -> list[str]:
    """All 256 variant names, ``leap_0000`` .. ``leap_3333``."""
    return [f"leap_{a}{b}{c}{d}" for a in range(4) for b in range(4) for c in range(4) for d in range(4)]


def is_variant(name: str) -> bool:
    """Whether ``name`` is a LEAP variant's name, ``leap_ABCD`` (digits 0-3); False for anything not a string."""
    return isinstance(name, str) and bool(VARIANT_RE.match(name))


def parse_variant(name: str) -> tuple[int, int, int, int]:
    m = VARIANT_RE.match(name) if isinstance(name, str) else None
    if not m:
        raise HandNotFoundError(f"{name!r} is not a LEAP variant name (expected leap_ABCD with digits 0-3)")
    return tuple(int(x) for x in m.groups())  # type: ignore[return-value]


@lru_cache(maxsize=512)
def _variant_vector(name: str) -> tuple[float, ...]:
    digits = parse_variant(name)
    t = load_leap_template()
    radii = t.finger_radii.copy()
    lengths = t.finger_lengths.copy()
    origins = t.joint_origins.copy()
    axes = t.joint_axes.copy()
    lo = np.zeros(22)
    up = np.zeros(22)
    for fi, n in zip(_VARIANT_FINGERS, digits):
        rows = slice(EXT_ROW_START[fi], EXT_ROW_START[fi] + EXT_ROWS_PER_FINGER[fi])
        lengths[fi, n:] = 0.0
        if n == 0:
            radii[fi] = 0.0
            origins[rows] = 0.0
            axes[rows] = 0.0
            continue
        if fi == 0 and n == 1:
            origins[EXT_ROW_START[0] + 2] = 0.0
        sl = FINGER_SLICES[("thumb", "index", "middle", "ring", "little")[fi]]
        base = sl.start + (1 if fi == 4 else 0)  # little_joint0 is never kept
        keep = _THUMB_SLOTS[n] if fi == 0 else _FINGER_SLOTS[n]
        idx = [base + k for k in keep]
        lo[idx] = t.joint_lowers[idx]
        up[idx] = t.joint_uppers[idx]
    v = ExtendedParams(
        palm_radius=t.palm_radius, finger_radii=radii, finger_lengths=lengths, joint_origins=origins,
        joint_axes=axes, joint_lowers=lo, joint_uppers=up, template="leap",
    ).to_vector()
    return tuple(float(x) for x in v)


def leap_variant(name: str) -> ExtendedParams:
    """Extended params (LEAP flavour) of variant ``leap_ABCD``."""
    return ExtendedParams.from_vector(np.array(_variant_vector(name)), template="leap")
