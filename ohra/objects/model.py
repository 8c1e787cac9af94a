"""Objects to grasp: mesh loading and repair, surface samples, and the body they are grasped as.

Frame convention: an object lives in its **mesh frame**: the coordinates stored in the file or,
for an object URDF, its link frame (mesh scale, then the ``<visual>`` origin, as PyBullet places
it). Nothing is recentred: grasps are expressed in this frame, and the evaluator places the object
with its mesh frame at the world origin. ``center_mass`` is reported separately.

The mesh is what the file holds (and what :meth:`ObjectModel.sample_surface` samples); the
solver, the simulator and the mass properties all use one :class:`~ohra.objects.body.Body`
(primitives, an exact shape, or convex pieces: see :mod:`ohra.objects.body`). Signed distances
are negative inside.
"""

from __future__ import annotations

import hashlib
import warnings
import xml.etree.ElementTree as ET
from functools import cached_property
from pathlib import Path

import numpy as np
import trimesh
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ohra.errors import ObjectError, ObjectWarning, is_finite_real, is_whole, require_seed, require_whole, user_stacklevel
from ohra.objects.body import BODY_TOLERANCE_M, BODY_VOLUME_RANGE, SDF, Body, Fidelity, MassProperties, fidelity
from ohra.objects.decompose import DECOMPOSITION_NAMES, check_solid, convex_components, load_convex_pieces, vhacd_pieces
from ohra.objects.repair import RepairReport, repair_mesh
from ohra.objects.sdf import SDFGrid

DEFAULT_DENSITY = 500.0  # kg/m^3, the evaluation protocol's object density
MESH_SUFFIXES = (".obj", ".stl", ".ply", ".off", ".glb")


def _load_mesh_file(path: Path, scale: np.ndarray | None = None) -> trimesh.Trimesh:
    if not path.is_file():
        raise ObjectError(f"object mesh not found: {path}")
    try:
        loaded = trimesh.load(str(path), force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types for bad files
        raise ObjectError(f"{path}: cannot read mesh ({exc})") from None
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise ObjectError(f"{path}: mesh has no faces")
    if scale is not None:
        loaded.apply_scale(scale)
    return loaded


OWN_PIECES = " pieces"  # the end of a body kind whose pieces are the mesh's own components ("provided:X.obj pieces")
BODY_CHOICES = ("auto", "hull", "provided", "vhacd")
"""What a mesh object can be grasped and simulated as (``body=``, ``--body``): ``auto`` the convex hull when the mesh is
convex, else whichever of the hull, a provided decomposition and (when neither is within tolerance) V-HACD lies nearest
the mesh on average; or the one named."""


def _choice_of(kind: str) -> str:
    """The ``body_choice`` that gives a body of ``kind`` (``"provided:collision_vhacd.obj"`` -> ``"provided"``)."""
    return kind.split(":", 1)[0]


def _label(path: Path) -> str:
    """An object's default name: its file's stem, or its folder's name when the stem is the YCB
    layout's generic one (``model.urdf``, ``textured_simple_reoriented.obj``, ``collision_vhacd.obj``);
    a flat folder of object URDFs (``duck_vhacd.urdf``, ``teddy_vhacd.urdf``) names each by its file."""
    stem = path.stem.lower()
    generic = stem in ("model", "collision_vhacd", "textured_vhacd") or stem.startswith("textured")
    return path.parent.name if generic else path.stem


def _urdf_mesh(path: Path):
    """Visual mesh, its (3,) scale and origin (4x4 in the link frame) named by a PyBullet-style object URDF
    (its first ``<visual>`` mesh; without one, its first ``<collision>`` mesh), **every** ``<collision>``
    element as ``(mesh file, scale, origin, None)`` or, for a ``<box>``/``<sphere>``/``<cylinder>``,
    ``(None, ones, origin, solid)`` (a plate's rim is six collision meshes and a cylinder), and the other
    ``<visual>`` elements alike (a pan's handle)."""
    from ohra.transforms import xyzrpy_to_matrix

    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise ObjectError(f"{path}: not valid XML ({exc})") from None

    def floats(text: str, what: str) -> list[float]:
        try:
            return [float(x) for x in text.split()]
        except ValueError:
            raise ObjectError(f"{path}: {what} {text!r} is not a list of numbers") from None

    def own_origin(el) -> np.ndarray:  # an element's <origin>, in its parent's frame
        o = el.find("origin")
        xyz = floats(o.get("xyz", "0 0 0") if o is not None else "0 0 0", "origin xyz")
        rpy = floats(o.get("rpy", "0 0 0") if o is not None else "0 0 0", "origin rpy")
        return xyzrpy_to_matrix(np.array(xyz + rpy))

    def mesh_of(el) -> tuple[Path, np.ndarray] | None:
        m = el.find("geometry/mesh")
        if m is None or not m.get("filename"):
            return None
        scale = np.array(floats(m.get("scale") or "1 1 1", "mesh scale"))
        return path.parent / m.get("filename"), scale

    def solid_of(el) -> trimesh.Trimesh | None:
        g = el.find("geometry")
        try:
            if g is not None and (b := g.find("box")) is not None:
                return trimesh.creation.box(extents=floats(b.get("size", ""), "box size"))
            if g is not None and (sp := g.find("sphere")) is not None:
                return trimesh.creation.icosphere(subdivisions=3, radius=float(sp.get("radius", "")))
            if g is not None and (c := g.find("cylinder")) is not None:
                return trimesh.creation.cylinder(radius=float(c.get("radius", "")), height=float(c.get("length", "")),
                                                 sections=48)
        except (ValueError, TypeError):
            raise ObjectError(f"{path}: a <{el.tag}> primitive with a missing or non-numeric size") from None
        return None

    # each link's frame in the root link's, down the joints at position 0: a handle on a second link sits where its
    # fixed joint puts it (the links were merged at their own origins, the handle buried in the body)
    joints = root.findall("joint")
    parent_of = {j.find("child").get("link"): (j.find("parent").get("link"), own_origin(j)) for j in joints
                 if j.find("child") is not None and j.find("parent") is not None}
    movable = [f"{j.get('name')} ({j.get('type')})" for j in joints if j.get("type", "fixed") != "fixed"]
    if movable:
        warnings.warn(f"{path}: the object URDF has movable joint(s) {', '.join(movable[:3])}; ohra grasps one rigid object, "
                      "so its links are taken together at joint position 0", ObjectWarning, stacklevel=user_stacklevel())

    def link_frame(name: str) -> np.ndarray:
        T, seen = np.eye(4), set()
        while name in parent_of and name not in seen:
            seen.add(name)
            name, T_joint = parent_of[name]
            T = T_joint @ T
        return T

    frames = {link.get("name"): link_frame(link.get("name")) for link in root.findall("link")}
    placed: dict[int, np.ndarray] = {}
    for link in root.findall("link"):
        for el in list(link.findall("visual")) + list(link.findall("collision")):
            placed[id(el)] = frames[link.get("name")]
    def origin(el) -> np.ndarray:  # a visual's or collision's origin, in the root link's frame
        return placed.get(id(el), np.eye(4)) @ own_origin(el)

    visuals = list(root.iter("visual"))
    vis_el = next((el for el in visuals if mesh_of(el) is not None), None)
    vis = None if vis_el is None else (mesh_of(vis_el), origin(vis_el))
    # the object's other visual parts (a pan's handle is a <cylinder> beside its mesh): part of its surface
    extra: list[tuple[Path | None, np.ndarray, np.ndarray, trimesh.Trimesh | None]] = []
    for el in visuals:
        if el is vis_el:
            continue
        if (m := mesh_of(el)) is not None:
            extra.append((m[0], m[1], origin(el), None))
        elif (solid := solid_of(el)) is not None:
            extra.append((None, np.ones(3), origin(el), solid))
    cols: list[tuple[Path | None, np.ndarray, np.ndarray, trimesh.Trimesh | None]] = []
    for el in root.iter("collision"):
        if (m := mesh_of(el)) is not None:
            cols.append((m[0], m[1], origin(el), None))
        elif (solid := solid_of(el)) is not None:
            cols.append((None, np.ones(3), origin(el), solid))
    if vis is None:
        first = next((c for c in cols if c[0] is not None), None)
        if first is None:
            raise ObjectError(f"{path}: no <mesh> geometry in the object URDF")
        vis = ((first[0], first[1]), first[2])
    (vis_path, scale), T_vis = vis
    return vis_path, scale, T_vis, cols, extra


# holes whose fill is at least this share of the repaired surface are said (a scan's pinholes are not)
FILLED_AREA_NOTE = 1e-3


class ObjectModel:
    """A rigid object: its surface mesh (as loaded and repaired) and the :class:`~ohra.objects.body.Body`
    it is grasped and simulated as (signed distance, convex pieces, mass properties; see there).

    Args:
        mesh: surface mesh in the object's mesh frame [m].
        name: label used in reports and dataset keys.
        density: [kg/m^3] for :attr:`mass`.
        source: the file it came from, if any.
        convex_pieces: a provided convex decomposition (a candidate body, chosen if it fits the mesh).
        repair: merge vertices, drop degenerate faces, fill holes, orient faces (see :func:`repair_mesh`).
        primitives: exact solids the body is made of (built-ins, procedural shapes).
        exact_sdf: closed-form signed distance of the shape the (convex) mesh approximates.
        body_choice: which body a mesh object is grasped and simulated as (:data:`BODY_CHOICES`): ``"auto"``
            (default: see :attr:`body`), ``"hull"``, ``"provided"`` (the given decomposition) or ``"vhacd"``.
            Objects made of primitives or with an exact shape keep theirs.

    Raises:
        ObjectError: ``density`` is not a finite number > 0; the mesh has no faces or spans no volume
            (a point, a line, a flat sheet); ``body_choice`` is unknown.
    """

    def __init__(self, mesh: trimesh.Trimesh, name: str, density: float = DEFAULT_DENSITY,
                 source: Path | None = None, convex_pieces: list[trimesh.Trimesh] | None = None,
                 repair: bool = True, primitives: list[dict] | None = None, exact_sdf: SDF | None = None,
                 pieces_label: str = "provided", body_choice: str = "auto"):
        if body_choice not in BODY_CHOICES:
            raise ObjectError(f"object {name!r}: body must be one of {', '.join(BODY_CHOICES)}, got {body_choice!r}")
        if not (is_finite_real(density) and density > 0):
            raise ObjectError(f"object {name!r}: density must be a finite number > 0 kg/m^3, got {density}")
        if len(mesh.faces) == 0:
            raise ObjectError(f"object {name!r}: mesh has no faces")
        check_solid(mesh, name)  # before repair: Qhull and V-HACD fail (or hang) on flat input
        self.file_scale = 1.0  # the factor :meth:`load` multiplied a file's coordinates by (its ``scale``)
        if repair:
            self.mesh, self.repair_report = repair_mesh(mesh)
        else:
            self.mesh = mesh
            self.repair_report = RepairReport(0, 0, bool(mesh.is_watertight), bool(mesh.is_watertight), True)
        if len(self.mesh.faces) == 0:
            raise ObjectError(f"object {name!r}: mesh is empty after repair")
        rr = self.repair_report
        if rr.filled_faces and rr.filled_area_fraction >= FILLED_AREA_NOTE and rr.watertight:  # else the open-mesh note
            # an open cup or box is closed into a solid one here, with a watertight mesh and no later note
            warnings.warn(f"object {name!r}: the mesh was open; repair closed its holes with {rr.filled_faces} face(s), "
                          f"{100 * rr.filled_area_fraction:.1f} % of the surface, so it is grasped and simulated as that "
                          f"closed solid (volume {1e6 * abs(float(self.mesh.volume)):.4g} cm^3)", ObjectWarning,
                          stacklevel=user_stacklevel())
        check_solid(self.mesh, name)
        self.name = name
        self.density = float(density)
        self.source = source
        self._pieces = convex_pieces
        self._pieces_label = pieces_label
        self.primitives = primitives  # exact solids for the simulator (built-ins, procedural), else None
        self._exact_sdf = exact_sdf
        self.body_choice = body_choice
        self.procedural_params: dict | None = None  # family, seed and sampled sizes of a procedural object

    # -- construction ------------------------------------------------------------------------------
    @classmethod
    def load(cls, path: str | Path, density: float = DEFAULT_DENSITY, name: str | None = None,
             scale: float | None = None, body: str = "auto") -> "ObjectModel":
        """Load a mesh file, a PyBullet-style object URDF (mesh scale, then ``<visual>`` origin applied),
        or a folder holding one. A convex decomposition beside the mesh (or the URDF's
        ``<collision>`` mesh) is taken as provided pieces.

        Args:
            path: ``.obj/.stl/.ply/.off/.glb``, ``.urdf``, or a folder (its
                ``textured_simple_reoriented.obj``, ``model.urdf``, else its one object URDF, else the first
                mesh by name, ``.obj`` before ``.stl``, ``.ply``, ``.off``, ``.glb``, with a warning when there
                are several).
            density: [kg/m^3] for :attr:`mass`.
            name: label; None: the file stem, or the folder's name for a folder and for a file whose stem
                names no object (``model.urdf``, ``textured*``, ``collision_vhacd``: the YCB layout).
            scale: factor on the vertices (and a provided decomposition's), which are read as metres:
                e.g. 0.001 for a millimetre mesh; None: 1.
            body: the body to grasp and simulate it as (``body_choice`` of :class:`ObjectModel`): ``"auto"``,
                ``"hull"``, ``"provided"`` (the decomposition beside the mesh or in the URDF) or ``"vhacd"``.

        Returns:
            The object, in its mesh frame [m] (not recentred).

        Raises:
            ObjectError: missing path or a folder without a mesh; unsupported type; unreadable mesh,
                URDF or decomposition; ``scale`` or ``density`` <= 0; a mesh with no faces or no volume.
        """
        path = Path(path)
        if not path.exists():
            raise ObjectError(f"object file not found: {path}")
        if path.is_dir():
            files = sorted(f for f in path.iterdir() if f.is_file())
            # an object URDF beside its meshes says how they are scaled and placed: it is the object
            urdfs = [f for f in files if f.suffix.lower() == ".urdf"]
            meshes = [f for suffix in MESH_SUFFIXES for f in files
                      if f.suffix.lower() == suffix and f.name not in DECOMPOSITION_NAMES]
            preferred = [c for c in (path / "textured_simple_reoriented.obj", path / "model.urdf") if c.is_file()]
            if not preferred and len(urdfs) > 1:
                raise ObjectError(f"{path}: folder holds {len(urdfs)} object URDFs ({', '.join(f.name for f in urdfs)}); "
                                  "name the one to load")
            cands = preferred + urdfs + meshes
            if not cands:
                raise ObjectError(f"{path}: folder holds no mesh ({', '.join(MESH_SUFFIXES)}) or object URDF")
            if not preferred and not urdfs and len(meshes) > 1:
                warnings.warn(f"{path}: folder holds {len(meshes)} meshes ({', '.join(f.name for f in meshes)}); loading "
                              f"{meshes[0].name} as the object (pass the files themselves to load each)",
                              ObjectWarning, stacklevel=user_stacklevel())
            return cls.load(cands[0], density, name or path.name, scale, body)
        pieces, label_pieces = None, "provided"
        if path.suffix.lower() == ".urdf":
            # the object frame is the URDF link frame: mesh scale, then the <visual>/<collision> origin
            mesh_path, vis_scale, T_vis, cols, extra = _urdf_mesh(path)
            mesh = _load_mesh_file(mesh_path, vis_scale)
            mesh.apply_transform(T_vis)
            if extra:
                parts = [mesh]
                for f, sc, T, solid in extra:
                    try:
                        parts.append((solid.copy() if solid is not None else _load_mesh_file(f, sc)).apply_transform(T))
                    except ObjectError as exc:  # the object's main visual loaded: a missing extra part is said, not fatal
                        warnings.warn(f"{path}: a further <visual> is left out of the object's surface: {exc}", ObjectWarning,
                                      stacklevel=user_stacklevel())
                mesh = trimesh.util.concatenate(parts)
            # every <collision> element is a candidate body piece (a plate's rim is six meshes and a cylinder);
            # the visual mesh itself counts only when it is a decomposition (several convex pieces), so that a
            # concave visual mesh still gets V-HACD rather than its hull
            pieces, names = [], []
            for col, col_scale, T_col, solid in cols:
                if solid is not None:
                    pieces.append(solid.apply_transform(T_col))
                    names.append("primitive")
                elif col is not None and col.is_file():
                    got = [pc.apply_transform(T_col) for pc in load_convex_pieces(col, col_scale)]
                    if col != mesh_path or len(got) > 1 or len(cols) > 1:
                        pieces += got
                        names.append(col.name)
            pieces = pieces or None
            names = list(dict.fromkeys(names))
            label_pieces = f"provided:{'+'.join(names) if len(names) <= 2 else f'{len(cols)} URDF collisions'}"
            label = name or _label(path)
        elif path.suffix.lower() in MESH_SUFFIXES:
            mesh = _load_mesh_file(path)
            for sib in (path.parent / n for n in DECOMPOSITION_NAMES):
                if sib.is_file() and sib != path:
                    pieces, label_pieces = load_convex_pieces(sib), f"provided:{sib.name}"
                    break
            if pieces is None:
                # a decomposition loaded as the object itself (collision_vhacd.obj, *_VHACD_CHs.obj, separate convex
                # parts): its own pieces are the exact body, where V-HACD would decompose it again (x1.5 volume)
                own = (load_convex_pieces(path) if path.name in DECOMPOSITION_NAMES else convex_components(mesh))
                if own and len(own) > 1:
                    pieces, label_pieces = own, f"provided:{path.name}{OWN_PIECES}"
            label = name or _label(path)
        else:
            raise ObjectError(f"{path}: unsupported object file type {path.suffix!r} (use {', '.join(MESH_SUFFIXES)} or .urdf)")
        if scale is not None:
            if not (is_finite_real(scale) and scale > 0):
                raise ObjectError(f"{path}: scale must be a number > 0, got {scale!r}")
            mesh.apply_scale(float(scale))
            for pc in pieces or []:
                pc.apply_scale(float(scale))
        out = cls(mesh, label, density, path, pieces, pieces_label=label_pieces, body_choice=body)
        out.file_scale = float(scale) if scale is not None else 1.0  # what the file's coordinates were multiplied by
        return out

    @classmethod
    def builtin(cls, name: str, density: float = DEFAULT_DENSITY) -> "ObjectModel":
        """A built-in primitive object generated by code.

        Args:
            name: one of :func:`builtin_object_names`.
            density: [kg/m^3].

        Raises:
            ObjectError: unknown ``name``.
        """
        from ohra.objects.builtin import BUILTINS

        if name not in BUILTINS:
            raise ObjectError(f"unknown built-in object {name!r}; known: {', '.join(BUILTINS)}")
        mesh, pieces, prims = BUILTINS[name]()
        return cls(mesh, name, density, None, pieces, repair=False, primitives=prims)

    @classmethod
    def procedural(cls, family: str, seed: int, density: float = DEFAULT_DENSITY) -> "ObjectModel":
        """A seeded procedural shape (see :mod:`ohra.objects.procedural`), named ``family-seed``.

        Args:
            family: ``"superquadric"``, ``"box"``, ``"cylinder"``, ``"capsule"`` or ``"ellipsoid"``.
            seed: same family and seed, same shape (sizes recorded in :attr:`procedural_params`, [m]).
            density: [kg/m^3].

        Raises:
            ObjectError: unknown ``family``.
        """
        from ohra.objects.procedural import make_procedural

        return make_procedural(cls, family, seed, density)

    # -- the body ------------------------------------------------------------------------------------
    @cached_property
    def body(self) -> Body:
        """The body the object is grasped and simulated as: its primitives or exact shape, else the
        convex hull or the provided decomposition, whichever lies closer to the mesh, else V-HACD."""
        if self.primitives:
            return Body(self._pieces or [self.mesh.convex_hull], "primitives", primitives=self.primitives)
        if self._exact_sdf is not None:
            return Body(self._pieces or [self.mesh.convex_hull], "exact", exact_sdf=self._exact_sdf)
        hull = Body([self.mesh.convex_hull], "hull")
        # the mesh is its own convex pieces (overlapping: its volume counts the overlaps twice, so the hull test
        # below would take a non-convex union for convex)
        own = bool(self._pieces) and self._pieces_label.endswith(OWN_PIECES)
        choice = self.body_choice
        if choice != "auto":
            scored = [(None, self._chosen_body(hull))]
            scored = [(self._fidelity_of(b), b) for _, b in scored]
        elif self.watertight and not own and hull.mass_properties.volume <= 1.01 * abs(float(self.mesh.volume)):
            return hull  # convex: the hull is the mesh
        else:
            cands = [hull] + ([Body(self._pieces, self._pieces_label)] if self._pieces else [])
            scored = [(self._fidelity_of(b), b) for b in cands]
        # V-HACD only for closed meshes: on an open surface it voxelises a thin shell (an open tube
        # became 30 of its 283 cm^3), while the hull takes the holes as closed
        if choice == "auto" and not min(f.p95 for f, _ in scored) <= BODY_TOLERANCE_M and not self._pieces and self.watertight:
            try:
                b = Body(vhacd_pieces(self.mesh, self.mesh_hash), "vhacd")
                scored.append((self._fidelity_of(b), b))
            except ObjectError as exc:
                warnings.warn(f"object {self.name!r}: {exc}; using the convex hull", ObjectWarning, stacklevel=user_stacklevel())
        fid, best = min(scored, key=lambda fb: fb[0].mean)
        self.__dict__["fidelity"] = fid
        apart = self._separate_parts()
        if apart:
            warnings.warn(f"object {self.name!r}: the mesh holds {apart[0]} separate parts (up to {1e3 * apart[1]:.0f} mm apart); "
                          "they are grasped and simulated as one rigid object (load each part's file to grasp it alone)",
                          ObjectWarning, stacklevel=user_stacklevel())
        lo, hi = BODY_VOLUME_RANGE
        if self.watertight and not (own and best.kind == self._pieces_label) and not lo <= fid.volume_ratio <= hi:
            # the surface can follow the mesh within tolerance while a cavity or thin walls are filled (a bowl's
            # V-HACD: x2.1 volume, p95 3.7 mm): the mass, centre of mass and inertia follow the body
            mp = best.mass_properties
            warnings.warn(f"object {self.name!r}: its body ({best.kind}, {len(best.pieces)} piece(s)) holds x{fid.volume_ratio:.2f} "
                          f"the mesh's volume ({1e6 * mp.volume:.4g} vs {1e6 * self.mesh_volume:.4g} cm^3: a cavity or thin walls "
                          f"filled?); mass and inertia follow the body ({1e3 * mp.volume * self.density:.4g} g at "
                          f"{self.density:g} kg/m^3): "
                          + ("a finer decomposition" if best.kind.startswith("provided") else
                             "a decomposition that follows the walls (collision_vhacd.obj beside the mesh"
                             + (", or body='vhacd', --body vhacd" if best.kind == "hull" else "") + ")")
                          + " or a density of (intended mass / body volume) corrects them", ObjectWarning,
                          stacklevel=user_stacklevel())
        if not self.watertight:
            warnings.warn(f"object {self.name!r}: the mesh is open (not watertight after repair); it is taken as the closed "
                          f"body {best.kind} ({len(best.pieces)} piece(s)): volume {1e6 * best.mass_properties.volume:.4g} cm^3, "
                          f"mass properties {best.mass_properties.method}", ObjectWarning, stacklevel=user_stacklevel())
        elif best.mass_properties.estimated:
            # overlapping pieces have no closed-form mass properties (the open-mesh note above already says so)
            mp = best.mass_properties
            warnings.warn(f"object {self.name!r}: the mass, centre of mass and inertia of its body ({best.kind}) are "
                          f"estimated on a grid, {mp.method.split(': ', 1)[-1]} (volume {1e6 * mp.volume:.4g} cm^3)",
                          ObjectWarning, stacklevel=user_stacklevel())
        if not fid.within_tolerance:
            tol = f"{1e3 * BODY_TOLERANCE_M:.0f} mm"
            inside = [(f, b) for f, b in scored if f.within_tolerance]
            if inside:
                # the ranking is by mean distance, so a body within the 95th-percentile tolerance can lose to one
                # closer on average; say so rather than claim no body is within it
                f2, b2 = min(inside, key=lambda fb: fb[0].mean)
                warnings.warn(f"object {self.name!r}: the body closest to the mesh on average ({best.kind}, mean "
                              f"{1e3 * fid.mean:.1f} mm) lies beyond {tol} at the 95th percentile ({1e3 * fid.p95:.1f} mm); "
                              f"{b2.kind} is within it ({1e3 * f2.p95:.1f} mm) but farther on average ({1e3 * f2.mean:.1f} mm); "
                              f"grasps are synthesised and simulated on {best.kind} (body={_choice_of(b2.kind)!r}, "
                              f"--body {_choice_of(b2.kind)}, picks the other)", ObjectWarning, stacklevel=user_stacklevel())
            elif choice != "auto":
                warnings.warn(f"object {self.name!r}: the body chosen ({best.kind}, {len(best.pieces)} piece(s)) lies beyond "
                              f"{tol} of the mesh at the 95th percentile ({1e3 * fid.p95:.1f} mm; mean {1e3 * fid.mean:.1f} mm, "
                              f"volume x{fid.volume_ratio:.2f})", ObjectWarning, stacklevel=user_stacklevel())
            else:
                warnings.warn(f"object {self.name!r}: no convex body within {tol} of the mesh "
                              f"(best: {best.kind}, 95th percentile {1e3 * fid.p95:.1f} mm, volume x{fid.volume_ratio:.2f}); "
                              "grasps are synthesised and simulated on that body", ObjectWarning, stacklevel=user_stacklevel())
        return best

    def _chosen_body(self, hull: Body) -> Body:
        """The body ``body_choice`` names (not ``"auto"``); :class:`ObjectError` when the object has none such."""
        choice = self.body_choice
        if choice == "hull":
            return hull
        if choice == "provided":
            if not self._pieces:
                where = f" beside {self.source} ({', '.join(DECOMPOSITION_NAMES)}) or in its URDF" if self.source else ""
                raise ObjectError(f"object {self.name!r}: body 'provided' asked for, but it has no convex decomposition{where}")
            return Body(self._pieces, self._pieces_label)
        if not self.watertight:  # "vhacd": on an open surface V-HACD voxelises a thin shell
            raise ObjectError(f"object {self.name!r}: body 'vhacd' needs a closed mesh; this one is open after repair "
                              "(use 'hull' or 'auto')")
        return Body(vhacd_pieces(self.mesh, self.mesh_hash), "vhacd")

    def _separate_parts(self) -> tuple[int, float] | None:
        """(groups, largest gap [m]) when the mesh is solid parts (each over 5 % of the volume) that fall into
        groups more than 2 mm apart: two cubes saved in one file are one rigid object. Gaps are surface to
        surface (a part's vertices and surface samples, outside the other part), so a handle through a hammer's
        head or a table's legs under its top are one group."""
        parts = list(self.mesh.split(only_watertight=True))
        total = sum(abs(float(p.volume)) for p in parts)
        parts = [p for p in parts if total > 0 and abs(float(p.volume)) > 0.05 * total]
        if len(parts) < 2:
            return None
        pts = [np.vstack([p.vertices, p.sample(2000, seed=0)]) for p in parts]
        n = len(parts)
        gap = np.zeros((n, n))
        for i in range(n):
            for j in range(n):
                if i != j:  # signed_distance is positive inside: points outside part j are that far from it
                    gap[i, j] = float(np.maximum(-trimesh.proximity.signed_distance(parts[j], pts[i]), 0.0).min())
        gap = np.minimum(gap, gap.T)
        count, group = connected_components(gap <= 0.002, directed=False)
        if count < 2:
            return None
        return count, float(gap[group[:, None] != group[None, :]].max())

    def _fidelity_of(self, body: Body) -> Fidelity:
        pts, _ = self.sample_surface(3000, seed=2)
        if body.kind.endswith(OWN_PIECES):
            # the mesh is these pieces: faces where they overlap lie inside the body and are no surface of it
            # (teddy2_VHACD_CHs.obj: 14 % of the samples, "95th percentile 24.9 mm" for an exact body)
            pts = pts[body.signed_distance(pts) > -1e-4]
        return fidelity(body, self.mesh, pts, self.mesh_volume)

    @cached_property
    def fidelity(self) -> Fidelity:
        """How far the body lies from the mesh (volume ratio, surface distances both ways)."""
        return self._fidelity_of(self.body)

    def convex_pieces(self) -> list[trimesh.Trimesh]:
        """The body's convex pieces (what PyBullet simulates unless the body is primitives)."""
        return self.body.pieces

    # -- properties ----------------------------------------------------------------------------------
    @cached_property
    def mesh_hash(self) -> str:
        """SHA-256 (16 hex) of the repaired vertices and faces."""
        h = hashlib.sha256()
        h.update(np.ascontiguousarray(self.mesh.vertices, dtype=np.float64).tobytes())
        h.update(np.ascontiguousarray(self.mesh.faces, dtype=np.int64).tobytes())
        return h.hexdigest()[:16]

    @cached_property
    def body_hash(self) -> str:
        """SHA-256 (16 hex) of the body's geometry."""
        return hashlib.sha256(self.body.hash_bytes()).hexdigest()[:16]

    @property
    def watertight(self) -> bool:
        return bool(self.mesh.is_watertight)

    @cached_property
    def mesh_volume(self) -> float:
        """Volume enclosed by the mesh [m^3]: exact if watertight, else a seeded Monte Carlo count of
        points the surface-normal test puts inside."""
        if self.watertight:
            return float(abs(self.mesh.volume))
        lo, hi = self.mesh.bounds
        P = lo + (hi - lo) * np.random.default_rng(0).random((200_000, 3))
        return float((self._mesh_signed_distance(P) < 0).mean() * np.prod(hi - lo))

    @property
    def mass_properties(self) -> MassProperties:
        """Volume, centre of mass and inertia of the body, and how they were obtained."""
        return self.body.mass_properties

    @property
    def volume(self) -> float:
        """Volume of the body [m^3]."""
        return self.body.mass_properties.volume

    @property
    def mass(self) -> float:
        """Mass [kg] = body volume x density."""
        return self.volume * self.density

    @property
    def center_mass(self) -> np.ndarray:
        """Centre of mass of the body in the mesh frame [m] (uniform density)."""
        return self.body.mass_properties.center_mass

    @property
    def inertia(self) -> np.ndarray:
        """(3,3) inertia tensor of the body about its centre of mass, mesh axes [kg m^2]."""
        return self.body.mass_properties.inertia_per_density * self.density

    @property
    def bounds(self) -> np.ndarray:
        """(2,3) bounds of the body [m]."""
        return self.body.bounds

    def __repr__(self) -> str:  # from the mesh only: the simulated body may need a decomposition
        e = ", ".join(f"{100 * x:.3g}" for x in self.mesh.extents)
        return (f"ObjectModel({self.name!r}, mesh extents ({e}) cm, {len(self.mesh.faces)} faces, "
                f"watertight={bool(self.mesh.is_watertight)}, density={self.density:g} kg/m^3)")

    @property
    def extents(self) -> np.ndarray:
        """(3,) extents of the body's axis-aligned bounds [m]."""
        b = self.bounds
        return b[1] - b[0]

    @property
    def radius(self) -> float:
        """Radius of the bounding sphere of the body about the centre of mass [m]."""
        return float(np.linalg.norm(self.body.vertices - self.center_mass, axis=1).max())

    # -- sampling --------------------------------------------------------------------------------------
    def sample_surface(self, n: int, seed: int = 0, oversample: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """Area-uniform points on the *mesh* surface (not the body), seeded.

        Args:
            n: number of points.
            seed: sampling seed; same seed, same points.
            oversample: > 1 draws ``n * oversample`` points and keeps ``n`` by farthest-point
                sampling (more even coverage).

        Returns:
            (n, 3) points in the mesh frame [m] and (n, 3) unit outward normals (of their faces).

        Raises:
            ObjectError: ``n`` or ``oversample`` not a whole number >= 1; ``seed`` not a whole number >= 0.
        """
        if isinstance(n, (int, np.integer)) and not isinstance(n, bool) and n < 1:
            raise ObjectError(f"object {self.name!r}: sample_surface needs n >= 1 points, got {n}")
        n = require_whole(n, ObjectError, f"object {self.name!r}: sample_surface's n", 1)
        seed = require_seed(seed, ObjectError, f"object {self.name!r}: sample_surface's seed")
        m = n * max(require_whole(oversample, ObjectError, "sample_surface's oversample", 1), 1)
        pts, fid = trimesh.sample.sample_surface(self.mesh, m, seed=seed)
        nrm = self.mesh.face_normals[fid]
        if m > n:
            idx = farthest_point_sampling(pts, n, seed=seed)
            pts, nrm = pts[idx], nrm[idx]
        return np.asarray(pts), np.asarray(nrm)

    # -- signed distance -------------------------------------------------------------------------------
    @cached_property
    def _surface_tree(self) -> tuple[cKDTree, np.ndarray, np.ndarray]:
        area = float(self.mesh.area)
        n = int(np.clip(area / (0.0015**2), 20_000, 150_000))
        pts, fid = trimesh.sample.sample_surface(self.mesh, n, seed=0)
        pts = np.vstack([pts, self.mesh.vertices])
        nrm = np.vstack([self.mesh.face_normals[fid], self.mesh.vertex_normals])
        return cKDTree(pts), pts, nrm

    def _mesh_signed_distance(self, points: np.ndarray, k: int = 4) -> np.ndarray:
        """Signed distance to the *mesh* (sign by a pseudo-normal vote of the k nearest surface
        samples, so small holes do not flip it): only to measure the body against the mesh."""
        tree, pts, nrm = self._surface_tree
        p = np.asarray(points, dtype=float).reshape(-1, 3)
        d, i = tree.query(p, k=k)
        side = np.einsum("nkj,nkj->nk", p[:, None, :] - pts[i], nrm[i])
        w = 1.0 / (d + 1e-9)
        return np.where((side * w).sum(axis=1) >= 0.0, 1.0, -1.0) * d[:, 0]

    @property
    def sdf_sample_spacing(self) -> float:
        """Spacing of the surface samples behind :meth:`signed_distance` (0 when exact) [m]."""
        return self.body.sample_spacing

    def signed_distance(self, points: np.ndarray) -> np.ndarray:
        """Signed distance to the surface of the :attr:`body` (not the mesh).

        Args:
            points: (N, 3) points in the mesh frame [m].

        Returns:
            (N,) signed distances [m], negative inside.

        Raises:
            ObjectError: ``points`` not (N, 3) finite numbers.
        """
        try:
            p = np.asarray(points, dtype=float)
        except (TypeError, ValueError):
            raise ObjectError(f"signed_distance: expected (N, 3) points [m], got {type(points).__name__}") from None
        if p.ndim != 2 or p.shape[1] != 3:
            raise ObjectError(f"signed_distance: expected (N, 3) points [m], got shape {p.shape}")
        if not np.all(np.isfinite(p)):
            raise ObjectError("signed_distance: points contain NaN or infinity")
        return self.body.signed_distance(p)

    def sdf(self, spacing: float | None = None, padding: float = 0.05, max_cells: int = 64) -> SDFGrid:
        """Signed-distance grid of the body covering its bounds plus ``padding`` [m].

        ``spacing`` defaults to the largest padded extent / ``max_cells``. Cached per settings.

        Raises:
            ObjectError: ``spacing`` not > 0, ``padding`` not >= 0, ``max_cells`` not a whole number >= 1.
        """
        if spacing is not None and not (is_finite_real(spacing) and spacing > 0):
            raise ObjectError(f"sdf: spacing must be a distance > 0 [m] (or None), got {spacing!r}")
        if not (is_finite_real(padding) and padding >= 0):
            raise ObjectError(f"sdf: padding must be a distance >= 0 [m], got {padding!r}")
        if not is_whole(max_cells) or max_cells < 1:
            raise ObjectError(f"sdf: max_cells must be a whole number >= 1, got {max_cells!r}")
        key = (spacing, padding, max_cells)
        cache = self.__dict__.setdefault("_sdf_cache", {})
        if key in cache:
            return cache[key]
        lo, hi = self.bounds[0] - padding, self.bounds[1] + padding
        h = float(spacing) if spacing else float((hi - lo).max() / max_cells)
        n = np.ceil((hi - lo) / h).astype(int) + 1
        axes = [lo[d] + h * np.arange(n[d]) for d in range(3)]
        X, Y, Z = np.meshgrid(*axes, indexing="ij")
        vals = self.signed_distance(np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)).reshape(tuple(n))
        grid = SDFGrid(lo, h, vals)
        cache[key] = grid
        return grid

    def _source_spec(self) -> str:
        """Where the object can be loaded from again: its file, ``procedural:FAMILY:SEED`` or ``builtin``."""
        if self.source:
            return str(self.source)
        pp = getattr(self, "procedural_params", None)
        return f"procedural:{pp['family']}:{pp['seed']}" if pp else "builtin"

    def describe(self) -> dict:
        """Summary for reports and manifests (body, its fidelity to the mesh, how mass was obtained)."""
        mp = self.mass_properties
        return {
            "name": self.name, "source": self._source_spec(),
            # how the source is read again into this object (a millimetre mesh's 0.001; the body asked for)
            "scale": float(self.file_scale), "body_choice": self.body_choice, "mesh_hash": self.mesh_hash,
            "body_hash": self.body_hash, "faces": int(len(self.mesh.faces)), "watertight": self.watertight,
            "extents_m": [float(x) for x in self.extents], "volume_m3": self.volume, "mass_kg": self.mass,
            "density": self.density, "radius_m": self.radius, "center_mass_m": [float(x) for x in mp.center_mass],
            "mass_properties": {"method": mp.method, "estimated": mp.estimated},
            "body": {"kind": self.body.kind, "pieces": len(self.body.pieces), "fidelity": self.fidelity.to_dict()},
            "repair": self.repair_report.__dict__,
            **({"procedural": self.procedural_params} if self.procedural_params else {}),
        }


def farthest_point_sampling(points: np.ndarray, k: int, seed: int = 0) -> np.ndarray:
    """Indices of ``k`` points chosen by farthest-point sampling from a seeded random start."""
    p = np.asarray(points, dtype=float)
    n = len(p)
    k = min(require_whole(k, ObjectError, "farthest_point_sampling's k", 1), n)
    if n == 0:
        raise ObjectError("farthest_point_sampling: no points to choose from")
    rng = np.random.default_rng(require_seed(seed, ObjectError, "farthest_point_sampling's seed"))
    idx = np.empty(k, dtype=int)
    idx[0] = rng.integers(n)
    d = np.linalg.norm(p - p[idx[0]], axis=1)
    for j in range(1, k):
        idx[j] = int(np.argmax(d))
        d = np.minimum(d, np.linalg.norm(p - p[idx[j]], axis=1))
    return idx


def builtin_object_names() -> list[str]:
    from ohra.objects.builtin import BUILTINS

    return list(BUILTINS)


def resolve_objects(spec, scale: float | None = None, body: str = "auto") -> list["ObjectModel"]:
    """Objects from command-line specs (see :func:`ohra.objects.resolve.resolve_objects`)."""
    from ohra.objects.resolve import resolve_objects as _resolve

    return _resolve(spec, scale, body)
