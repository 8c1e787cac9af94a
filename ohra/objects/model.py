"""Objects to grasp: mesh loading and repair, surface samples, a signed-distance grid, convex pieces.

Frame convention: an object lives in its **mesh frame**: the coordinates stored in the file or,
for an object URDF, its link frame (mesh scale, then the ``<visual>`` origin, as PyBullet places
it). Nothing is recentred: grasps are expressed in this
frame, and the evaluator places the object with its mesh frame at the world origin. ``center_mass``
is reported separately.

Signed distances are negative inside. Signs come from the outward normal of the nearest surface
sample (a pseudo-normal test), which needs consistently oriented faces (repair ensures this) but not
a watertight mesh: holes smaller than the sample spacing do not flip signs, unlike ray parity.
Distances are to a dense area-uniform sample of the surface, so they overestimate the true distance
by at most about half the sample spacing (reported as ``sdf_sample_spacing``).
"""

from __future__ import annotations

import hashlib
import math
import warnings
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from ohra.errors import ObjectError
from ohra.paths import cache_dir

DEFAULT_DENSITY = 500.0  # kg/m^3, the evaluation protocol's object density
MESH_SUFFIXES = (".obj", ".stl", ".ply", ".off", ".glb")


@dataclass(frozen=True)
class SDFGrid:
    """Signed distance values on a regular grid (metres; negative inside).

    ``values[i, j, k]`` is the distance at ``origin + spacing * (i, j, k)``.
    """

    origin: np.ndarray
    spacing: float
    values: np.ndarray

    @property
    def shape(self) -> tuple[int, int, int]:
        return tuple(self.values.shape)  # type: ignore[return-value]

    @property
    def upper(self) -> np.ndarray:
        """Coordinates of the last grid node (the grid spans ``origin`` .. ``upper``)."""
        return self.origin + self.spacing * (np.array(self.values.shape) - 1)

    def axes(self) -> list[np.ndarray]:
        """Grid coordinates along x, y, z."""
        return [self.origin[d] + self.spacing * np.arange(n) for d, n in enumerate(self.values.shape)]

    def query(self, points: np.ndarray) -> np.ndarray:
        """Trilinear signed distance at (N,3) points; outside the grid, distance to the grid box is added."""
        p = np.asarray(points, dtype=float).reshape(-1, 3)
        pc = np.clip(p, self.origin, self.upper)
        extra = np.linalg.norm(p - pc, axis=1)
        g = (pc - self.origin) / self.spacing
        i0 = np.clip(np.floor(g).astype(int), 0, np.array(self.values.shape) - 2)
        f = g - i0
        v = self.values
        out = np.zeros(len(p))
        for dx in (0, 1):
            wx = f[:, 0] if dx else 1 - f[:, 0]
            for dy in (0, 1):
                wy = f[:, 1] if dy else 1 - f[:, 1]
                for dz in (0, 1):
                    wz = f[:, 2] if dz else 1 - f[:, 2]
                    out += wx * wy * wz * v[i0[:, 0] + dx, i0[:, 1] + dy, i0[:, 2] + dz]
        return out + extra

    def gradient(self, points: np.ndarray, h: float | None = None) -> np.ndarray:
        """(N,3) gradient of :meth:`query` by central differences (step ``h``, default spacing / 2)."""
        p = np.asarray(points, dtype=float).reshape(-1, 3)
        h = self.spacing / 2 if h is None else float(h)
        g = np.empty_like(p)
        for d in range(3):
            e = np.zeros(3)
            e[d] = h
            g[:, d] = (self.query(p + e) - self.query(p - e)) / (2 * h)
        return g

    def interpolant(self, method: str = "linear"):
        """``scipy.interpolate.RegularGridInterpolator`` over the grid (``"linear"``, ``"cubic"``, ...);
        points outside the grid are extrapolated."""
        from scipy.interpolate import RegularGridInterpolator

        return RegularGridInterpolator(self.axes(), self.values, method=method, bounds_error=False, fill_value=None)


@dataclass
class RepairReport:
    """What :func:`repair_mesh` did and what it means."""

    merged_vertices: int
    removed_faces: int
    watertight_before: bool
    watertight: bool
    winding_consistent: bool
    note: str = ""


def repair_mesh(mesh: trimesh.Trimesh) -> tuple[trimesh.Trimesh, RepairReport]:
    """Merge vertices, drop degenerate/duplicate faces, fill small holes, orient faces outward."""
    with np.errstate(divide="ignore", invalid="ignore"):  # trimesh probes the volume of open meshes
        return _repair(mesh)


def _repair(mesh: trimesh.Trimesh) -> tuple[trimesh.Trimesh, RepairReport]:
    m = mesh.copy()
    was = bool(m.is_watertight)
    nv, nf = len(m.vertices), len(m.faces)
    m.merge_vertices(merge_tex=True, merge_norm=True)
    m.update_faces(m.nondegenerate_faces())
    m.update_faces(m.unique_faces())
    m.remove_unreferenced_vertices()
    if not m.is_watertight:
        trimesh.repair.fill_holes(m)
    trimesh.repair.fix_winding(m)
    trimesh.repair.fix_normals(m)
    if m.is_watertight and m.volume < 0:
        m.invert()
    note = ""
    if not m.is_watertight:
        note = ("still not watertight after repair: volume and mass come from the SDF inside count, "
                "signs from surface normals (see module doc)")
    return m, RepairReport(nv - len(m.vertices), nf - len(m.faces), was, bool(m.is_watertight), bool(m.is_winding_consistent), note)


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


def _urdf_mesh(path: Path) -> tuple[Path, np.ndarray, np.ndarray, Path | None, np.ndarray]:
    """Visual mesh, its scale and origin (4x4 in the link frame), and the collision mesh and origin
    named by a PyBullet-style object URDF (the first ``<mesh>`` of each kind)."""
    from ohra.transforms import xyzrpy_to_matrix

    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise ObjectError(f"{path}: not valid XML ({exc})") from None

    def find(tag: str) -> tuple[Path | None, np.ndarray, np.ndarray]:
        for el in root.iter(tag):
            m = el.find("geometry/mesh")
            if m is not None and m.get("filename"):
                scale = np.array([float(x) for x in (m.get("scale") or "1 1 1").split()])
                o = el.find("origin")
                xyz = [float(x) for x in (o.get("xyz", "0 0 0") if o is not None else "0 0 0").split()]
                rpy = [float(x) for x in (o.get("rpy", "0 0 0") if o is not None else "0 0 0").split()]
                return path.parent / m.get("filename"), scale, xyzrpy_to_matrix(np.array(xyz + rpy))
        return None, np.ones(3), np.eye(4)

    vis, scale, T_vis = find("visual")
    col, _, T_col = find("collision")
    if vis is None and col is None:
        raise ObjectError(f"{path}: no <mesh> geometry in the object URDF")
    if vis is None:
        vis, T_vis = col, T_col
    return vis, scale, T_vis, col, T_col  # type: ignore[return-value]


class ObjectModel:
    """A rigid object: repaired mesh, mass properties, samples, SDF grid and convex pieces."""

    def __init__(self, mesh: trimesh.Trimesh, name: str, density: float = DEFAULT_DENSITY,
                 source: Path | None = None, convex_pieces: list[trimesh.Trimesh] | None = None,
                 repair: bool = True, primitives: list[dict] | None = None):
        if len(mesh.faces) == 0:
            raise ObjectError(f"object {name!r}: mesh has no faces")
        if repair:
            self.mesh, self.repair_report = repair_mesh(mesh)
        else:
            self.mesh = mesh
            self.repair_report = RepairReport(0, 0, bool(mesh.is_watertight), bool(mesh.is_watertight), True)
        if len(self.mesh.faces) == 0 or float(np.ptp(self.mesh.vertices, axis=0).max()) <= 0.0:
            raise ObjectError(f"object {name!r}: mesh is empty or degenerate after repair")
        self.name = name
        self.density = float(density)
        self.source = source
        self._pieces = convex_pieces
        self._pieces_resolved = False  # convex_pieces() settles hull / provided / V-HACD once
        # exact solids for the simulator (built-ins only; see ohra.objects.builtin), else None
        self.primitives = primitives

    # -- construction ------------------------------------------------------------------------------
    @classmethod
    def load(cls, path: str | Path, density: float = DEFAULT_DENSITY, name: str | None = None) -> "ObjectModel":
        """Load ``.obj/.stl/.ply`` or a PyBullet-style object URDF (mesh scale applied)."""
        path = Path(path)
        if not path.exists():
            raise ObjectError(f"object file not found: {path}")
        if path.is_dir():
            cands = [path / "textured_simple_reoriented.obj", path / "model.urdf"] + sorted(path.glob("*.obj")) + sorted(path.glob("*.stl"))
            cands = [c for c in cands if c.is_file() and c.name != "collision_vhacd.obj"]
            if not cands:
                raise ObjectError(f"{path}: folder holds no mesh (.obj/.stl) or model.urdf")
            return cls.load(cands[0], density, name or path.name)
        pieces = None
        if path.suffix.lower() == ".urdf":
            # the object frame is the URDF link frame: mesh scale, then the <visual>/<collision> origin
            mesh_path, scale, T_vis, col, T_col = _urdf_mesh(path)
            mesh = _load_mesh_file(mesh_path, scale)
            mesh.apply_transform(T_vis)
            if col is not None and col.is_file() and col != mesh_path:
                pieces = [pc.apply_transform(T_col) for pc in load_convex_pieces(col, scale)]
            label = name or path.parent.name
        elif path.suffix.lower() in MESH_SUFFIXES:
            mesh = _load_mesh_file(path)
            sib = path.parent / "collision_vhacd.obj"
            if sib.is_file() and sib != path:
                pieces = load_convex_pieces(sib)
            label = name or (path.parent.name if path.stem.startswith("textured") else path.stem)
        else:
            raise ObjectError(f"{path}: unsupported object file type {path.suffix!r} (use .obj, .stl, .ply or .urdf)")
        return cls(mesh, label, density, path, pieces)

    @classmethod
    def builtin(cls, name: str, density: float = DEFAULT_DENSITY) -> "ObjectModel":
        """A built-in primitive object generated by code (see :func:`builtin_object_names`)."""
        from ohra.objects.builtin import BUILTINS

        if name not in BUILTINS:
            raise ObjectError(f"unknown built-in object {name!r}; known: {', '.join(BUILTINS)}")
        mesh, pieces, prims = BUILTINS[name]()
        return cls(mesh, name, density, None, pieces, repair=False, primitives=prims)

    # -- properties ----------------------------------------------------------------------------------
    @cached_property
    def mesh_hash(self) -> str:
        """SHA-256 (16 hex) of the repaired vertices and faces."""
        h = hashlib.sha256()
        h.update(np.ascontiguousarray(self.mesh.vertices, dtype=np.float64).tobytes())
        h.update(np.ascontiguousarray(self.mesh.faces, dtype=np.int64).tobytes())
        return h.hexdigest()[:16]

    @property
    def watertight(self) -> bool:
        return bool(self.mesh.is_watertight)

    @cached_property
    def volume(self) -> float:
        """Volume [m^3]: exact for a watertight mesh, else the SDF grid's inside-voxel count."""
        if self.watertight:
            return float(abs(self.mesh.volume))
        g = self.sdf()
        return float((g.values < 0).sum() * g.spacing**3)

    @property
    def mass(self) -> float:
        """Mass [kg] = volume x density."""
        return self.volume * self.density

    @cached_property
    def center_mass(self) -> np.ndarray:
        """Centre of mass in the mesh frame [m] (uniform density)."""
        if self.watertight:
            return np.asarray(self.mesh.center_mass, dtype=float)
        g = self.sdf()
        idx = np.argwhere(g.values < 0)
        return g.origin + g.spacing * idx.mean(axis=0) if len(idx) else self.mesh.bounds.mean(axis=0)

    @cached_property
    def inertia(self) -> np.ndarray:
        """(3,3) inertia tensor about the centre of mass [kg m^2] (convex hull when not watertight)."""
        m = self.mesh if self.watertight else self.mesh.convex_hull
        I = np.asarray(m.moment_inertia, dtype=float) * self.density  # trimesh assumes unit density
        return I

    @property
    def bounds(self) -> np.ndarray:
        return np.asarray(self.mesh.bounds, dtype=float)

    @property
    def radius(self) -> float:
        """Radius of the bounding sphere about the centre of mass [m]."""
        return float(np.linalg.norm(self.mesh.vertices - self.center_mass, axis=1).max())

    # -- sampling --------------------------------------------------------------------------------------
    def sample_surface(self, n: int, seed: int = 0, oversample: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """(n,3) area-uniform surface points and (n,3) outward normals, seeded.

        With ``oversample > 1``, ``n * oversample`` points are drawn and reduced to ``n`` by
        farthest-point sampling (more even coverage).
        """
        m = max(int(n) * max(int(oversample), 1), 1)
        pts, fid = trimesh.sample.sample_surface(self.mesh, m, seed=seed)
        nrm = self.mesh.face_normals[fid]
        if m > n:
            idx = farthest_point_sampling(pts, n, seed=seed)
            pts, nrm = pts[idx], nrm[idx]
        return np.asarray(pts), np.asarray(nrm)

    # -- signed distance -------------------------------------------------------------------------------
    @cached_property
    def _surface_tree(self) -> tuple[cKDTree, np.ndarray, np.ndarray, float]:
        area = float(self.mesh.area)
        n = int(np.clip(area / (0.0015**2), 20_000, 150_000))
        pts, fid = trimesh.sample.sample_surface(self.mesh, n, seed=0)
        pts = np.vstack([pts, self.mesh.vertices])
        nrm = np.vstack([self.mesh.face_normals[fid], self.mesh.vertex_normals])
        spacing = math.sqrt(area / n)
        return cKDTree(pts), pts, nrm, spacing

    @property
    def sdf_sample_spacing(self) -> float:
        """Mean spacing of the surface samples behind :meth:`signed_distance` [m]."""
        return self._surface_tree[3]

    def signed_distance(self, points: np.ndarray, k: int = 4) -> np.ndarray:
        """Signed distance [m] at (N,3) points in the mesh frame (negative inside)."""
        tree, pts, nrm, _ = self._surface_tree
        p = np.asarray(points, dtype=float).reshape(-1, 3)
        d, i = tree.query(p, k=k)
        # pseudo-normal sign: vote of the k nearest samples' outward normals (robust on edges)
        side = np.einsum("nkj,nkj->nk", p[:, None, :] - pts[i], nrm[i])
        w = 1.0 / (d + 1e-9)
        sign = np.where((side * w).sum(axis=1) >= 0.0, 1.0, -1.0)
        return sign * d[:, 0]

    def sdf(self, spacing: float | None = None, padding: float = 0.05, max_cells: int = 64) -> SDFGrid:
        """Signed-distance grid covering the bounds plus ``padding`` [m].

        ``spacing`` defaults to the largest padded extent / ``max_cells``. Cached per settings.
        """
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

    # -- convex pieces ---------------------------------------------------------------------------------
    def convex_pieces(self) -> list[trimesh.Trimesh]:
        """Convex decomposition for simulation: the hull of a convex watertight mesh (exactly the
        shape the SDF describes, preferred even over a provided decomposition, which for YCB boxes
        is off by up to 7 mm), else a provided decomposition, else PyBullet's V-HACD (cached on disk
        by mesh hash)."""
        if not self._pieces_resolved:
            hull = self.mesh.convex_hull
            if self.watertight and abs(hull.volume - self.volume) <= 0.01 * hull.volume:
                self._pieces = [hull]
            elif self._pieces is None:
                self._pieces = self._decompose()
            self._pieces_resolved = True
        return self._pieces

    def _decompose(self) -> list[trimesh.Trimesh]:
        out = cache_dir() / "vhacd" / f"{self.mesh_hash}.obj"
        if not out.is_file():
            import pybullet as pb

            out.parent.mkdir(parents=True, exist_ok=True)
            src = out.with_suffix(".in.obj")
            self.mesh.export(str(src))
            tmp = out.with_suffix(".tmp.obj")
            client = pb.connect(pb.DIRECT)
            try:
                pb.vhacd(str(src), str(tmp), str(out.with_suffix(".log")), resolution=100000, physicsClientId=client)
            finally:
                pb.disconnect(client)
            tmp.replace(out)
            src.unlink(missing_ok=True)
        return load_convex_pieces(out)

    def describe(self) -> dict:
        """Summary for reports and manifests."""
        return {
            "name": self.name, "source": str(self.source) if self.source else "builtin", "mesh_hash": self.mesh_hash,
            "faces": int(len(self.mesh.faces)), "watertight": self.watertight, "volume_m3": self.volume,
            "mass_kg": self.mass, "density": self.density, "radius_m": self.radius,
            "repair": self.repair_report.__dict__,
        }


def load_convex_pieces(path: Path, scale: np.ndarray | None = None) -> list[trimesh.Trimesh]:
    """Convex pieces of a decomposition file (V-HACD / CoACD OBJ): one piece per ``o``/``g`` object,
    or per connected component when the file has a single object; each piece is its convex hull."""
    path = Path(path)
    if not path.is_file():
        raise ObjectError(f"convex decomposition not found: {path}")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # trimesh warns about texture-less materials
            loaded = trimesh.load(str(path), process=False, group_material=False, split_object=True, maintain_order=True)
    except Exception as exc:  # trimesh raises many types for bad files
        raise ObjectError(f"{path}: cannot read convex decomposition ({exc})") from None
    geoms = [g.copy() for g in (loaded.dump() if isinstance(loaded, trimesh.Scene) else [loaded]) if isinstance(g, trimesh.Trimesh)]
    for g in geoms:
        g.remove_unreferenced_vertices()  # an OBJ object may carry the whole file's vertex list
    if len(geoms) == 1:
        # unmerged vertices would split every triangle off: merge before splitting by connectivity
        merged = geoms[0]
        merged.merge_vertices()
        geoms = merged.split(only_watertight=False) or [merged]
    pieces = [g.convex_hull for g in geoms if len(g.faces) >= 4 and float(np.ptp(g.vertices, axis=0).min()) > 0.0]
    if not pieces:
        raise ObjectError(f"{path}: convex decomposition holds no solid piece")
    if scale is not None:
        for pc in pieces:
            pc.apply_scale(scale)
    return pieces


def farthest_point_sampling(points: np.ndarray, k: int, seed: int = 0) -> np.ndarray:
    """Indices of ``k`` points chosen by farthest-point sampling from a seeded random start."""
    p = np.asarray(points, dtype=float)
    n = len(p)
    k = min(int(k), n)
    rng = np.random.default_rng(seed)
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


def resolve_objects(spec: list[str] | str | None) -> list[ObjectModel]:
    """Objects from CLI-style specs: ``builtin`` (all built-ins), ``builtin:NAME``, a mesh/URDF file,
    or a folder (each sub-folder or mesh file in it)."""
    specs = [spec] if isinstance(spec, str) else list(spec or ["builtin"])
    out: list[ObjectModel] = []
    for s in specs:
        if s == "builtin":
            out += [ObjectModel.builtin(n) for n in builtin_object_names()]
        elif s.startswith("builtin:"):
            out.append(ObjectModel.builtin(s.split(":", 1)[1]))
        else:
            p = Path(s)
            if not p.exists():
                raise ObjectError(f"object file or folder not found: {p}")
            if p.is_dir() and not any(p.glob("*.obj")) and not (p / "model.urdf").exists():
                subs = sorted(d for d in p.iterdir() if d.is_dir())
                files = sorted(f for f in p.iterdir() if f.suffix.lower() in MESH_SUFFIXES)
                if not subs and not files:
                    raise ObjectError(f"{p}: folder holds no objects")
                out += [ObjectModel.load(d) for d in subs] + [ObjectModel.load(f) for f in files]
            else:
                out.append(ObjectModel.load(p))
    names = [o.name for o in out]
    if len(set(names)) != len(names):
        warnings.warn("several objects share a name; shards are keyed by name and mesh hash", stacklevel=2)
    return out
