"""Mesh repair: merge vertices, drop degenerate faces, fill small holes, orient faces outward."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh


@dataclass
class RepairReport:
    """What :func:`repair_mesh` did and what it means."""

    merged_vertices: int
    removed_faces: int  # degenerate or duplicate faces dropped
    watertight_before: bool
    watertight: bool
    winding_consistent: bool
    note: str = ""
    filled_faces: int = 0  # faces added to close holes
    filled_area_fraction: float = 0.0  # their area over the repaired mesh's


def repair_mesh(mesh: trimesh.Trimesh) -> tuple[trimesh.Trimesh, RepairReport]:
    """Merge vertices, drop degenerate/duplicate faces, fill small holes, orient faces outward."""
    with np.errstate(divide="ignore", invalid="ignore"):  # trimesh probes the volume of open meshes
        return _repair(mesh)


def _turn_stray_parts_outward(m: trimesh.Trimesh) -> None:
    """Flip, in place, each closed part that faces inward and lies inside no other part (a part saved inside out:
    its volume counted negative). An inward part inside another is a cavity's wall and keeps its faces; a mesh with
    no such stray part is left as it was, face order included (its hash does not change)."""
    if m.body_count < 2:
        return
    groups = trimesh.graph.connected_components(m.face_adjacency, nodes=np.arange(len(m.faces)))
    if len(groups) < 2:
        return
    parts = [m.submesh([g], append=True) for g in groups]
    closed = [p.is_watertight for p in parts]
    flip = []
    for i, (g, p) in enumerate(zip(groups, parts)):
        if not closed[i] or p.volume >= 0:
            continue
        probe = p.vertices[:1]
        if not any(j != i and closed[j] and parts[j].volume > 0 and parts[j].contains(probe)[0] for j in range(len(parts))):
            flip.append(g)
    if flip:
        faces = m.faces.copy()
        for g in flip:
            faces[g] = faces[g][:, ::-1]
        m.faces = faces


def _repair(mesh: trimesh.Trimesh) -> tuple[trimesh.Trimesh, RepairReport]:
    m = mesh.copy()
    was = bool(m.is_watertight)
    nv, nf = len(m.vertices), len(m.faces)
    m.merge_vertices(merge_tex=True, merge_norm=True)
    merged = m.copy() if m.is_watertight else None
    m.update_faces(m.nondegenerate_faces())
    m.update_faces(m.unique_faces())
    m.remove_unreferenced_vertices()
    removed = nf - len(m.faces)
    nf_open = len(m.faces)
    if not m.is_watertight:
        trimesh.repair.fill_holes(m)
    filled = len(m.faces) - nf_open
    trimesh.repair.fix_winding(m)
    trimesh.repair.fix_normals(m)
    if merged is not None and not m.is_watertight:
        # dropping degenerate or duplicate faces opened a closed surface: keep the merged one
        m = merged
        trimesh.repair.fix_normals(m)
        removed, filled = nf - len(m.faces), 0
    if m.is_watertight and m.volume < 0:
        m.invert()
    _turn_stray_parts_outward(m)
    note = ""
    if not m.is_watertight:
        note = ("still not watertight after repair: the object is grasped and simulated as its convex "
                "body (hull or decomposition), whose volume and mass properties are reported")
    area = float(m.area_faces[len(m.faces) - filled:].sum() / max(m.area, 1e-30)) if filled > 0 else 0.0
    return m, RepairReport(nv - len(m.vertices), removed, was, bool(m.is_watertight), bool(m.is_winding_consistent), note,
                           filled, area)
