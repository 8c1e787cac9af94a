"""Grasp quality: the Ferrari-Canny epsilon metric (Q1) for point contacts with Coulomb friction."""

from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from ohra.objects.model import ObjectModel


def contact_normals(points: np.ndarray, obj: ObjectModel, h: float = 1e-3) -> np.ndarray:
    """Outward unit normals at surface points from central differences of the object's SDF grid."""
    g = obj.sdf()
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    grad = np.zeros_like(p)
    for k in range(3):
        e = np.zeros(3)
        e[k] = h
        grad[:, k] = (g.query(p + e) - g.query(p - e)) / (2 * h)
    return grad / np.maximum(np.linalg.norm(grad, axis=1, keepdims=True), 1e-12)


def contact_wrenches(points: np.ndarray, normals: np.ndarray, center: np.ndarray, mu: float = 0.5,
                     torque_length: float = 0.05, facets: int = 8) -> np.ndarray:
    """(N * facets, 6) wrenches [force, torque / ``torque_length``] of the linearised friction cones.

    Contact ``i`` at ``points[i]`` with *outward* unit normal ``normals[i]`` pushes on the object:
    each cone edge is ``-n + mu * t`` (unit normal force, into the object) for ``facets`` tangents
    ``t`` evenly spaced around ``n``; torques are about ``center`` (the centre of mass) [m].
    """
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    n = np.asarray(normals, dtype=float).reshape(-1, 3)
    wrenches = []
    for pi, ni in zip(p, n):
        a = np.cross(ni, [1.0, 0.0, 0.0])
        if np.linalg.norm(a) < 1e-6:
            a = np.cross(ni, [0.0, 1.0, 0.0])
        a /= np.linalg.norm(a)
        b = np.cross(ni, a)
        for k in range(facets):
            th = 2 * np.pi * k / facets
            f = -ni + mu * (np.cos(th) * a + np.sin(th) * b)
            wrenches.append(np.concatenate([f, np.cross(pi - center, f) / torque_length]))
    return np.array(wrenches).reshape(-1, 6)


def ferrari_canny(points: np.ndarray, obj: ObjectModel, mu: float = 0.5, torque_length: float = 0.05, facets: int = 8,
                  normals: np.ndarray | None = None) -> float:
    """Q1: radius of the largest origin-centred ball in the convex hull of the contact wrenches.

    Wrenches: :func:`contact_wrenches` about the object's centre of mass. ``normals`` (outward,
    unit) default to the SDF gradient at the points. Returns 0 when the origin is not strictly
    inside the hull (no force closure).
    """
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    if len(p) < 2:
        return 0.0
    n = contact_normals(p, obj) if normals is None else np.asarray(normals, dtype=float).reshape(-1, 3)
    W = contact_wrenches(p, n, obj.center_mass, mu, torque_length, facets)
    try:
        hull = ConvexHull(W)
    except (QhullError, ValueError):
        return 0.0
    # facet equations: normal . x + offset <= 0 inside; distance of the origin = -offset
    d = -hull.equations[:, -1]
    return float(max(d.min(), 0.0))
