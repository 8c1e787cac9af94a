"""Convex pieces of an object: reading decomposition files, solidity checks, and V-HACD.

V-HACD (``pybullet.vhacd``) runs in a child process with a time limit and its output discarded:
in-process it cannot be interrupted (a flat mesh made it loop forever) and it prints its usage
text on the process's stdout whatever ``--quiet`` says. Its result is cached under
``cache_dir()/vhacd/<mesh hash>.obj`` and written by rename, so an interrupted or failed run
leaves no file behind that a later run would trust.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np
import trimesh

from ohra.errors import ObjectError
from ohra.paths import cache_dir

# an object thinner than this along any principal axis has no volume to grasp or simulate [m]
MIN_THICKNESS_M = 1e-4
# provided decompositions next to a surface mesh (pybullet-object-models and YCB releases)
DECOMPOSITION_NAMES = ("collision_vhacd.obj", "textured_vhacd.obj")
VHACD_TIMEOUT_S = 300.0


def check_solid(mesh: trimesh.Trimesh, label: str) -> None:
    """Raise :class:`ObjectError` unless ``mesh`` spans a volume (not a point, line or plane).

    The thickness is the extent of the vertices along their least principal axis, so a tilted
    flat sheet is caught as well as an axis-aligned one.
    """
    v = np.asarray(mesh.vertices, dtype=float)
    if len(mesh.faces):
        used = np.unique(np.asarray(mesh.faces))
        bad = used[~np.isfinite(v[used]).all(axis=1)]
        if len(bad):  # an SVD of them failed with numpy's LinAlgError; a vertex no face uses is dropped by repair
            raise ObjectError(f"object {label!r}: {len(bad)} vertices used by its faces are not finite numbers (NaN or "
                              f"infinity), e.g. vertex {int(bad[0])}; fix or remove them in the mesh file")
        v = v[used]
    if len(v) < 4 or len(mesh.faces) < 2:
        raise ObjectError(f"object {label!r}: {len(mesh.faces)} face(s) and {len(v)} vertices span no volume; "
                          "a graspable object needs a closed surface")
    c = v - v.mean(axis=0)
    _, _, axes = np.linalg.svd(c, full_matrices=False)
    extent = np.ptp(c @ axes.T, axis=0)  # along the principal axes, largest first
    if extent[-1] < MIN_THICKNESS_M:
        # a whole object below a centimetre is a units problem first (e.g. --scale 0.001 given to every object of a
        # command, one of them already in metres): say so rather than call a 3 cm torus flat
        units = (f"; the whole object is only {1e3 * extent[0]:.3g} mm across, so its units are likely wrong (a --scale "
                 "meant for millimetre meshes given to one already in metres?)") if extent[0] < 0.01 else ""
        raise ObjectError(f"object {label!r} is flat: {1e3 * extent[-1]:.3g} mm thick across its thinnest principal axis "
                          f"(extents {', '.join(f'{1e3 * e:.3g}' for e in extent)} mm); a graspable object needs volume{units}")


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
    pieces = []
    for g in geoms:
        if len(g.vertices) < 4 or float(np.ptp(g.vertices, axis=0).min()) <= 0.0:
            continue
        try:
            hull = g.convex_hull
        except Exception:  # Qhull rejects coplanar pieces
            continue
        if hull.volume > 0:
            pieces.append(hull)
    if not pieces:
        raise ObjectError(f"{path}: convex decomposition holds no solid piece")
    if scale is not None:
        for pc in pieces:
            pc.apply_scale(scale)
    return pieces


def convex_components(mesh: trimesh.Trimesh, rel: float = 0.02) -> list[trimesh.Trimesh] | None:
    """The mesh's connected components as convex pieces when it is already a convex decomposition
    (two or more closed components, each within ``rel`` of its hull's volume: V-HACD / CoACD output
    saved as one mesh, or separate convex parts); else None."""
    parts = mesh.split(only_watertight=False)
    if len(parts) < 2 or not all(p.is_watertight for p in parts):
        return None
    hulls = []
    for p in parts:
        try:
            h = p.convex_hull
        except Exception:  # Qhull rejects flat parts
            return None
        if not (h.volume > 0 and abs(float(p.volume)) >= (1.0 - rel) * h.volume):
            return None
        hulls.append(h)
    return hulls


_VHACD_SCRIPT = (
    "import sys, pybullet as pb\n"
    "c = pb.connect(pb.DIRECT)\n"
    "pb.vhacd(sys.argv[1], sys.argv[2], sys.argv[3], resolution=int(sys.argv[4]), physicsClientId=c)\n"
)


def vhacd_pieces(mesh: trimesh.Trimesh, mesh_hash: str, resolution: int = 100_000,
                 timeout_s: float = VHACD_TIMEOUT_S) -> list[trimesh.Trimesh]:
    """V-HACD convex pieces of ``mesh`` (cached by ``mesh_hash``); :class:`ObjectError` if it fails."""
    out = cache_dir() / "vhacd" / f"{mesh_hash}.obj"
    if not out.is_file():
        check_solid(mesh, mesh_hash)
        out.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(dir=out.parent) as tmp:
            src, dst, log = (Path(tmp) / n for n in ("in.obj", "out.obj", "log.txt"))
            mesh.export(str(src))
            try:
                proc = subprocess.run([sys.executable, "-c", _VHACD_SCRIPT, str(src), str(dst), str(log), str(int(resolution))],
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=timeout_s,
                                      env={**os.environ, "OMP_NUM_THREADS": "1"})
            except subprocess.TimeoutExpired:
                raise ObjectError(f"V-HACD did not finish within {timeout_s:.0f} s on mesh {mesh_hash}; "
                                  "provide a decomposition (collision_vhacd.obj) next to the mesh") from None
            if proc.returncode != 0 or not dst.is_file() or dst.stat().st_size == 0:
                raise ObjectError(f"V-HACD failed on mesh {mesh_hash} (exit {proc.returncode}); "
                                  "provide a decomposition (collision_vhacd.obj) next to the mesh")
            os.replace(dst, out)
    return load_convex_pieces(out)
