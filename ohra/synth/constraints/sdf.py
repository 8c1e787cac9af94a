"""The object's signed distance as CasADi expressions, with all queries evaluated by one mapped call.

:meth:`SdfQuery.value` returns a placeholder symbol per query; :meth:`SdfQuery.resolve` substitutes
every placeholder at once by one ``map`` of the distance function over all query points (one graph
node for all of them: ~15 % faster derivatives than one call node per query). Normals are inlined
(the gradient of the distance function at the point, normalised).
"""

from __future__ import annotations

from typing import Callable

import casadi as ca
import numpy as np

from ohra.objects.model import SDFGrid


def sdf_bspline(grid: SDFGrid) -> ca.Function:
    """The C2 cubic B-spline that interpolates an SDF grid exactly at its nodes, as a CasADi Function.

    The coefficients come from scipy's recursive prefilter (mirror boundary), the same spline as
    ``scipy.ndimage.map_coordinates(order=3, mode="mirror")``; this takes milliseconds where
    ``casadi.interpolant(..., "bspline")`` solves a 100k-unknown fit in seconds. Valid inside the grid.
    """
    from scipy import ndimage

    n = np.array(grid.shape)
    coeffs = np.pad(ndimage.spline_filter(grid.values, order=3, mode="mirror"), 1, mode="reflect")
    knots = [list(grid.origin[d] + grid.spacing * np.arange(-3, n[d] + 3)) for d in range(3)]
    spline = ca.Function.bspline("sdf_spline", knots, coeffs.ravel(order="F").tolist(), [3, 3, 3], 1, {})
    x = ca.MX.sym("x", 3)
    return ca.Function("sdf", [x], [spline(x)])


class SdfQuery:
    """Signed distance [m] and outward unit normal of an object at symbolic points (object frame).

    Args:
        phi: a CasADi Function of one 3-vector (object frame, m) to the signed distance (m,
            negative inside), whose SX expression may contain call nodes (the B-spline).
    """

    def __init__(self, phi: ca.Function):
        self.phi = phi
        p = ca.SX.sym("p", 3)
        self._grad = ca.Function("grad_phi", [p], [ca.gradient(phi(p), p)])
        self._pending: list[tuple[ca.SX, ca.SX]] = []

    @classmethod
    def from_grid(cls, grid: SDFGrid) -> "SdfQuery":
        """Query of the exact-interpolating B-spline of ``grid``; outside the grid the distance
        continues as the spline at the clamped point plus the distance to it (an upper bound)."""
        spline = sdf_bspline(grid)
        p = ca.SX.sym("p", 3)
        pc = ca.fmin(ca.fmax(p, grid.origin + 1e-6), grid.upper - 1e-6)
        # an SX call node (never inlined: the B-spline node has no SX form)
        dist = spline.call([pc], False, True)[0] + ca.sqrt(ca.dot(p - pc, p - pc) + 1e-12) - 1e-6
        return cls(ca.Function("phi", [p], [dist]))

    @classmethod
    def analytic(cls, fn: Callable[[ca.SX], ca.SX]) -> "SdfQuery":
        """Query of a closed-form distance ``fn(p)`` (tests: a sphere's ``|p - c| - R``)."""
        p = ca.SX.sym("p", 3)
        return cls(ca.Function("phi", [p], [fn(p)]))

    def value(self, p: ca.SX) -> ca.SX:
        """Signed distance [m] at ``p`` (3x1, object frame), as a placeholder until :meth:`resolve`."""
        sym = ca.SX.sym(f"phi{len(self._pending)}")
        self._pending.append((sym, p))
        return sym

    def normal(self, p: ca.SX) -> ca.SX:
        """Outward unit normal (3x1, object frame) at ``p``: the normalised distance gradient."""
        grad = self._grad(p)
        return grad / ca.sqrt(ca.dot(grad, grad) + 1e-12)

    def resolve(self, expr: ca.SX) -> ca.SX:
        """``expr`` with every placeholder made so far replaced by its distance (one mapped call)."""
        if not self._pending:
            return expr
        P = ca.horzcat(*[p for _, p in self._pending])
        vals = self.phi.map(len(self._pending))(P)
        return ca.substitute([expr], [ca.vertcat(*[v for v, _ in self._pending])], [vals.T])[0]
