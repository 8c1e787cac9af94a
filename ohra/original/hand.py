"""The original hand model: links, joints (with mimic relations), geometry and batched kinematics.

:class:`OriginalHand` is what :func:`ohra.original.urdf.load_urdf` returns. Frames: poses are 4x4
transforms of link frames in the URDF root link frame, metres. A *joint frame* is the child link
frame of that joint (URDF semantics: the joint axis is expressed in it). The joint vector of the
hand is its movable joints (revolute, continuous, prismatic) in file order, mimic joints excluded
(they follow their master), as in :class:`ohra.ActionMap`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from ohra.errors import ParseError
from ohra.transforms import axis_angle_to_matrix

MOVABLE_TYPES = ("revolute", "continuous", "prismatic")
KNOWN_TYPES = MOVABLE_TYPES + ("fixed", "floating", "planar")


class MissingMeshWarning(UserWarning):
    """A mesh file named by the URDF does not exist; its geometry element is skipped."""


@dataclass(frozen=True)
class Geometry:
    """One ``<visual>``/``<collision>`` element: ``kind`` box|cylinder|sphere|mesh, pose in the link frame."""

    link: str
    tag: str  # "visual" or "collision"
    kind: str
    origin: np.ndarray  # (4,4) element pose in the link frame
    size: tuple[float, ...] = ()  # box (x,y,z); cylinder (radius, length); sphere (radius,)
    filename: str | None = None  # resolved absolute mesh path
    scale: tuple[float, float, float] = (1.0, 1.0, 1.0)


@dataclass(frozen=True)
class Joint:
    name: str
    type: str
    parent: str
    child: str
    origin: np.ndarray  # (4,4) child frame in the parent frame at q=0
    axis: np.ndarray  # (3,) unit axis in the child (joint) frame
    lower: float
    upper: float
    mimic: tuple[str, float, float] | None = None  # (master joint, multiplier, offset)


@dataclass
class OriginalHand:
    """A validated original hand URDF with resolved geometry and batched forward kinematics."""

    path: Path | None
    urdf_text: str  # cleaned XML (missing meshes removed); loads in Pinocchio / PyBullet
    root: str
    links: tuple[str, ...]
    joints: dict[str, Joint]
    geometries: tuple[Geometry, ...]
    missing_meshes: tuple[str, ...] = ()
    _mesh_cache: dict = field(default_factory=dict, repr=False)

    # -- structure -------------------------------------------------------------------------------
    @cached_property
    def movable_joints(self) -> tuple[str, ...]:
        """Names of the joint-vector entries (movable, not mimic), file order."""
        return tuple(n for n, j in self.joints.items() if j.type in MOVABLE_TYPES and j.mimic is None)

    @cached_property
    def parent_joint(self) -> dict[str, Joint]:
        """child link -> the joint whose child it is."""
        return {j.child: j for j in self.joints.values()}

    @cached_property
    def _order(self) -> tuple[str, ...]:
        """Links in topological order (root first, depth-first)."""
        children: dict[str, list[str]] = {}
        for j in self.joints.values():
            children.setdefault(j.parent, []).append(j.child)
        out, stack = [], [self.root]
        while stack:
            link = stack.pop()
            out.append(link)
            stack.extend(reversed(children.get(link, [])))
        return tuple(out)

    def ancestors(self, link: str) -> list[str]:
        """Links from ``link`` up to the root (inclusive)."""
        out = [link]
        while out[-1] in self.parent_joint:
            out.append(self.parent_joint[out[-1]].parent)
        return out

    def descendants(self, link: str) -> list[str]:
        """``link`` and every link below it."""
        children: dict[str, list[str]] = {}
        for j in self.joints.values():
            children.setdefault(j.parent, []).append(j.child)
        out, stack = [], [link]
        while stack:
            x = stack.pop()
            out.append(x)
            stack.extend(children.get(x, []))
        return out

    @property
    def lower(self) -> np.ndarray:
        """(n,) lower limits of the joint vector (continuous joints: -pi)."""
        return np.array([self.joints[n].lower for n in self.movable_joints])

    @property
    def upper(self) -> np.ndarray:
        return np.array([self.joints[n].upper for n in self.movable_joints])

    def random_configurations(self, n: int, seed: int = 0) -> np.ndarray:
        """(n, dof) joint vectors uniform within the limits, seeded."""
        rng = np.random.default_rng(seed)
        return self.lower + rng.random((int(n), len(self.movable_joints))) * (self.upper - self.lower)

    # -- kinematics ------------------------------------------------------------------------------
    @cached_property
    def mimic_joints(self) -> tuple[str, ...]:
        """Names of the movable joints that follow another through ``<mimic>``, file order."""
        return tuple(n for n, j in self.joints.items() if j.type in MOVABLE_TYPES and j.mimic is not None)

    def mimic_root(self, name: str) -> tuple[str, float, float]:
        """(actuated joint, multiplier, offset) with ``q[name] = multiplier * q[root] + offset``,
        composing chains of mimics; an actuated joint returns ``(name, 1, 0)``."""
        a, b = 1.0, 0.0
        j = self.joints[name]
        while j.mimic is not None:
            master, mult, off = j.mimic
            a, b = a * mult, a * off + b  # q = a * (mult * q_master + off) + b
            j = self.joints[master]
        return j.name, a, b

    def link_poses(
        self, q: np.ndarray, links: Sequence[str] | None = None, passive: Mapping[str, Any] | None = None
    ) -> np.ndarray:
        """Poses of ``links`` (default: all, order :attr:`links`) in the root frame.

        ``q``: (dof,) -> (L,4,4); (N,dof) -> (N,L,4,4). ``passive``: mimic joint name -> value
        (scalar or (N,)) that replaces what its ``<mimic>`` tag would give (joints mimicking it
        follow the given value); used to pose the hand where the coupling does not hold, e.g. at
        the canonical zero of every slot.
        """
        q = np.asarray(q, dtype=float)
        single = q.ndim == 1
        qb = np.atleast_2d(q)
        n_dof = len(self.movable_joints)
        if qb.shape[-1] != n_dof:
            raise ParseError(f"expected an original joint vector of length {n_dof}, got shape {q.shape}")
        index = {name: i for i, name in enumerate(self.movable_joints)}
        N = qb.shape[0]
        over = {}
        for name, v in (passive or {}).items():
            if name not in self.mimic_joints:
                raise ParseError(f"passive value for {name!r}, which is not a mimic joint (mimic joints: {', '.join(self.mimic_joints) or 'none'})")
            over[name] = np.broadcast_to(np.asarray(v, dtype=float), (N,))
        want = list(self.links if links is None else links)
        for w in want:
            if w not in self.links:
                raise ParseError(f"unknown link {w!r}")
        needed: set[str] = set()
        for w in want:
            needed.update(self.ancestors(w))
        poses: dict[str, np.ndarray] = {}
        for link in self._order:
            if link not in needed:
                continue
            if link == self.root:
                poses[link] = np.broadcast_to(np.eye(4), (N, 4, 4))
                continue
            j = self.parent_joint[link]
            T = poses[j.parent] @ j.origin
            if j.type in MOVABLE_TYPES:
                val = _joint_value(qb, index, self.joints, j.name, over)
                M = np.broadcast_to(np.eye(4), (N, 4, 4)).copy()
                if j.type == "prismatic":
                    M[:, :3, 3] = val[:, None] * j.axis
                else:
                    M[:, :3, :3] = axis_angle_to_matrix(j.axis, val)
                T = T @ M
            poses[link] = T
        out = np.stack([poses[w] for w in want], axis=1)
        return out[0] if single else out

    # -- geometry --------------------------------------------------------------------------------
    def link_geometry(self, link: str, prefer: str = "collision"):
        """The link's geometry as one trimesh in the link frame, or None.

        Collision elements when the link has any, else visual ones (``prefer="visual"`` swaps).
        Raises :class:`ParseError` for a mesh with zero faces.
        """
        import trimesh

        other = "visual" if prefer == "collision" else "collision"
        for tag in (prefer, other):
            elems = [g for g in self.geometries if g.link == link and g.tag == tag]
            if elems:
                parts = [self._element_mesh(g) for g in elems]
                parts = [p for p in parts if p is not None]
                if parts:
                    return trimesh.util.concatenate(parts) if len(parts) > 1 else parts[0]
        return None

    def geometry_source(self, link: str, prefer: str = "collision") -> str | None:
        """Which element kind :meth:`link_geometry` uses for ``link`` ("collision"/"visual"), or None."""
        other = "visual" if prefer == "collision" else "collision"
        for tag in (prefer, other):
            if any(g.link == link and g.tag == tag for g in self.geometries):
                return tag
        return None

    def _element_mesh(self, g: Geometry):
        import trimesh

        if g.kind == "box":
            m = trimesh.creation.box(extents=g.size)
        elif g.kind == "cylinder":
            m = trimesh.creation.cylinder(radius=g.size[0], height=g.size[1], sections=24)
        elif g.kind == "sphere":
            m = trimesh.creation.icosphere(subdivisions=2, radius=g.size[0])
        else:
            m = self._load_mesh(g.filename).copy()
            m.apply_scale(np.asarray(g.scale)) if len(set(g.scale)) == 1 else m.apply_transform(np.diag([*g.scale, 1.0]))
        m.apply_transform(g.origin)
        return m

    def _load_mesh(self, filename: str):
        if filename not in self._mesh_cache:
            self._mesh_cache[filename] = read_mesh(filename)
        return self._mesh_cache[filename]

    def pinocchio_model(self):
        """Pinocchio model of the (cleaned) URDF, kinematics only."""
        import pinocchio as pin

        try:
            return pin.buildModelFromXML(self.urdf_text)
        except Exception as exc:
            raise ParseError(f"Pinocchio cannot load {self.path}: {exc}") from None


def read_mesh(filename: str | Path):
    """A hand link's mesh file as one trimesh (scene transforms applied, no processing): how the parser
    measures it and the simulator gets it (:func:`ohra.sim.bullet.bullet_mesh`).

    Raises :class:`ParseError` naming the file when it cannot be read or has no faces.
    """
    import trimesh

    try:
        m = trimesh.load(filename, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many kinds
        raise ParseError(f"mesh {filename} cannot be read: {exc}") from None
    if not isinstance(m, trimesh.Trimesh) or len(m.faces) == 0:
        raise ParseError(f"mesh {filename} has zero faces")
    return m


def _joint_value(qb: np.ndarray, index: dict[str, int], joints: dict[str, Joint], name: str, over: dict) -> np.ndarray:
    """(N,) value of joint ``name``: given (``over``), else its entry of q, else through its mimic tag."""
    if name in over:
        return over[name]
    j = joints[name]
    if j.mimic is not None:
        master, mult, off = j.mimic
        return mult * _joint_value(qb, index, joints, master, over) + off
    return qb[:, index[name]]


__all__ = ["OriginalHand", "Joint", "Geometry", "MissingMeshWarning", "MOVABLE_TYPES", "KNOWN_TYPES", "read_mesh"]
