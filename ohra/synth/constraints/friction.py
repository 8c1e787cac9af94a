"""Friction cones: each contact force pushes with a unit minimum normal force inside a friction cone.

The force ``f`` is what the hand applies to the object; with the outward normal ``n`` its normal part
is ``fn = -f.n`` and its tangential part ``ft = f + fn n``. Rows per contact: ``fn >= 1`` (fixes the
scale of the otherwise homogeneous equilibrium) and ``(mu_in fn)^2 - |ft|^2 >= 0``.

The circular cone is shrunk to lie strictly inside the 8-facet pyramid that Ferrari-Canny's Q1 uses
(``mu_in = mu cos(pi/8) 0.95``), so an equilibrium found here is one of strictly interior forces
(force closure, Q1 > 0).
"""

from __future__ import annotations

from typing import Sequence

import casadi as ca
import numpy as np

from ohra.synth.constraints import ConstraintBlock
from ohra.synth.constraints.variables import Contact

MIN_NORMAL_FORCE = 1.0  # normalised units: the NLP's forces are scale-free


def inner_mu(mu: float) -> float:
    """Friction coefficient of the circular cone the NLP uses for a design friction ``mu``."""
    return mu * np.cos(np.pi / 8) * 0.95  # the pyramid's inscribed cone, with a 5 % margin


def friction_cones(contacts: Sequence[Contact], mu: float) -> ConstraintBlock:
    """Rows ``[fn_0, cone_0, fn_1, cone_1, ...]``: normal force >= 1 and cone margin >= 0 per contact."""
    rows = []
    mu_in = inner_mu(mu)
    for c in contacts:
        fn = -ca.dot(c.force, c.normal)
        ft = c.force + fn * c.normal
        rows.append((fn, MIN_NORMAL_FORCE, np.inf))
        rows.append((mu_in**2 * fn * fn - ca.dot(ft, ft), 0.0, np.inf))
    return ConstraintBlock.of("friction", rows)
