"""Seeded procedural objects: a training set of hundreds of graspable shapes without a download.

``ObjectModel.procedural(family, seed)`` (``procedural:FAMILY:SEED`` on the command line) gives a
deterministic, watertight, convex shape named ``FAMILY-SEED`` whose every full extent lies in
[3, 20] cm (``EXTENT_M``):

- ``box``: edge lengths uniform in the range;
- ``cylinder``: diameter and length uniform in the range;
- ``capsule``: diameter in [3, 10] cm, total length (cylinder + two caps) in [diameter, 20] cm;
- ``ellipsoid``: axis lengths uniform in the range;
- ``superquadric``: axis lengths uniform in the range and shape exponents ``e1`` (along z) and
  ``e2`` (around z) uniform in [0.25, 1.75]: from box-like through ellipsoids to pinched, always
  convex (a superquadric is convex for exponents up to 2).

Boxes, cylinders and capsules are PyBullet primitives with a closed-form signed distance and
closed-form mass properties (exact for solver and simulator alike); ellipsoids and superquadrics
have no closed-form distance and are simulated and grasped as the convex hull of a 642-vertex mesh (more vertices make every PyBullet contact slower)
(``exact`` would be an approximation there: see :mod:`ohra.objects.body`).
"""

from __future__ import annotations

import hashlib
import math
import numbers
from typing import Mapping

import numpy as np
import trimesh

from ohra.errors import ObjectError

FAMILIES = ("superquadric", "box", "cylinder", "capsule", "ellipsoid")
EXTENT_M = (0.03, 0.20)  # every full extent of a procedural object [m]
EXPONENTS = (0.25, 1.75)  # superquadric shape exponents


def _check_seed(seed) -> int:
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or not 0 <= int(seed) < 2**32:
        raise ObjectError(f"a procedural seed is a whole number in [0, 2**32), got {seed!r}")
    return int(seed)


def _rng(family: str, seed: int) -> np.random.Generator:
    # the family is part of the stream: box 3 and cylinder 3 do not share their numbers
    h = int.from_bytes(hashlib.sha256(f"procedural:{family}".encode()).digest()[:4], "little")
    return np.random.default_rng([h, int(seed) & 0xFFFFFFFF])


def _prim(kind: str, size) -> dict:
    return {"type": kind, "size": tuple(float(x) for x in size), "pos": (0.0, 0.0, 0.0)}


def _pow(x: np.ndarray, p: float) -> np.ndarray:
    """``x ** p`` elementwise through the C library's ``pow``, the same bits on every x86-64 CPU.

    NumPy dispatches ``power`` to SIMD kernels by CPU (AVX-512 machines use SVML, others libm), and
    the two differ in the last bit: the superquadric's vertices, hence its mesh hash, depended on the
    machine that made it (a dataset built on one could not be loaded on another). A few thousand
    scalar calls cost well under a millisecond.
    """
    return np.fromiter((math.pow(float(v), p) for v in np.ravel(x)), dtype=np.float64, count=np.size(x)).reshape(np.shape(x))


def superquadric_mesh(axes: np.ndarray, e1: float, e2: float, subdivisions: int = 3) -> trimesh.Trimesh:
    """Watertight mesh of the superquadric ``(|x/a|^(2/e2) + |y/b|^(2/e2))^(e2/e1) + |z/c|^(2/e1) = 1``:
    an icosphere's vertices pushed radially onto the surface (a superquadric is star-shaped, so the
    topology stays closed)."""
    ico = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0)
    u = np.asarray(ico.vertices)
    a, b, c = axes
    f = _pow(_pow(np.abs(u[:, 0] / a), 2 / e2) + _pow(np.abs(u[:, 1] / b), 2 / e2), e2 / e1) + _pow(np.abs(u[:, 2] / c), 2 / e1)
    # the inside-outside function is homogeneous of degree 2/e1 along a ray: F(s u) = s^(2/e1) F(u)
    v = u * _pow(f, -e1 / 2)[:, None]
    return trimesh.Trimesh(v, ico.faces, process=False)


def procedural_parts(family: str, seed: int) -> tuple[trimesh.Trimesh, list[dict] | None, dict]:
    """(surface mesh, primitives or None, sampled parameters) of ``family`` and ``seed``."""
    if family not in FAMILIES:
        raise ObjectError(f"unknown procedural family {family!r}; known: {', '.join(FAMILIES)}")
    rng = _rng(family, seed)
    lo, hi = EXTENT_M
    if family == "box":
        ext = rng.uniform(lo, hi, 3)
        return trimesh.creation.box(extents=ext), [_prim("box", ext / 2)], {"extents_m": ext.tolist()}
    if family == "cylinder":
        d, length = rng.uniform(lo, hi, 2)
        m = trimesh.creation.cylinder(radius=d / 2, height=length, sections=96)
        return m, [_prim("cylinder", (d / 2, length))], {"diameter_m": float(d), "length_m": float(length)}
    if family == "capsule":
        d = rng.uniform(lo, 0.10)
        total = rng.uniform(d, hi)
        m = trimesh.creation.capsule(height=total - d, radius=d / 2, count=[48, 48])
        return m, [_prim("capsule", (d / 2, total - d))], {"diameter_m": float(d), "length_m": float(total)}
    axes = rng.uniform(lo, hi, 3) / 2
    e1, e2 = rng.uniform(*EXPONENTS, 2) if family == "superquadric" else (1.0, 1.0)
    return superquadric_mesh(axes, e1, e2), None, {"semi_axes_m": axes.tolist(), "e1": float(e1), "e2": float(e2)}


def make_procedural(cls, family: str, seed: int, density: float):
    """The :class:`~ohra.objects.model.ObjectModel` of ``family`` and ``seed`` (see the module doc).

    Raises:
        ObjectError: ``seed`` not a whole number in [0, 2**32) (the stream keeps 32 bits: a larger or
            negative seed would alias another one's shape under its own name).
    """
    seed = _check_seed(seed)
    mesh, prims, params = procedural_parts(family, int(seed))
    obj = cls(mesh, f"{family}-{int(seed)}", density, None, None if prims is None else [mesh.convex_hull],
              repair=False, primitives=prims)
    obj.procedural_params = {"family": family, "seed": int(seed), **params}
    return obj


def procedural_objects(family: str, count: int, seed: int = 0, density: float | None = None) -> list:
    """``count`` objects of ``family`` with seeds ``seed .. seed + count - 1``.

    Raises:
        ObjectError: ``count`` not a whole number >= 1; a seed outside [0, 2**32).
    """
    from ohra.objects.model import DEFAULT_DENSITY, ObjectModel

    if isinstance(count, bool) or not isinstance(count, numbers.Integral) or count < 1:
        raise ObjectError(f"procedural {family}: count must be a whole number >= 1, got {count!r}")
    _check_seed(seed)
    if seed + count - 1 >= 2**32:
        raise ObjectError(f"procedural {family}: seeds {seed} .. {seed + count - 1} pass 2**32 - 1, the largest seed")

    return [ObjectModel.procedural(family, s, density or DEFAULT_DENSITY) for s in range(int(seed), int(seed) + int(count))]


def same_procedural_object(a: Mapping, b: Mapping, rtol: float = 1e-9) -> bool:
    """Whether two object descriptions (manifest entries: ``source``, ``faces``, ``extents_m``,
    ``volume_m3``) are the same procedural object: same ``procedural:FAMILY:SEED``, face count, and
    extents and volume within relative ``rtol``.

    A procedural object is defined by its family and seed. Its vertices' last bits depended on the
    CPU that generated them before :func:`superquadric_mesh` used :func:`_pow`, so manifests made on
    an AVX-512 machine carry mesh hashes others cannot reproduce; for these objects the geometry
    decides. Real meshes are never matched this way (their hash is exact on every machine).
    """
    src = str(a.get("source", ""))
    if not src.startswith("procedural:") or src != str(b.get("source", "")):
        return False
    try:
        ea, eb = np.asarray(a["extents_m"], float), np.asarray(b["extents_m"], float)
        va, vb = float(a["volume_m3"]), float(b["volume_m3"])
        same_faces = int(a["faces"]) == int(b["faces"])
    except (KeyError, TypeError, ValueError):
        return False
    return (same_faces and ea.shape == eb.shape == (3,) and bool(np.allclose(ea, eb, rtol=rtol, atol=0.0))
            and abs(va - vb) <= rtol * abs(vb))
