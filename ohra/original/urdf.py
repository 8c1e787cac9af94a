"""Original (non-canonical) hand URDFs: robust loading, batched forward kinematics, link geometry.

:func:`load_urdf` reads a hand's original URDF (``.urdf``; ``.xacro`` / ``.urdf.xacro`` are expanded
with the ``xacro`` package first), validates its kinematic tree and resolves every mesh path
(relative to the URDF, or ``package://name/...`` searched next to and above the URDF). A mesh file
that does not exist is *skipped*: a :class:`MissingMeshWarning` names the file and the link, and the
element is removed from :attr:`OriginalHand.urdf_text` so that Pinocchio and PyBullet (which both
refuse absent meshes) still load the hand for kinematics.

Problems that make the hand unusable raise :class:`ohra.ParseError` naming the problem: text that
is not XML, a joint naming an unknown link, a link with two parent joints (a kinematic loop), more
than one root link, a mesh with zero faces (when its geometry is loaded).

Frames: poses are 4x4 transforms of link frames in the URDF root link frame, metres. A *joint
frame* is the child link frame of that joint (URDF semantics: the joint axis is expressed in it).
The joint vector of the hand is its movable joints (revolute, continuous, prismatic) in file
order, mimic joints excluded (they follow their master), as in :class:`ohra.ActionMap`.
"""

from __future__ import annotations

import warnings
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Sequence

import numpy as np

from ohra.errors import ParseError
from ohra.transforms import xyzrpy_to_matrix

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
    def link_poses(self, q: np.ndarray, links: Sequence[str] | None = None) -> np.ndarray:
        """Poses of ``links`` (default: all, order :attr:`links`) in the root frame.

        ``q``: (dof,) -> (L,4,4); (N,dof) -> (N,L,4,4).
        """
        q = np.asarray(q, dtype=float)
        single = q.ndim == 1
        qb = np.atleast_2d(q)
        n_dof = len(self.movable_joints)
        if qb.shape[-1] != n_dof:
            raise ParseError(f"expected an original joint vector of length {n_dof}, got shape {q.shape}")
        index = {name: i for i, name in enumerate(self.movable_joints)}
        N = qb.shape[0]
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
                if j.mimic is not None:
                    master, mult, off = j.mimic
                    val = mult * _joint_value(qb, index, self.joints, master) + off
                else:
                    val = qb[:, index[j.name]]
                M = np.broadcast_to(np.eye(4), (N, 4, 4)).copy()
                if j.type == "prismatic":
                    M[:, :3, 3] = val[:, None] * j.axis
                else:
                    M[:, :3, :3] = _rodrigues(j.axis, val)
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
        import trimesh

        if filename not in self._mesh_cache:
            try:
                m = trimesh.load(filename, force="mesh", process=False)
            except Exception as exc:  # trimesh raises many kinds
                raise ParseError(f"mesh {filename} cannot be read: {exc}") from None
            if not isinstance(m, trimesh.Trimesh) or len(m.faces) == 0:
                raise ParseError(f"mesh {filename} has zero faces")
            self._mesh_cache[filename] = m
        return self._mesh_cache[filename]

    def pinocchio_model(self):
        """Pinocchio model of the (cleaned) URDF, kinematics only."""
        import pinocchio as pin

        try:
            return pin.buildModelFromXML(self.urdf_text)
        except Exception as exc:
            raise ParseError(f"Pinocchio cannot load {self.path}: {exc}") from None


def _joint_value(qb: np.ndarray, index: dict[str, int], joints: dict[str, Joint], name: str) -> np.ndarray:
    j = joints[name]
    if j.mimic is not None:
        master, mult, off = j.mimic
        return mult * _joint_value(qb, index, joints, master) + off
    return qb[:, index[name]]


def _rodrigues(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """(N,3,3) rotations about a fixed unit axis."""
    x, y, z = axis
    K = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    s, c = np.sin(angle)[:, None, None], np.cos(angle)[:, None, None]
    return np.eye(3) + s * K + (1.0 - c) * (K @ K)


# -- loading -------------------------------------------------------------------------------------
def read_urdf_text(path: Path) -> str:
    """URDF text of ``path``; ``.xacro`` files are expanded with the xacro package."""
    if not path.is_file():
        raise ParseError(f"original URDF not found: {path}")
    if path.suffix == ".xacro":
        try:
            import xacro

            return xacro.process_file(str(path)).toxml()
        except Exception as exc:
            raise ParseError(f"{path}: xacro expansion failed: {exc}") from None
    return path.read_text(errors="replace")


def _floats(text: str | None, n: int, default: float, where: str) -> np.ndarray:
    if text is None:
        return np.full(n, default)
    parts = text.replace(",", " ").split()
    try:
        vals = np.array([float(p) for p in parts])
    except ValueError:
        raise ParseError(f"{where}: expected {n} numbers, got {text!r}") from None
    if vals.size != n:
        raise ParseError(f"{where}: expected {n} numbers, got {text!r}")
    return vals


def _origin(elem: ET.Element | None, where: str) -> np.ndarray:
    if elem is None:
        return np.eye(4)
    xyz = _floats(elem.get("xyz"), 3, 0.0, where + " origin xyz")
    rpy = _floats(elem.get("rpy"), 3, 0.0, where + " origin rpy")
    return xyzrpy_to_matrix(np.concatenate([xyz, rpy]))


def resolve_mesh_path(filename: str, urdf_dir: Path) -> Path:
    """Absolute path of a mesh reference (``package://pkg/rel``, ``file://``, relative or absolute).

    ``package://pkg/rel`` is searched as ``<dir>/rel`` and ``<dir>/pkg/rel`` for the URDF's folder
    and each folder above it, and as ``<ancestor named pkg>/rel``; the first existing file wins, else
    the path next to the URDF is returned (and reported missing by the caller).
    """
    if filename.startswith("file://"):
        return Path(filename[len("file://"):])
    if filename.startswith("package://"):
        rest = filename[len("package://"):]
        pkg, _, rel = rest.partition("/")
        candidates = []
        for d in (urdf_dir, *urdf_dir.parents):
            candidates += [d / rel, d / pkg / rel]
            if d.name == pkg:
                candidates.append(d / rel)
        for c in candidates:
            if c.is_file():
                return c.resolve()
        return (urdf_dir / rel).resolve()
    p = Path(filename)
    return p if p.is_absolute() else (urdf_dir / p).resolve()


def load_urdf(source: str | Path, base_dir: str | Path | None = None) -> OriginalHand:
    """Load and validate an original hand URDF (path, or XML text with ``base_dir`` for meshes)."""
    path: Path | None = None
    if isinstance(source, Path) or (isinstance(source, str) and not source.lstrip().startswith("<")):
        path = Path(source).expanduser().resolve()
        text = read_urdf_text(path)
        where = str(path)
        urdf_dir = path.parent
    else:
        text = str(source)
        where = "<urdf text>"
        urdf_dir = Path(base_dir) if base_dir is not None else Path.cwd()
    try:
        root_elem = ET.fromstring(text)
    except ET.ParseError as exc:
        raise ParseError(f"{where}: not valid XML ({exc})") from None
    if root_elem.tag != "robot":
        raise ParseError(f"{where}: root element is <{root_elem.tag}>, expected <robot>")

    links = [l.get("name") for l in root_elem.findall("link")]
    if not links:
        raise ParseError(f"{where}: no <link> elements")
    dup = sorted({n for n in links if links.count(n) > 1})
    if dup:
        raise ParseError(f"{where}: link {dup[0]!r} is defined twice")
    link_set = set(links)

    joints: dict[str, Joint] = {}
    child_of: dict[str, str] = {}
    for je in root_elem.findall("joint"):
        name = je.get("name")
        jtype = je.get("type")
        jw = f"{where}: joint {name!r}"
        if not name:
            raise ParseError(f"{where}: a <joint> has no name")
        if name in joints:
            raise ParseError(f"{jw} is defined twice")
        if jtype not in KNOWN_TYPES:
            raise ParseError(f"{jw} has unknown type {jtype!r}")
        if jtype in ("floating", "planar"):
            raise ParseError(f"{jw}: {jtype} joints are not supported in a hand")
        pe, ce = je.find("parent"), je.find("child")
        if pe is None or ce is None:
            raise ParseError(f"{jw} lacks <parent> or <child>")
        parent, child = pe.get("link"), ce.get("link")
        for ln in (parent, child):
            if ln not in link_set:
                raise ParseError(f"{jw} names link {ln!r}, which is not defined")
        if child in child_of:
            raise ParseError(
                f"{where}: kinematic loop: link {child!r} is the child of two joints ({child_of[child]!r} and {name!r})"
            )
        child_of[child] = name
        axis = _floats(je.find("axis").get("xyz") if je.find("axis") is not None else None, 3, 0.0, jw + " axis")
        if je.find("axis") is None:
            axis = np.array([1.0, 0.0, 0.0])
        nrm = float(np.linalg.norm(axis))
        if jtype in MOVABLE_TYPES:
            if nrm < 1e-12:
                raise ParseError(f"{jw} has a zero axis")
            axis = axis / nrm
        lim = je.find("limit")
        if jtype == "continuous":
            lo, up = -np.pi, np.pi
        elif jtype in MOVABLE_TYPES:
            if lim is None:
                raise ParseError(f"{jw} ({jtype}) has no <limit>")
            lo = float(_floats(lim.get("lower"), 1, 0.0, jw + " lower")[0])
            up = float(_floats(lim.get("upper"), 1, 0.0, jw + " upper")[0])
            if lo > up:
                raise ParseError(f"{jw}: lower limit {lo} > upper limit {up}")
        else:
            lo = up = 0.0
        mimic = None
        me = je.find("mimic")
        if me is not None and jtype in MOVABLE_TYPES:
            mimic = (me.get("joint"), float(me.get("multiplier", 1.0)), float(me.get("offset", 0.0)))
        joints[name] = Joint(name, jtype, parent, child, _origin(je.find("origin"), jw), axis, lo, up, mimic)
    for j in joints.values():
        if j.mimic is not None and j.mimic[0] not in joints:
            raise ParseError(f"{where}: joint {j.name!r} mimics unknown joint {j.mimic[0]!r}")

    roots = [l for l in links if l not in child_of]
    if len(roots) == 0:
        raise ParseError(f"{where}: kinematic loop: every link has a parent joint (no root link)")
    if len(roots) > 1:
        raise ParseError(f"{where}: the URDF has {len(roots)} root links ({', '.join(roots)}); expected one tree")
    # every link must be reachable from the root (a cycle detached from the root is a loop)
    seen, stack = set(), [roots[0]]
    children: dict[str, list[str]] = {}
    for j in joints.values():
        children.setdefault(j.parent, []).append(j.child)
    while stack:
        x = stack.pop()
        if x in seen:
            raise ParseError(f"{where}: kinematic loop through link {x!r}")
        seen.add(x)
        stack.extend(children.get(x, []))
    if len(seen) != len(links):
        loop = sorted(link_set - seen)
        raise ParseError(f"{where}: kinematic loop: links {loop} are not reachable from the root {roots[0]!r}")

    geoms, missing = _collect_geometry(root_elem, urdf_dir, where)
    cleaned = ET.tostring(root_elem, encoding="unicode")
    return OriginalHand(
        path=path,
        urdf_text=cleaned,
        root=roots[0],
        links=tuple(links),
        joints=joints,
        geometries=tuple(geoms),
        missing_meshes=tuple(missing),
    )


def _collect_geometry(root_elem: ET.Element, urdf_dir: Path, where: str) -> tuple[list[Geometry], list[str]]:
    """Geometry elements with resolved mesh paths; elements whose mesh is missing are removed
    from the tree (in place) with a warning naming the file."""
    geoms: list[Geometry] = []
    missing: list[str] = []
    for le in root_elem.findall("link"):
        lname = le.get("name")
        for tag in ("visual", "collision"):
            for ge in list(le.findall(tag)):
                gw = f"{where}: link {lname!r} {tag}"
                geo = ge.find("geometry")
                if geo is None or len(geo) == 0:
                    continue
                shape = geo[0]
                T = _origin(ge.find("origin"), gw)
                if shape.tag == "box":
                    size = tuple(_floats(shape.get("size"), 3, 0.0, gw + " box size"))
                    geoms.append(Geometry(lname, tag, "box", T, size))
                elif shape.tag == "cylinder":
                    r = float(_floats(shape.get("radius"), 1, 0.0, gw + " cylinder radius")[0])
                    h = float(_floats(shape.get("length"), 1, 0.0, gw + " cylinder length")[0])
                    geoms.append(Geometry(lname, tag, "cylinder", T, (r, h)))
                elif shape.tag == "sphere":
                    r = float(_floats(shape.get("radius"), 1, 0.0, gw + " sphere radius")[0])
                    geoms.append(Geometry(lname, tag, "sphere", T, (r,)))
                elif shape.tag == "mesh":
                    fn = shape.get("filename") or ""
                    p = resolve_mesh_path(fn, urdf_dir)
                    if not p.is_file():
                        warnings.warn(
                            f"{where}: mesh file {p} not found (link {lname!r} {tag}); geometry skipped",
                            MissingMeshWarning,
                            stacklevel=3,
                        )
                        missing.append(str(p))
                        le.remove(ge)
                        continue
                    shape.set("filename", str(p))  # absolute: the cleaned text loads from anywhere
                    scale = tuple(_floats(shape.get("scale"), 3, 1.0, gw + " mesh scale"))
                    geoms.append(Geometry(lname, tag, "mesh", T, (), str(p), scale))  # type: ignore[arg-type]
    return geoms, missing


__all__ = ["OriginalHand", "Joint", "Geometry", "MissingMeshWarning", "load_urdf", "read_urdf_text", "resolve_mesh_path"]
