"""Objects of the rotation task as PyBullet primitives with exact mass properties.

``cube``, ``sphere`` and ``cylinder`` are sized by one length (cube side, sphere and cylinder
diameter; the cylinder is as long as its diameter and lies along the fingers, so that turning it
about world +z is not a spin about its own symmetry axis). ``builtin:NAME`` takes an ohra built-in
object (``ohra.objects.builtin``) at its own size. Frames: the object frame is the primitive's
centre; ``rest_quat`` (xyzw) is its orientation in the world at yaw 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import trimesh

from ohra.errors import ObjectError

SIZED = ("cube", "sphere", "cylinder")


@dataclass(frozen=True)
class ObjectShape:
    """A rigid object as the rotation scene builds it.

    Attributes:
        name: label.
        prims: primitives ``{"type", "size", "pos"}`` in the object frame (see ``ohra.objects.builtin``).
        mass: kg.
        inertia: (3,) principal moments about the centre of mass [kg m^2], in the object frame axes.
        com: (3,) centre of mass in the object frame [m].
        rest_quat: (4,) xyzw orientation of the object frame in the world at yaw 0.
        half_height: m, extent below the centre along world -z at rest (the resting height above a plane).
        mesh: surface mesh in the object frame (renders and meshcat replays).
    """

    name: str
    prims: tuple[dict, ...]
    mass: float
    inertia: np.ndarray
    com: np.ndarray
    rest_quat: np.ndarray
    half_height: float
    mesh: trimesh.Trimesh


def make_object(name: str, size: float, density: float) -> ObjectShape:
    """The object ``name`` (see module doc) of characteristic length ``size`` [m] and density [kg/m^3]."""
    if name == "cube":
        h = size / 2
        m = density * size**3
        return ObjectShape(name, ({"type": "box", "size": (h, h, h), "pos": (0.0, 0.0, 0.0)},), m,
                           np.full(3, m * size**2 / 6.0), np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]), h,
                           trimesh.creation.box(extents=(size, size, size)))
    if name == "sphere":
        r = size / 2
        m = density * 4.0 / 3.0 * math.pi * r**3
        return ObjectShape(name, ({"type": "sphere", "size": (r,), "pos": (0.0, 0.0, 0.0)},), m,
                           np.full(3, 0.4 * m * r**2), np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]), r,
                           trimesh.creation.icosphere(subdivisions=3, radius=r))
    if name == "cylinder":
        r, length = size / 2, size
        m = density * math.pi * r**2 * length
        ixx = m * (3 * r**2 + length**2) / 12.0
        s = math.sqrt(0.5)  # 90 deg about world y: the axis (object z) lies along world x (the fingers)
        return ObjectShape(name, ({"type": "cylinder", "size": (r, length), "pos": (0.0, 0.0, 0.0)},), m,
                           np.array([ixx, ixx, 0.5 * m * r**2]), np.zeros(3), np.array([0.0, s, 0.0, s]), r,
                           trimesh.creation.cylinder(radius=r, height=length, sections=48))
    if name.startswith("builtin:"):
        return _builtin(name.split(":", 1)[1], density)
    raise ObjectError(f"unknown rotation object {name!r}; expected one of {SIZED} or 'builtin:NAME'")


def _builtin(name: str, density: float) -> ObjectShape:
    from ohra.objects.model import ObjectModel

    obj = ObjectModel.builtin(name, density)
    if not obj.primitives:
        raise ObjectError(f"built-in object {name!r} has no primitive solids; the rotation scene needs primitives")
    I = np.asarray(obj.inertia, dtype=float)
    w, V = np.linalg.eigh(0.5 * (I + I.T))
    if not np.allclose(V, np.diag(np.diag(V)) * np.sign(np.diag(V)), atol=1e-6):
        raise ObjectError(f"built-in object {name!r}: principal axes are not the mesh axes")
    order = np.argmax(np.abs(V), axis=0)  # eigenvector k lies along axis order[k]
    inertia = np.zeros(3)
    inertia[order] = w
    com = np.asarray(obj.center_mass, dtype=float)
    half = float(com[2] - obj.bounds[0][2])
    return ObjectShape(f"builtin:{name}", tuple(obj.primitives), float(obj.mass), np.maximum(inertia, 1e-12), com,
                       np.array([0.0, 0.0, 0.0, 1.0]), half, obj.mesh)
