"""Contact band: each contact sphere touches the surface, ``band[0] <= sdf(centre) - r <= band[1]``.

A band rather than an equality: the solver settles a contact within it (default -0.5 .. +1 mm), which
keeps the problem feasible under the SDF spline's interpolation error and costs no quality (the
simulator's squeeze closes the last millimetre).
"""

from __future__ import annotations

from typing import Sequence

from ohra.synth.constraints import ConstraintBlock
from ohra.synth.constraints.sdf import SdfQuery
from ohra.synth.constraints.variables import Contact


def contact_band(sdf: SdfQuery, contacts: Sequence[Contact], band: tuple[float, float]) -> ConstraintBlock:
    """One row per contact: the gap [m] between the contact sphere and the surface, within ``band`` [m]."""
    lo, hi = band
    return ConstraintBlock.of("contact", [(sdf.value(c.centre) - c.radius, lo, hi) for c in contacts])
