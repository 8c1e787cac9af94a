"""Objects named on the command line or in recipes, and the size check before synthesis."""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np

from ohra.errors import ObjectError, ObjectWarning, user_stacklevel
from ohra.objects.model import BODY_CHOICES, MESH_SUFFIXES, ObjectModel, builtin_object_names

# largest extent [m] of an object a hand can grasp; outside it the units are almost surely wrong
# (a millimetre mesh read as metres is a 75 m apple) or the object is a speck or a wall
GRASPABLE_EXTENT_M = (0.01, 0.5)


def resolve_objects(spec: list[str] | str | None, scale: float | None = None, body: str = "auto") -> list[ObjectModel]:
    """Objects from specs: ``builtin`` (all built-ins), ``builtin:NAME``, ``procedural:FAMILY:SEED``,
    a mesh/URDF file, or a folder (each sub-folder or mesh file in it). ``scale`` multiplies the
    coordinates of objects read from files (e.g. 0.001 for millimetre meshes); ``body`` picks the body they are
    grasped and simulated as (:data:`~ohra.objects.model.BODY_CHOICES`; built-in and procedural shapes keep their
    exact solids)."""
    if scale is not None and not (isinstance(scale, (int, float)) and math.isfinite(scale) and scale > 0):
        raise ObjectError(f"scale must be a number > 0, got {scale!r}")
    if body not in BODY_CHOICES:
        raise ObjectError(f"body must be one of {', '.join(BODY_CHOICES)}, got {body!r}")
    specs = [spec] if isinstance(spec, (str, Path)) else list(spec or ["builtin"])
    for s in specs:
        if not isinstance(s, (str, Path)) or not str(s).strip():  # Path("") is the current folder
            raise ObjectError(f"object spec {s!r}: expected builtin, builtin:NAME, procedural:FAMILY:SEED or a mesh/URDF "
                              "file or folder")
    specs = [str(s) for s in specs]
    sized = [s for s in specs if s == "builtin" or s.startswith(("builtin:", "procedural:"))]
    them = f"{', '.join(sized)} keep{'s' if len(sized) == 1 else ''}"
    if scale is not None and scale != 1.0 and sized:
        warnings.warn(f"scale {scale:g} applies to objects read from files; {them} its own size (built-in and procedural "
                      "shapes are made in metres)", ObjectWarning, stacklevel=user_stacklevel())
    if body != "auto" and sized:
        warnings.warn(f"body {body!r} applies to objects read from files; {them} its exact solid (built-in and procedural "
                      "shapes are simulated as what they are)", ObjectWarning, stacklevel=user_stacklevel())
    out: list[ObjectModel] = []
    for s in specs:
        if s == "builtin":
            out += [ObjectModel.builtin(n) for n in builtin_object_names()]
        elif s.startswith("builtin:"):
            out.append(ObjectModel.builtin(s.split(":", 1)[1]))
        elif s.startswith("procedural:"):
            out.append(parse_procedural(s))
        else:
            out += _from_path(Path(s), scale, body)
    return out


def resolve_object(obj: "ObjectModel | str | Path", scale: float | None = None, body: str = "auto") -> ObjectModel:
    """One object from an ObjectModel or a spec.

    Args:
        obj: an :class:`ObjectModel` (returned as is), ``builtin:NAME``, ``procedural:FAMILY:SEED``, or
            a mesh / URDF file or folder that holds exactly one object.
        scale: multiplies the coordinates of an object read from a file (e.g. 0.001 for a millimetre mesh).
        body: the body an object read from a file is grasped and simulated as (:data:`~ohra.objects.model.BODY_CHOICES`).

    Returns:
        The object; its mesh in its mesh frame [m].

    Raises:
        ObjectError: ``obj`` is of another type, is not found or unusable, or names more than one object.
    """
    if isinstance(obj, ObjectModel):
        return obj
    if not isinstance(obj, (str, Path)):
        raise ObjectError(f"object: expected an ObjectModel, builtin:NAME or a mesh path, got {type(obj).__name__}")
    objs = resolve_objects(str(obj), scale=scale, body=body)
    if len(objs) != 1:
        raise ObjectError(f"object {str(obj)!r} names {len(objs)} objects, expected one")
    return objs[0]


def parse_procedural(spec: str) -> ObjectModel:
    """``procedural:FAMILY:SEED`` -> :meth:`ObjectModel.procedural`."""
    parts = spec.split(":")
    if len(parts) != 3 or not parts[2].isdigit():
        raise ObjectError(f"procedural object spec {spec!r}: expected procedural:FAMILY:SEED (SEED a whole number >= 0)")
    return ObjectModel.procedural(parts[1], int(parts[2]))


def _from_path(p: Path, scale: float | None, body: str = "auto") -> list[ObjectModel]:
    if not p.exists():
        hint = f" (the built-in object: builtin:{p.name})" if str(p) in builtin_object_names() else ""
        if not hint and not p.suffix and len(p.parts) == 1:  # a bare word: perhaps a built-in shape by another name
            hint = (f" (built-in objects: {', '.join('builtin:' + n for n in builtin_object_names())}; procedural shapes: "
                    "procedural:FAMILY:SEED)")
        head, sep, rest = str(p).partition(":")
        if sep and head.lower() in ("builtin", "procedural") and head != head.lower():  # the prefixes are lower case
            hint = f" (the {head.lower()} object: {head.lower()}:{rest})"
        raise ObjectError(f"object file or folder not found: {p}{hint}")
    if p.is_dir() and not any(p.glob("*.obj")) and not any(p.glob("*.urdf")):
        # hidden entries (.git, .ci, .ipynb_checkpoints) are not objects
        subs = sorted(d for d in p.iterdir() if d.is_dir() and not d.name.startswith("."))
        files = sorted(f for f in p.iterdir() if f.suffix.lower() in MESH_SUFFIXES and not f.name.startswith("."))
        if not subs and not files:
            raise ObjectError(f"{p}: folder holds no objects")
        return ([ObjectModel.load(d, scale=scale, body=body) for d in subs]
                + [ObjectModel.load(f, scale=scale, body=body) for f in files])
    return [ObjectModel.load(p, scale=scale, body=body)]


def size_problem(obj: ObjectModel, extent_range: tuple[float, float] = GRASPABLE_EXTENT_M) -> str | None:
    """Why ``obj`` cannot be a graspable object (largest extent of its mesh outside ``extent_range``), with
    the power-of-ten ``--scale`` that would bring it to ~10 cm; None when its size is plausible. Reads the
    mesh, not the simulated body, so a plausible object never pays for a convex decomposition here."""
    ext = float(np.max(obj.mesh.extents))
    lo, hi = extent_range
    if lo <= ext <= hi:
        return None
    k = round(math.log10(0.1 / ext))
    given = obj.file_scale  # --scale replaces, not multiplies: suggest the total
    total = given * 10.0 ** k
    if not k:
        hint = ""
    elif abs(math.log10(total)) < 1e-9:
        hint = f"if its units are wrong, without --scale ({given:g} now) it is {100 * ext * 10.0 ** k:.3g} cm"
    else:
        hint = f"if its units are wrong, --scale {total:g} makes it {100 * ext * 10.0 ** k:.3g} cm"
    # the mass of the mesh (its hull when open), not of the body: a refused object must not pay for a convex
    # decomposition (minutes of V-HACD on a 75 m apple) nor warn about how that body fits it
    volume = abs(float(obj.mesh.volume)) if obj.watertight else float(obj.mesh.convex_hull.volume)
    return (f"object {obj.name!r}: largest extent {ext:.4g} m ({volume * obj.density:.4g} kg at {obj.density:g} kg/m^3) is outside the "
            f"graspable range {lo:g}-{hi:g} m" + (f"; {hint}" if hint else ""))


def warn_if_ungraspable(obj: ObjectModel, extent_range: tuple[float, float] = GRASPABLE_EXTENT_M) -> bool:
    """Warn (:class:`~ohra.errors.ObjectWarning`) when ``obj`` is outside the graspable size range, e.g. a
    mesh in millimetres: evaluation and sampling still run on it (the synthesiser refuses it instead).
    Each object warns once, whoever asks (the evaluator, the grasp model, the CLI). Returns whether it is outside."""
    problem = size_problem(obj, extent_range)
    if problem and not obj.__dict__.get("_size_warned"):
        obj.__dict__["_size_warned"] = True
        warnings.warn(f"{problem}; grasps on it say little about a hand", ObjectWarning, stacklevel=user_stacklevel())
    return problem is not None
