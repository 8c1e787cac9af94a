"""Wrench balance: the contact forces hold the object in equilibrium without gravity (6 rows ``= 0``).

Torques are taken about the object's centre of mass and divided by ``torque_length`` (default 5 cm),
so force and torque rows have comparable magnitudes.
"""

from __future__ import annotations

from typing import Sequence

import casadi as ca

from ohra.synth.constraints import ConstraintBlock
from ohra.synth.constraints.variables import Contact


def net_wrench(contacts: Sequence[Contact], centre: ca.SX, torque_length: float) -> tuple[ca.SX, ca.SX]:
    """Net force (3x1) and torque about ``centre`` divided by ``torque_length`` (3x1) of the contacts."""
    F = ca.SX.zeros(3)
    Tq = ca.SX.zeros(3)
    for c in contacts:
        F += c.force
        Tq += ca.cross(c.point - centre, c.force) / torque_length
    return F, Tq


def wrench_balance(contacts: Sequence[Contact], centre: ca.SX, torque_length: float) -> ConstraintBlock:
    """Rows ``[Fx, Fy, Fz, Tx, Ty, Tz] = 0`` (see :func:`net_wrench`)."""
    F, Tq = net_wrench(contacts, centre, torque_length)
    return ConstraintBlock.of("wrench", [(F[k], 0.0, 0.0) for k in range(3)] + [(Tq[k], 0.0, 0.0) for k in range(3)])
