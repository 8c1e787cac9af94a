"""Couplings: coupled canonical joints follow their drivers, ``q[slot] - a q[driver] - b = 0``.

A hand whose joints move together (URDF ``<mimic>``, tendons, linkages; see
:mod:`ohra.canonical.couplings`) keeps its 22 independent canonical slots; the NLP adds one
equality row per resolved coupling (chains composed to their root driver) so the solver searches
only the coupled manifold. The rows are linear in ``q``, so IPOPT's Newton steps keep them satisfied
to rounding once they hold (radians).
"""

from __future__ import annotations

from typing import Sequence

import casadi as ca
import numpy as np

from ohra.canonical.couplings import Coupling, resolve
from ohra.canonical.params import JOINT_NAMES
from ohra.errors import OhraError
from ohra.synth.constraints import ConstraintBlock


def _slot_value(q: ca.SX, position: dict[int, int], fixed: np.ndarray, k: int) -> ca.SX | float:
    """Canonical slot ``k`` as the decision variable when it is movable, else its fixed value [rad]."""
    return q[position[k]] if k in position else float(fixed[k])


def couplings(q: ca.SX, movable: np.ndarray, fixed: np.ndarray, cs: Sequence[Coupling], tol: float = 1e-9) -> ConstraintBlock:
    """One row ``q[slot] - multiplier * q[driver] - offset`` with ``lower = upper = 0`` per coupling.

    Args:
        q: (nq,) SX, the movable joints in canonical order of ``movable``.
        movable: canonical indices of the entries of ``q``.
        fixed: (22,) values of the slots that are not movable (their locked value) [rad].
        cs: the hand's couplings (resolved here).

    Raises:
        OhraError: a coupling between two immovable slots whose locked values violate it by more
            than ``tol`` (the hand cannot satisfy it; names both slots and the residual).
    """
    position = {int(k): n for n, k in enumerate(movable)}
    rows = []
    for c in resolve(cs):
        slot, driver = _slot_value(q, position, fixed, c.i), _slot_value(q, position, fixed, c.d)
        if c.i not in position and c.d not in position:
            r = float(fixed[c.i]) - (c.multiplier * float(fixed[c.d]) + c.offset)
            if abs(r) > tol:
                raise OhraError(f"coupling {JOINT_NAMES[c.i]} = {c.multiplier:g} * {JOINT_NAMES[c.d]} + {c.offset:g}: "
                                f"both slots are locked and violate it by {r:.3g} rad")
            continue
        rows.append((slot - c.multiplier * driver - c.offset, 0.0, 0.0))
    return ConstraintBlock.of("coupling", rows)
