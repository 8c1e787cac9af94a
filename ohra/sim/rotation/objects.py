"""Objects of the rotation task with exact mass properties: PyBullet primitives or convex pieces.

``cube``, ``sphere`` and ``cylinder`` are sized by one length (cube side, sphere and cylinder
diameter; the cylinder is as long as its diameter and lies along the fingers, so that turning it
about world +z is not a spin about its own symmetry axis). Any other object ohra resolves
(``builtin:NAME``, ``procedural:FAMILY:SEED``, a mesh or URDF file or a one-object folder) is taken as
the body :class:`ohra.objects.ObjectModel` simulates (its primitives, else its convex pieces) at its own
size, or scaled so that its largest extent is ``size`` when one is given (file objects only). Frames: the
object frame is the primitive's centre for the sized objects, the mesh frame otherwise; ``rest_quat``
(xyzw) is its orientation in the world at yaw 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

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
        inertia_quat: (4,) xyzw orientation of the principal axes (``inertia``'s frame) in the object frame.
        pieces: convex collision pieces in the object frame, for an object without primitives.
        digest: what identifies the geometry beyond ``prims`` (a mesh object's body hash), for caches.
    """

    name: str
    prims: tuple[dict, ...]
    mass: float
    inertia: np.ndarray
    com: np.ndarray
    rest_quat: np.ndarray
    half_height: float
    mesh: trimesh.Trimesh
    inertia_quat: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 0.0, 1.0]))
    pieces: tuple[trimesh.Trimesh, ...] = ()
    digest: str = ""


def make_object(name: str, size: float | None, density: float) -> ObjectShape:
    """The object ``name`` (see module doc) of characteristic length ``size`` [m] (``None``: its own size, for
    objects other than the sized shapes) and density [kg/m^3].

    Raises:
        ObjectError: an unknown object; a sized shape without a size; an object whose largest extent lies
            outside the graspable range (``ohra.objects.resolve.GRASPABLE_EXTENT_M``), e.g. a mesh in millimetres.
    """
    if name in SIZED and not (size is not None and size > 0):
        raise ObjectError(f"object {name!r} needs a size > 0 [m], got {size!r}")
    shape = _make(name, size, density)
    _check_size(shape, size)
    return shape


def _check_size(shape: "ObjectShape", size: float | None) -> None:
    """Refuse an object no hand can hold: the task would run (a 100 m capsule 'held' 50 m up) and mean nothing."""
    from ohra.objects.resolve import GRASPABLE_EXTENT_M

    ext = float(np.max(shape.mesh.extents))
    lo, hi = GRASPABLE_EXTENT_M
    if lo <= ext <= hi:
        return
    how = ("set object_size (--object-size M) within that range" if size is not None else
           "if its units are wrong (a mesh in millimetres?), give its largest extent in metres with object_size "
           "(--object-size M)")
    raise ObjectError(f"rotation object {shape.name!r}: largest extent {ext:.4g} m is outside the graspable range "
                      f"{lo:g}-{hi:g} m; {how}")


def _make(name: str, size: float | None, density: float) -> "ObjectShape":
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
    return from_model(name, size, density)


def resolve_model(spec: str, density: float, size: float | None = None):
    """The one :class:`ohra.objects.ObjectModel` ``spec`` names, at ``density``; a file object is scaled so its
    largest extent is ``size`` [m] when given."""
    from ohra.objects.model import resolve_objects

    if not spec.strip() or not (spec.startswith(("builtin:", "procedural:")) or Path(spec).expanduser().exists()):
        raise ObjectError(f"unknown rotation object {spec!r}; expected one of {SIZED}, builtin:NAME, "
                          "procedural:FAMILY:SEED, or a mesh/URDF file or folder that exists")
    if size is not None and spec.startswith(("builtin:", "procedural:")):
        raise ObjectError(f"object {spec!r} keeps its own size: object_size scales cube, sphere, cylinder and "
                          "mesh files only")
    objs = resolve_objects(spec)
    if len(objs) != 1:
        raise ObjectError(f"object {spec!r} names {len(objs)} objects, expected one")
    obj = objs[0]
    if size is not None:
        obj = resolve_objects(spec, scale=float(size) / float(np.max(obj.mesh.extents)))[0]
    obj.density = float(density)
    return obj


def from_model(spec: str, size: float | None, density: float) -> ObjectShape:
    """The rotation object of any object spec ohra resolves (module doc): primitives when the object has them,
    else the convex pieces of its simulated body; mass properties of that body."""
    from ohra.rotations import matrix_to_quat

    obj = resolve_model(spec, density, size)
    I = np.asarray(obj.inertia, dtype=float)
    w, V = np.linalg.eigh(0.5 * (I + I.T))
    if np.linalg.det(V) < 0:
        V[:, 0] *= -1
    com = np.asarray(obj.center_mass, dtype=float)
    half = float(com[2] - obj.bounds[0][2])
    prims = tuple(dict(p) for p in obj.primitives) if obj.primitives else ()
    pieces = () if prims else tuple(obj.convex_pieces())
    return ObjectShape(spec, prims, float(obj.mass), np.maximum(w, 1e-12), com, np.array([0.0, 0.0, 0.0, 1.0]), half,
                       obj.mesh, np.asarray(matrix_to_quat(V), dtype=float), pieces, "" if prims else obj.body_hash)
