"""Constraint families of the grasp NLP, one module each (the way mink gives each task its own file).

Every builder is a function of CasADi expressions (sphere centres, contact forces, an SDF query) that
returns a :class:`ConstraintBlock` of rows ``lower <= g <= upper``; :class:`ohra.synth.nlp.GraspNLP`
only stacks the blocks. :mod:`.variables` owns the decision variables and the hand's geometry in the
object frame (sphere samples of every capsule and of the palm, the contact sites), :mod:`.sdf` the
object's signed distance.

====================  ===========================================================================
module                rows
====================  ===========================================================================
:mod:`.contact`       contact spheres on the surface: ``band[0] <= sdf - r <= band[1]``
:mod:`.clearance`     other capsule samples and the palm clear of the object: ``sdf - r >= gap``
:mod:`.finger_pairs`  spheres of different fingers apart: ``|pa - pb|^2 - (ra + rb + gap)^2 >= 0``
:mod:`.friction`      unit minimum normal force and the (inner) friction cone at each contact
:mod:`.wrench`        force and torque balance about the object centre: 6 rows ``= 0``
:mod:`.objective`     small forces plus a posture prior (a cost, not rows)
====================  ===========================================================================
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import casadi as ca
import numpy as np

from ohra.errors import OhraError


@dataclass(frozen=True)
class ConstraintBlock:
    """Rows ``lower <= g <= upper`` of one constraint family.

    ``g`` holds scalar CasADi SX expressions (units per family, see the module table); ``lower`` and
    ``upper`` are float arrays of the same length (``inf`` for one-sided rows). A block may be empty.
    """

    name: str
    g: tuple[ca.SX, ...]
    lower: np.ndarray
    upper: np.ndarray

    def __post_init__(self) -> None:
        if not (len(self.g) == len(self.lower) == len(self.upper)):
            raise OhraError(f"constraint block {self.name!r}: {len(self.g)} rows, {len(self.lower)} lower, {len(self.upper)} upper bounds")

    def __len__(self) -> int:
        return len(self.g)

    @classmethod
    def of(cls, name: str, rows: Sequence[tuple[ca.SX, float, float]]) -> "ConstraintBlock":
        """Block from ``(expression, lower, upper)`` triples."""
        return cls(name, tuple(r[0] for r in rows), np.array([r[1] for r in rows], dtype=float),
                   np.array([r[2] for r in rows], dtype=float))


def stack(blocks: Sequence[ConstraintBlock]) -> tuple[ca.SX, np.ndarray, np.ndarray, dict[str, slice]]:
    """All rows in block order: ``(g, lower, upper, rows)``; ``rows[name]`` is a block's slice of ``g``."""
    rows, start = {}, 0
    for b in blocks:
        rows[b.name] = slice(start, start + len(b))
        start += len(b)
    g = ca.vertcat(*[e for b in blocks for e in b.g]) if start else ca.SX(0, 1)
    lower = np.concatenate([b.lower for b in blocks]) if blocks else np.zeros(0)
    upper = np.concatenate([b.upper for b in blocks]) if blocks else np.zeros(0)
    return g, lower, upper, rows


__all__ = ["ConstraintBlock", "stack"]
