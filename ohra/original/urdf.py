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

The model itself (:class:`OriginalHand`: frames, kinematics, geometry) lives in
:mod:`ohra.original.hand` and is re-exported here.
"""

from __future__ import annotations

import difflib
import threading
import warnings
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from ohra.errors import ParseError, user_stacklevel
from ohra.transforms import xyzrpy_to_matrix
from ohra.original.hand import KNOWN_TYPES, MOVABLE_TYPES, Geometry, Joint, MissingMeshWarning, OriginalHand


# -- loading -------------------------------------------------------------------------------------
def read_urdf_text(path: Path, xacro_args: Mapping[str, str] | None = None) -> str:
    """URDF text of ``path``; ``.xacro`` files are expanded with the xacro package, with ``xacro_args`` as their
    ``<xacro:arg>`` values and ``$(find pkg)`` resolved without ROS (:func:`find_package`)."""
    if not path.is_file():
        raise ParseError(f"original URDF not found: {path}")
    if path.suffix == ".xacro":
        try:
            import xacro
            import xacro.substitution_args as subst
        except ImportError:
            raise ParseError(f"{path}: a .xacro URDF needs the xacro package (pip install xacro)") from None
        with _XACRO_LOCK:  # the resolver is a module global of xacro: one expansion at a time sets and restores it
            return _expand_xacro(xacro, subst, path, xacro_args)
    return path.read_text(errors="replace")


_XACRO_LOCK = threading.Lock()


def _expand_xacro(xacro, subst, path: Path, xacro_args: Mapping[str, str] | None) -> str:
    """``path`` expanded by xacro with ``$(find pkg)`` falling back to :func:`find_package` (call under the lock)."""
    ros_find = subst._eval_find

    def find(pkg: str) -> str:
        try:
            return ros_find(pkg)  # a ROS installation that knows the package
        except Exception:  # no ament_index_python, or the package is not installed: look beside the file
            return str(find_package(pkg, path.parent))

    subst._eval_find = find
    try:
        return xacro.process_file(str(path), mappings={str(k): str(v) for k, v in (xacro_args or {}).items()}).toxml()
    except Exception as exc:
        hint = (" (a spec passes <xacro:arg> values with xacro_args: {name: value})"
                if "substitution argument" in str(exc) or "arg" in type(exc).__name__.lower() else "")
        raise ParseError(f"{path}: xacro expansion failed: {exc}{hint}") from None
    finally:
        subst._eval_find = ros_find


def find_package(pkg: str, start: Path) -> Path:
    """The folder of ROS package ``pkg`` for ``$(find pkg)`` without ROS: the nearest folder named ``pkg`` at or above
    ``start``, or a child named ``pkg`` of one of them (the layout ``package://`` mesh paths are resolved in)."""
    for d in (start, *start.parents):
        if d.name == pkg:
            return d
        if (d / pkg).is_dir():
            return d / pkg
    raise ParseError(f"$(find {pkg}): no folder named {pkg!r} at or above {start} (the package's folder holds the .xacro "
                     "or lies beside one of its parent folders)")


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


def _read_source(source: str | Path, base_dir: str | Path | None,
                 xacro_args: Mapping[str, str] | None = None) -> tuple[Path | None, str, str, Path]:
    """(path or None, XML text, where-label for messages, folder that relative meshes resolve against)."""
    if isinstance(source, Path) or (isinstance(source, str) and not source.lstrip().startswith("<")):
        path = Path(source).expanduser().resolve()
        return path, read_urdf_text(path, xacro_args), str(path), path.parent
    return None, str(source), "<urdf text>", Path(base_dir) if base_dir is not None else Path.cwd()


def _link_names(root_elem: ET.Element, where: str) -> list[str]:
    links = [l.get("name") for l in root_elem.findall("link")]
    if not links:
        raise ParseError(f"{where}: no <link> elements")
    dup = sorted({n for n in links if links.count(n) > 1})
    if dup:
        raise ParseError(f"{where}: link {dup[0]!r} is defined twice")
    return links  # type: ignore[return-value]


def _joint_limits(je: ET.Element, jtype: str, jw: str) -> tuple[float, float]:
    """(lower, upper) of a joint element: continuous -pi..pi; fixed 0..0; others need <limit>."""
    if jtype == "continuous":
        return -np.pi, np.pi
    if jtype not in MOVABLE_TYPES:
        return 0.0, 0.0
    lim = je.find("limit")
    if lim is None:
        raise ParseError(f"{jw} ({jtype}) has no <limit>")
    lo = float(_floats(lim.get("lower"), 1, 0.0, jw + " lower")[0])
    up = float(_floats(lim.get("upper"), 1, 0.0, jw + " upper")[0])
    if lo > up:
        raise ParseError(f"{jw}: lower limit {lo} > upper limit {up}")
    return lo, up


def _joint_axis(je: ET.Element, jtype: str, jw: str) -> np.ndarray:
    """Unit axis of a joint element (URDF default +x when absent)."""
    ae = je.find("axis")
    if ae is None:
        return np.array([1.0, 0.0, 0.0])
    axis = _floats(ae.get("xyz"), 3, 0.0, jw + " axis")
    if jtype in MOVABLE_TYPES:
        nrm = float(np.linalg.norm(axis))
        if nrm < 1e-12:
            raise ParseError(f"{jw} has a zero axis")
        axis = axis / nrm
    return axis


def _mimic(je: ET.Element, jtype: str, jw: str) -> tuple[str, float, float] | None:
    """(master joint, multiplier, offset) of a ``<mimic>`` tag on a movable joint, else None."""
    me = je.find("mimic")
    if me is None or jtype not in MOVABLE_TYPES:
        return None
    if not me.get("joint"):
        raise ParseError(f"{jw}: <mimic> names no joint")
    mult = float(_floats(me.get("multiplier"), 1, 1.0, jw + " mimic multiplier")[0])
    off = float(_floats(me.get("offset"), 1, 0.0, jw + " mimic offset")[0])
    return me.get("joint"), mult, off  # type: ignore[return-value]


def _joint(je: ET.Element, where: str, link_set: set[str]) -> Joint:
    """One validated ``<joint>`` element."""
    name = je.get("name")
    jtype = je.get("type")
    jw = f"{where}: joint {name!r}"
    if not name:
        raise ParseError(f"{where}: a <joint> has no name")
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
    lo, up = _joint_limits(je, jtype, jw)
    return Joint(name, jtype, parent, child, _origin(je.find("origin"), jw), _joint_axis(je, jtype, jw), lo, up,
                 _mimic(je, jtype, jw))


def _joints(root_elem: ET.Element, where: str, link_set: set[str]) -> dict[str, Joint]:
    """Every joint, checked: unique names, one parent joint per link, known mimic masters, no mimic cycle."""
    joints: dict[str, Joint] = {}
    child_of: dict[str, str] = {}
    for je in root_elem.findall("joint"):
        j = _joint(je, where, link_set)
        if j.name in joints:
            raise ParseError(f"{where}: joint {j.name!r} is defined twice")
        if j.child in child_of:
            raise ParseError(
                f"{where}: kinematic loop: link {j.child!r} is the child of two joints ({child_of[j.child]!r} and {j.name!r})"
            )
        child_of[j.child] = j.name
        joints[j.name] = j
    for j in joints.values():
        seen = [j.name]
        while j.mimic is not None:
            master = joints.get(j.mimic[0])
            if master is None:
                raise ParseError(f"{where}: joint {j.name!r} mimics unknown joint {j.mimic[0]!r}")
            if master.type not in MOVABLE_TYPES:
                raise ParseError(f"{where}: joint {j.name!r} mimics {master.name!r}, which is a {master.type} joint")
            if master.name in seen:
                raise ParseError(f"{where}: mimic cycle {' -> '.join(seen + [master.name])}")
            seen.append(master.name)
            j = master
    return joints


def _root_link(links: list[str], joints: dict[str, Joint], where: str) -> str:
    """The single root link; every link must be reachable from it (else a kinematic loop)."""
    link_set = set(links)
    children_set = {j.child for j in joints.values()}
    roots = [l for l in links if l not in children_set]
    if len(roots) == 0:
        raise ParseError(f"{where}: kinematic loop: every link has a parent joint (no root link)")
    if len(roots) > 1:
        raise ParseError(f"{where}: the URDF has {len(roots)} root links ({', '.join(roots)}); expected one tree")
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
    return roots[0]


def _cut_below(root_elem: ET.Element, root_link: str, where: str) -> None:
    """In place: keep only ``root_link`` and what hangs below it (a hand on an arm: the arm's links,
    joints and transmissions go)."""
    names = [e.get("name") for e in root_elem.findall("link")]
    if root_link not in names:
        near = difflib.get_close_matches(root_link, [n for n in names if n], n=3)
        raise ParseError(f"{where}: root_link {root_link!r} is not a link of the URDF"
                         + (f" (did you mean {', '.join(map(repr, near))}?)" if near else f" ({len(names)} links)"))
    children: dict[str, list[str]] = {}
    for je in root_elem.findall("joint"):
        p, c = je.find("parent"), je.find("child")
        if p is not None and c is not None:
            children.setdefault(p.get("link"), []).append(c.get("link"))
    keep, stack = set(), [root_link]
    while stack:
        x = stack.pop()
        if x not in keep:
            keep.add(x)
            stack.extend(children.get(x, []))
    dropped_joints = set()
    for e in list(root_elem):
        if e.tag == "link" and e.get("name") not in keep:
            root_elem.remove(e)
        elif e.tag == "joint":
            c = e.find("child")
            if c is None or c.get("link") not in keep or c.get("link") == root_link:
                dropped_joints.add(e.get("name"))
                root_elem.remove(e)
    for e in list(root_elem.findall("transmission")):
        if any(j.get("name") in dropped_joints for j in e.iter("joint")):
            root_elem.remove(e)


def load_urdf(source: str | Path, base_dir: str | Path | None = None, root_link: str | None = None,
              xacro_args: Mapping[str, str] | None = None) -> OriginalHand:
    """Load and validate an original hand URDF (path, or XML text with ``base_dir`` for meshes).

    ``root_link``: the hand's own root in a URDF that holds more (a hand on an arm); only that link
    and its subtree are loaded, so link poses are in its frame. ``xacro_args``: ``<xacro:arg>`` values of a
    ``.xacro`` file (:func:`read_urdf_text`).

    Raises:
        ParseError: the text is not a valid single-tree ``<robot>`` (message names file and element),
            or ``root_link`` is not one of its links.
    """
    path, text, where, urdf_dir = _read_source(source, base_dir, xacro_args)
    try:
        root_elem = ET.fromstring(text)
    except ET.ParseError as exc:
        raise ParseError(f"{where}: not valid XML ({exc})") from None
    if root_elem.tag != "robot":
        raise ParseError(f"{where}: root element is <{root_elem.tag}>, expected <robot>")
    if root_link is not None:
        _cut_below(root_elem, root_link, where)
    links = _link_names(root_elem, where)
    joints = _joints(root_elem, where, set(links))
    root = _root_link(links, joints, where)
    geoms, missing = _collect_geometry(root_elem, urdf_dir, where)
    return OriginalHand(
        path=path,
        urdf_text=ET.tostring(root_elem, encoding="unicode"),
        root=root,
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
    gone: list[str] = []
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
                        missing.append(str(p))
                        gone.append(f"{p.name} (link {lname!r} {tag})")
                        le.remove(ge)
                        continue
                    shape.set("filename", str(p))  # absolute: the cleaned text loads from anywhere
                    scale = tuple(_floats(shape.get("scale"), 3, 1.0, gw + " mesh scale"))
                    geoms.append(Geometry(lname, tag, "mesh", T, (), str(p), scale))  # type: ignore[arg-type]
    if gone:  # one warning per URDF, not one per link (a hand without its visual meshes gave 13 lines per run)
        folder = Path(missing[0]).parent
        shown = ", ".join(gone[:4]) + (f" and {len(gone) - 4} more" if len(gone) > 4 else "")
        warnings.warn(f"{where}: {len(gone)} mesh file(s) not found (in {folder}): {shown}; geometry skipped",
                      MissingMeshWarning, stacklevel=user_stacklevel())
    return geoms, missing


__all__ = ["OriginalHand", "Joint", "Geometry", "MissingMeshWarning", "find_package", "load_urdf", "read_urdf_text", "resolve_mesh_path"]
