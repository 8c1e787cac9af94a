"""What the simulator needs to know about a hand: URDF text, joint map, palm transform, fingers.

:class:`SimHand` describes either a canonical hand (from params) or an original hand URDF driven
through its :class:`ohra.ActionMap`; the evaluator treats both alike. Grasps are always canonical
``[t, rot6d, q22]``: the palm pose is mapped to the URDF root with the palm origin, and the 22
canonical joints to the URDF's movable joints with the action map.

The URDF is prepared for speed without changing the hand: joints the grasp never moves (absent
canonical joints, unmapped original joints, immovable ones) become fixed joints at their locked
value ("inactive joints locked", exactly), so that links joined by fixed joints can be merged like
Isaac Gym's ``collapse_fixed_joints``; a canonical capsule link's cylinder + two end spheres become
one native ``<capsule>`` (the same solid); relative mesh paths become absolute.
"""

from __future__ import annotations

import hashlib

import xml.etree.ElementTree as ET
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ohra.errors import GraspError
from ohra.canonical.params import FINGERS, FINGER_SLICES, JOINT_NAMES, BaseParams, ExtendedParams, Params
from ohra.transforms import matrix_to_rpy, xyzrpy_to_matrix

MOVABLE = ("revolute", "continuous", "prismatic")


def _finger_of_slot(k: int) -> int:
    for f, name in enumerate(FINGERS):
        s = FINGER_SLICES[name]
        if s.start <= k < s.stop:
            return f
    raise IndexError(k)


# which squeeze directions an original hand's evaluation used (part of the caches' keys): its canonical twin's,
# mapped through the action map (stop 53); before, the original's own joint frames decided
ORIGINAL_SQUEEZE = "canonical-twin"


@dataclass
class SimHand:
    """A hand as the simulator loads it.

    Attributes:
        name: label for reports.
        urdf: prepared URDF text (see module doc).
        joints: names of the URDF joints the grasp drives, in the order of the simulator vector.
        lower, upper: their limits (radians / metres).
        canon_lower, canon_upper: (22,) canonical limits; grasps outside them are clamped.
        T_palm_root: (4,4) the URDF root link frame in the canonical palm frame.
        joint_finger: finger index (0..4) of each driven joint.
        link_finger: URDF link name -> finger index, -1 for the palm and other non-finger links.
        mimic: joint name -> (driven joint name, multiplier, offset) for URDF mimic joints.
        couplings: a canonical hand's joint couplings (:mod:`ohra.canonical.couplings`): the
            controller projects its poses and targets onto them (:meth:`project_sim`).
        squeeze_reference: an original hand's canonical twin (same params and form). The squeeze
            controller decides which way each joint closes on the twin and maps it through the action
            map's signs (:meth:`squeeze_map`): the reference rule reads a link's direction off its frame's
            +z, true of canonical links but not of many original URDFs' (Allegro's thumb joint 13, LEAP,
            DexHand's thumb), whose fingers then squeezed open. None: the hand's own frames decide.
    """

    name: str
    urdf: str
    joints: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    canon_lower: np.ndarray
    canon_upper: np.ndarray
    drive: np.ndarray  # indices of the driven joints in the canonical (22) or original joint vector
    base: np.ndarray  # canonical (22) or original full vector holding the locked values
    action_map: object | None  # None for a canonical hand
    T_palm_root: np.ndarray
    joint_finger: np.ndarray
    link_finger: dict[str, int]
    mimic: dict[str, tuple[str, float, float]] = field(default_factory=dict)
    couplings: tuple = ()
    squeeze_reference: "SimHand | None" = None

    def __post_init__(self) -> None:
        # a hand without one driven joint would fail deep in PyBullet calls on empty joint lists
        if len(self.joints) == 0:
            raise GraspError(f"hand {self.name!r} has no movable joint (none is driven, or every upper limit is at "
                             "or below its lower one): simulating a grasp or an in-hand rotation needs at least one")

    @property
    def coupled(self) -> bool:
        """A canonical hand with couplings (an original hand couples through its URDF mimic tags)."""
        return self.action_map is None and bool(self.couplings)

    def project_sim(self, qs: np.ndarray) -> np.ndarray:
        """Simulator vector (..., len(joints)) with coupled joints set from their drivers, clipped into
        the limits; unchanged for a hand without canonical couplings."""
        if not self.coupled:
            return np.asarray(qs, dtype=float)
        from ohra.canonical.couplings import project

        return np.clip(self.to_sim(project(self.couplings, self.to_canonical(qs))), self.lower, self.upper)

    @property
    def canonical(self) -> bool:
        return self.action_map is None

    def squeeze_map(self) -> tuple[np.ndarray, np.ndarray]:
        """(index into ``squeeze_reference.joints``, whether the sign flips) for each driven joint: a joint closes
        toward its positive side when its canonical slot does on the twin, unless its slot's sign is negative."""
        ref = self.squeeze_reference
        if ref is None or self.action_map is None:
            raise GraspError(f"hand {self.name!r} has no canonical twin to take its squeeze directions from")
        slot = {sm.name: (s, sm.sign) for s, sm in self.action_map.slots.items()}
        idx = np.array([ref.joints.index(slot[j][0]) for j in self.joints], dtype=int)
        flip = np.array([slot[j][1] < 0 for j in self.joints], dtype=bool)
        return idx, flip

    def to_sim(self, q: np.ndarray) -> np.ndarray:
        """Canonical (..., 22) -> simulator vector (..., len(joints))."""
        q = np.asarray(q, dtype=float)
        full = q if self.action_map is None else self.action_map.to_original(q)
        return full[..., self.drive]

    def to_canonical(self, qs: np.ndarray) -> np.ndarray:
        """Simulator vector (..., len(joints)) -> canonical (..., 22)."""
        full = np.broadcast_to(self.base, np.shape(qs)[:-1] + self.base.shape).copy()
        full[..., self.drive] = qs
        return full if self.action_map is None else self.action_map.to_canonical(full)

    # -- constructors ---------------------------------------------------------------------------
    @classmethod
    def from_params(cls, params: Params, name: str | None = None, couplings: tuple = ()) -> "SimHand":
        """A canonical hand: the driven joints are its movable canonical joints; ``couplings`` (the
        hand's, e.g. ``ohra.get_couplings(name)``) make the controller drive coupled joints with
        their drivers. Without a ``name`` the hand is named by its content (``canonical_<hash>``, the first
        8 hex digits of its params JSON's SHA-256), so reports of two unnamed hands are told apart."""
        from ohra.canonical.urdfgen import render

        if not isinstance(params, (BaseParams, ExtendedParams)):
            from ohra.errors import ParamsError

            hint = (f" (a hand name: SimHand.from_params(ohra.get_hand({str(params)!r}), name={str(params)!r}, "
                    f"couplings=ohra.get_couplings({str(params)!r})))") if isinstance(params, (str, Path)) else ""
            raise ParamsError(f"SimHand.from_params: expected BaseParams or ExtendedParams, got {type(params).__name__}{hint}")
        if name is None:
            name = "canonical_" + hashlib.sha256(params.to_json().encode()).hexdigest()[:8]
        lo, up = np.asarray(params.joint_lowers, dtype=float), np.asarray(params.joint_uppers, dtype=float)
        movable = up > lo
        locked = {n: float(lo[k]) for k, n in enumerate(JOINT_NAMES) if not movable[k]}
        urdf = prepare_urdf(render(params), locked, capsules=True)
        idx = np.flatnonzero(movable)
        joints = tuple(JOINT_NAMES[k] for k in idx)
        base = np.where(movable, 0.0, lo)
        link_finger = _link_fingers(urdf, {n: _finger_of_slot(JOINT_NAMES.index(n)) for n in JOINT_NAMES})
        return cls(name, urdf, joints, lo[idx], up[idx], lo, up, idx, base, None, np.eye(4),
                   np.array([_finger_of_slot(k) for k in idx], dtype=int), link_finger, {}, tuple(couplings))

    @property
    def finger_masses(self) -> np.ndarray:
        """(5,) total mass [kg] of each finger's links (thumb, index, middle, ring, little; 0 when absent),
        from the ``<inertial>`` of every link a finger's joints move (mimic-driven links included)."""
        return finger_masses(self.urdf, self.link_finger)

    def with_finger_masses(self, masses: np.ndarray) -> "SimHand":
        """This canonical hand with each finger's inertials scaled to the given total mass [kg].

        The canonical template weighs its capsules at 1000 kg/m^3 (the reference's choice), which makes
        fingers of most registered hands 1.4-16x lighter than their URDFs' links; under a force-limited position drive
        the finger mass changes how a grasp resists the perturbations (README, Table 4 analogue). Mass,
        centre of mass and inertia stay one consistent body: every link of finger ``f`` is scaled by
        ``masses[f] / current[f]`` (its shape, and the mass distribution along the finger, unchanged).
        Fingers whose target is 0 (absent on the original) keep their capsule mass.
        """
        if not self.canonical:
            raise GraspError(f"with_finger_masses applies to canonical hands; {self.name!r} is an original URDF")
        m = np.asarray(masses, dtype=float).reshape(-1)
        if m.shape != (5,) or not np.all(np.isfinite(m)) or np.any(m < 0):
            raise GraspError(f"finger masses: expected 5 finite non-negative values in kg, got {np.asarray(masses).tolist()!r}")
        return replace(self, urdf=scale_finger_inertials(self.urdf, self.link_finger, m))

    @classmethod
    def from_original(cls, urdf: str | Path, action_map, name: str | None = None,
                      canon_limits: tuple[np.ndarray, np.ndarray] | None = None, params: Params | None = None) -> "SimHand":
        """An original hand URDF (path, or text with absolute mesh paths) driven through ``action_map``.

        ``canon_limits`` defaults to the original limits mapped to canonical slots
        (``action_map.limits_to_canonical``). Unmapped original joints are locked at the action
        map's value for them (0 unless ``unmapped_default`` says otherwise). ``params``: the hand's canonical
        params (the form ``action_map`` maps to), whose canonical twin then sets the squeeze directions
        (``squeeze_reference``); without them the URDF's own link frames do.
        """
        path = None
        if isinstance(urdf, Path) or not str(urdf).lstrip().startswith("<"):
            path = Path(urdf)
            if not path.is_file():
                raise GraspError(f"original hand URDF not found: {path}")
            text = path.read_text()
        else:
            text = str(urdf)
        root = ET.fromstring(text)
        info = {j.get("name"): j for j in root.iter("joint")}
        mimic: dict[str, tuple[str, float, float]] = {}
        for n, j in info.items():
            m = j.find("mimic")
            if m is not None and j.get("type") in MOVABLE:
                mimic[n] = (m.get("joint"), float(m.get("multiplier", 1.0)), float(m.get("offset", 0.0)))
        orig = tuple(action_map.original_joints)
        missing = [n for n in orig if n not in info]
        if missing:
            raise GraspError(f"action map names joints {missing} that the URDF does not have")
        lim = np.array([_limits(info[n]) for n in orig]).reshape(-1, 2)
        mapped = action_map.mapped_original
        probe = action_map.to_original(np.zeros(22))  # unmapped joints' locked values
        locked = {n: float(probe[i]) for i, n in enumerate(orig) if not mapped[i] or lim[i, 1] <= lim[i, 0]}
        drive = [i for i, n in enumerate(orig) if n not in locked]
        joints = tuple(orig[i] for i in drive)
        mimic = {n: m for n, m in mimic.items() if m[0] in joints}
        locked.update({n: 0.0 for n, j in info.items() if j.get("type") in MOVABLE and n not in orig and n not in mimic})
        prepared = prepare_urdf(text, locked, capsules=True, base_dir=path.parent if path else None)
        lo_c, up_c = canon_limits if canon_limits is not None else action_map.limits_to_canonical(lim[:, 0], lim[:, 1])
        drive_a = np.array(drive, dtype=int)
        slot_of = {sm.name: k for k, sm in ((JOINT_NAMES.index(s), sm) for s, sm in action_map.slots.items())}
        joint_finger = np.array([_finger_of_slot(slot_of[orig[i]]) for i in drive_a], dtype=int)

        finger_of_joint = {orig[i]: f for i, f in zip(drive_a, joint_finger)}
        finger_of_joint.update({n: finger_of_joint[m[0]] for n, m in mimic.items()})
        link_finger = _link_fingers(prepared, finger_of_joint)
        T = np.linalg.inv(xyzrpy_to_matrix(action_map.palm_origin))  # root in palm: inverse of palm in root
        label = name or (path.stem if path else "original_hand")
        twin = None if params is None else cls.from_params(params, name=label.replace(":original", "") + ":canonical",
                                                          couplings=tuple(getattr(action_map, "couplings", ()) or ()))
        return cls(label, prepared, joints, lim[drive_a, 0], lim[drive_a, 1],
                   np.asarray(lo_c, float), np.asarray(up_c, float), drive_a, probe, action_map, T, joint_finger,
                   link_finger, mimic, squeeze_reference=twin)

    @classmethod
    def registered_original(cls, name: str, form: str | None = None) -> "SimHand":
        """The original hand of a registered hand (needs the hand assets and the registry)."""
        from ohra.hands import get_hand
        from ohra.hands import registry

        sp = registry.spec(name)
        oh = registry.load_original(name)
        params = get_hand(name, form)
        am = sp.action_map(params.form, oh)  # the OriginalHand: its mimic couplings come along
        return cls._original_of(oh, am, params, name)

    @classmethod
    def original_of(cls, hand: str, form: str | None = None, purpose: str = "--original") -> "SimHand":
        """The original URDF of any hand with a known original: a registered name (:meth:`registered_original`), a
        spec YAML, or a params JSON with its spec; driven through the action map of the form it resolves to.
        ``purpose`` starts the error messages (what needed the original).

        Raises:
            HandNotFoundError: a LEAP variant (a canonical hand only) or a params JSON without its spec.
        """
        from ohra.errors import HandNotFoundError
        from ohra.hands.registry import registered_hands
        from ohra.hands.resolve import resolve_hand

        if hand in registered_hands():
            return cls.registered_original(hand, form)
        ref = resolve_hand(hand, form)
        if ref.kind == "variant":
            raise HandNotFoundError(f"{purpose}: {hand} is a LEAP variant, a canonical hand with no original URDF")
        ref.require_spec(purpose)  # a params JSON without its spec: names what to pass
        return cls._original_of(ref.original(), ref.action_map(), ref.params, ref.name)

    @classmethod
    def _original_of(cls, oh, action_map, params: Params, name: str) -> "SimHand":
        lo = np.asarray(params.joint_lowers, float)
        up = np.asarray(params.joint_uppers, float)
        return cls.from_original(_absolute_text(oh), action_map, name=f"{name}:original", canon_limits=(lo, up), params=params)


def _absolute_text(oh) -> str:
    """The cleaned URDF text of an :class:`ohra.original.urdf.OriginalHand` with absolute mesh paths."""
    from ohra.original.urdf import resolve_mesh_path

    root = ET.fromstring(oh.urdf_text)
    base = oh.path.parent if oh.path is not None else Path.cwd()
    for m in root.iter("mesh"):
        m.set("filename", str(resolve_mesh_path(m.get("filename", ""), base)))
    return ET.tostring(root, encoding="unicode")


def _limits(j: ET.Element) -> tuple[float, float]:
    if j.get("type") == "continuous":
        return (-np.pi, np.pi)
    lim = j.find("limit")
    if lim is None:
        return (0.0, 0.0)
    return (float(lim.get("lower", 0.0)), float(lim.get("upper", 0.0)))


def original_finger_masses(name: str, form: str | None = None) -> np.ndarray:
    """(5,) finger masses [kg] of the original URDF of ``name`` (a registered hand, a spec YAML or a
    params JSON beside its spec: :meth:`SimHand.original_of`); one clear error for a hand without one."""
    return SimHand.original_of(name, form=form, purpose="original finger masses (--inertials original)").finger_masses


def _link_mass(link: ET.Element) -> float:
    m = link.find("inertial/mass")
    return float(m.get("value", 0.0)) if m is not None else 0.0


def finger_masses(urdf: str, link_finger: dict[str, int]) -> np.ndarray:
    """(5,) summed ``<inertial>`` mass [kg] of the links of each finger (``link_finger``: link -> 0..4, -1 palm)."""
    out = np.zeros(5)
    for link in ET.fromstring(urdf).iter("link"):
        f = link_finger.get(link.get("name"), -1)
        if f >= 0:
            out[f] += _link_mass(link)
    return out


def scale_finger_inertials(urdf: str, link_finger: dict[str, int], masses: np.ndarray) -> str:
    """URDF text with the inertials of each finger's links scaled so the finger weighs ``masses[f]`` kg."""
    root = ET.fromstring(urdf)
    current = finger_masses(urdf, link_finger)
    k = np.where((current > 0) & (np.asarray(masses) > 0), np.asarray(masses) / np.maximum(current, 1e-300), 1.0)
    for link in root.iter("link"):
        f = link_finger.get(link.get("name"), -1)
        inertial = link.find("inertial")
        if f < 0 or inertial is None or k[f] == 1.0:
            continue
        m = inertial.find("mass")
        if m is not None:
            m.set("value", repr(float(float(m.get("value", 0.0)) * k[f])))
        I = inertial.find("inertia")
        if I is not None:
            for a in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz"):
                if I.get(a) is not None:
                    I.set(a, repr(float(float(I.get(a)) * k[f])))
    return ET.tostring(root, encoding="unicode")


def _link_fingers(urdf: str, finger_of_joint: dict[str, int]) -> dict[str, int]:
    """Finger of every link: that of the nearest driven-joint ancestor (-1 when none: the palm)."""
    root = ET.fromstring(urdf)
    parent_joint = {j.find("child").get("link"): j for j in root.iter("joint")}
    out: dict[str, int] = {}
    for link in root.iter("link"):
        n, f = link.get("name"), -1
        cur = n
        while cur in parent_joint:
            j = parent_joint[cur]
            if j.get("name") in finger_of_joint and j.get("type") in MOVABLE:
                f = finger_of_joint[j.get("name")]
                break
            cur = j.find("parent").get("link")
        out[n] = f
    return out


def _axis_rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    a = axis / np.linalg.norm(axis)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def prepare_urdf(text: str, locked: dict[str, float], capsules: bool = True, base_dir: Path | None = None) -> str:
    """URDF text with ``locked`` joints made fixed at their value, capsule triples as ``<capsule>``."""
    root = ET.fromstring(text)
    for j in root.iter("joint"):
        n = j.get("name")
        if n not in locked or j.get("type") not in MOVABLE:
            continue
        o = j.find("origin")
        xyz = np.array([float(x) for x in (o.get("xyz", "0 0 0") if o is not None else "0 0 0").split()])
        rpy = np.array([float(x) for x in (o.get("rpy", "0 0 0") if o is not None else "0 0 0").split()])
        ax_el = j.find("axis")
        axis = np.array([float(x) for x in (ax_el.get("xyz") if ax_el is not None else "1 0 0").split()])
        T = xyzrpy_to_matrix(np.concatenate([xyz, rpy]))
        v = float(locked[n])
        if j.get("type") == "prismatic":
            T[:3, 3] += T[:3, :3] @ (axis / np.linalg.norm(axis) * v)
        elif v != 0.0:
            T[:3, :3] = T[:3, :3] @ _axis_rotation(axis, v)
        for tag in ("axis", "limit", "mimic", "dynamics", "safety_controller", "calibration"):
            for el in j.findall(tag):
                j.remove(el)
        if o is None:
            o = ET.SubElement(j, "origin")
        o.set("xyz", " ".join(repr(float(x)) for x in T[:3, 3]))
        o.set("rpy", " ".join(repr(float(x)) for x in matrix_to_rpy(T[:3, :3])))
        j.set("type", "fixed")
    for link in root.iter("link"):
        _give_inertial(link)
    if capsules:
        for link in root.iter("link"):
            _capsulise(link)
    if base_dir is not None:
        from ohra.original.urdf import resolve_mesh_path

        for m in root.iter("mesh"):
            m.set("filename", str(resolve_mesh_path(m.get("filename", ""), base_dir)))
    from ohra.sim.bullet import BULLET_MESH_SUFFIXES, bullet_mesh

    for m in root.iter("mesh"):
        name = m.get("filename", "")
        if Path(name).is_absolute() and Path(name).suffix.lower() not in BULLET_MESH_SUFFIXES:
            m.set("filename", str(bullet_mesh(name)))
    return ET.tostring(root, encoding="unicode")


def _give_inertial(link: ET.Element) -> None:
    """A small explicit inertial on a link that has none (every link but the root).

    PyBullet gives a link without ``<inertial>`` a mass of 1 kg and unit inertia; on an original URDF's
    fingertip frames (Inspire's ``*_tip`` links, fixed to the distal link) that made every distal link
    weigh 1 kg with 1 kg m^2 of inertia, which the 1 N m finger motors cannot squeeze with. The
    canonical template's dummy links carry the same values (:data:`ohra.canonical.urdfgen.DUMMY_MASS`).
    """
    from ohra.canonical.urdfgen import DUMMY_INERTIA, DUMMY_MASS

    if link.find("inertial") is not None:
        return
    inertial = ET.Element("inertial")
    ET.SubElement(inertial, "origin", xyz="0 0 0", rpy="0 0 0")
    ET.SubElement(inertial, "mass", value=repr(DUMMY_MASS))
    ET.SubElement(inertial, "inertia", ixx=repr(DUMMY_INERTIA), ixy="0", ixz="0", iyy=repr(DUMMY_INERTIA), iyz="0", izz=repr(DUMMY_INERTIA))
    link.insert(0, inertial)


def _capsulise(link: ET.Element) -> None:
    """Replace a cylinder(length l, radius r) + spheres(r) at its two ends by one capsule (same solid)."""
    cols = link.findall("collision")
    if len(cols) != 3:
        return
    geos = [c.find("geometry") for c in cols]
    kinds = [g[0].tag if g is not None and len(g) else "" for g in geos]
    if sorted(kinds) != ["cylinder", "sphere", "sphere"]:
        return
    ci = kinds.index("cylinder")
    cyl = geos[ci][0]
    r, length = float(cyl.get("radius")), float(cyl.get("length"))

    def origin(c: ET.Element) -> np.ndarray:
        o = c.find("origin")
        xyz = [float(x) for x in (o.get("xyz", "0 0 0") if o is not None else "0 0 0").split()]
        rpy = [float(x) for x in (o.get("rpy", "0 0 0") if o is not None else "0 0 0").split()]
        return xyzrpy_to_matrix(np.array(xyz + rpy))

    Tc = origin(cols[ci])
    rel = sorted((np.linalg.inv(Tc) @ origin(cols[k]))[:3, 3].tolist() for k in range(3) if k != ci)
    radii = [float(geos[k][0].get("radius")) for k in range(3) if k != ci]
    expected = [[0.0, 0.0, -length / 2], [0.0, 0.0, length / 2]]
    if not (np.allclose(radii, r) and np.allclose(rel, expected, atol=1e-9)):
        return
    for k in range(3):
        if k != ci:
            link.remove(cols[k])
    g = geos[ci]
    g.remove(cyl)
    ET.SubElement(g, "capsule", radius=repr(r), length=repr(length))
