"""Mesh repair: merge vertices, drop degenerate faces, fill small holes, orient faces outward."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh


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
    merged = m.copy() if m.is_watertight else None
    m.update_faces(m.nondegenerate_faces())
    m.update_faces(m.unique_faces())
    m.remove_unreferenced_vertices()
    if not m.is_watertight:
        trimesh.repair.fill_holes(m)
    trimesh.repair.fix_winding(m)
    trimesh.repair.fix_normals(m)
    if merged is not None and not m.is_watertight:
        # dropping degenerate or duplicate faces opened a closed surface: keep the merged one
        m = merged
        trimesh.repair.fix_normals(m)
    if m.is_watertight and m.volume < 0:
        m.invert()
    note = ""
    if not m.is_watertight:
        note = ("still not watertight after repair: the object is grasped and simulated as its convex "
                "body (hull or decomposition), whose volume and mass properties are reported")
    return m, RepairReport(nv - len(m.vertices), nf - len(m.faces), was, bool(m.is_watertight), bool(m.is_winding_consistent), note)
