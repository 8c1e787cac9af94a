"""Clearance: hand spheres that are not contacts stay out of the object, ``sdf(centre) - r >= gap``.

The gap (default 1 mm) keeps non-contact links from grazing the surface, where the simulator would
register extra, uncontrolled contacts.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from ohra.synth.constraints import ConstraintBlock
from ohra.synth.constraints.sdf import SdfQuery
from ohra.synth.constraints.variables import Sphere


def clearance(sdf: SdfQuery, spheres: Sequence[Sphere], gap: float, name: str = "clearance") -> ConstraintBlock:
    """One row per sphere: its gap [m] to the surface, at least ``gap`` [m] (no upper bound)."""
    return ConstraintBlock.of(name, [(sdf.value(s.centre) - s.radius, gap, np.inf) for s in spheres])
