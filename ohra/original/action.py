"""The unified action space: original hand joint vectors <-> the canonical 22-D vector.

Each canonical slot is driven by at most one original joint, named (never indexed by tree
traversal), with ``q_canon = sign * q_orig + offset``. Slots with no original joint hold a fixed
value (0 by default; e.g. a joint frozen at a tilt). Original joints that drive no slot (a wrist, a
twist joint the form cannot express) are set to 0 when mapping back, the reference's choice; pass
``unmapped_default`` to choose other values.

The original joint order is the order of the movable (revolute, continuous, prismatic) joints as
they appear in the original URDF file, mimic joints excluded.

Couplings (:mod:`ohra.canonical.couplings`, ``slot = multiplier * driver + offset``) are applied
both ways: original -> canonical fills every coupled slot from its driver; canonical -> original
reads only the driving slots (a coupled slot mapped to an actuated original joint gets the value
the coupling gives). A slot may map a joint outside the original joint vector (a ``<mimic>``
joint, moved by the URDF itself) only when it is coupled. :meth:`ActionMap.residual` reports how
far a canonical vector violates the couplings and :meth:`ActionMap.project` enforces them.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from ohra.canonical import couplings as cpl
from ohra.canonical.couplings import Coupling
from ohra.canonical.params import JOINT_INDEX, JOINT_NAMES
from ohra.errors import MappingError, ParamsError
from ohra.transforms import invert, xyzrpy_to_matrix

MOVABLE_TYPES = ("revolute", "continuous", "prismatic")


def _numbers(x, what: str) -> np.ndarray:
    """``x`` as a float array; a :class:`MappingError` naming ``what`` when it is not numbers."""
    if isinstance(x, (str, bytes)):
        raise MappingError(f"{what} must be numbers, got the string {x!r:.60}")
    try:
        return np.asarray(x, dtype=float)
    except (TypeError, ValueError):
        raise MappingError(f"{what} must be numbers, got {type(x).__name__} {x!r:.60}") from None


def _poses(T, what: str) -> np.ndarray:
    """``T`` as homogeneous pose(s), shape (4, 4) or (..., 4, 4), all finite."""
    T = _numbers(T, what)
    if T.ndim < 2 or T.shape[-2:] != (4, 4):
        raise MappingError(f"{what} must be a 4x4 homogeneous transform or a stack of them (..., 4, 4), got shape {T.shape}")
    if not np.all(np.isfinite(T)):
        raise MappingError(f"{what} holds non-finite values")
    return T


@dataclass(frozen=True)
class SlotMap:
    """One canonical slot driven by the original joint ``name``: ``q_canon = sign * q_orig + offset``."""

    name: str
    sign: float = 1.0
    offset: float = 0.0

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise MappingError(f"SlotMap: the original joint's name must be a non-empty string, got {self.name!r}")
        if self.sign not in (1.0, -1.0, 1, -1):
            raise MappingError(f"sign of original joint {self.name!r} must be +1 or -1, got {self.sign}")

    @classmethod
    def from_mapping(cls, d: Mapping) -> "SlotMap":
        """From ``{"joint" (as in a spec YAML) or "name": ..., "sign": ..., "offset": ...}``; other keys are a
        :class:`MappingError` naming them."""
        d = dict(d)
        if "joint" in d and "name" in d:
            raise MappingError(f"slot mapping {d}: give the original joint as 'joint' or 'name', not both")
        if "joint" in d:
            d["name"] = d.pop("joint")
        unknown = sorted(set(d) - {"name", "sign", "offset"})
        if unknown or "name" not in d:
            raise MappingError(f"slot mapping {d}: expected keys 'joint' (or 'name'), 'sign', 'offset'"
                               + (f"; unknown: {', '.join(map(str, unknown))}" if unknown else "; 'joint' is missing"))
        return cls(**d)


Mimic = Mapping[str, tuple[str, float, float]]  # mimic joint -> (actuated root joint, multiplier, offset)


def mimic_relations(slots: Mapping[str, Any], hand: Any) -> dict[str, tuple[str, float, float]]:
    """``{mimic joint: (actuated root, a, b)}`` (``q_J = a q_root + b``, chains composed) for the
    mapped joints of ``slots`` that are ``<mimic>`` joints of ``hand`` (an OriginalHand)."""
    names = {(sm.name if isinstance(sm, SlotMap) else SlotMap.from_mapping(sm).name if isinstance(sm, Mapping) else str(sm)) for sm in slots.values()}
    return {j: hand.mimic_root(j) for j in hand.mimic_joints if j in names}


def _linear(slots: Mapping[str, SlotMap], original_joints: Sequence[str], mimic: Mimic) -> dict[str, tuple[str, float, float]]:
    """Slot -> (actuated joint, alpha, beta) with ``q_slot = alpha * q_joint + beta`` (direct or via a mimic)."""
    out = {}
    for slot, sm in slots.items():
        if sm.name in original_joints:
            out[slot] = (sm.name, float(sm.sign), float(sm.offset))
        elif sm.name in mimic:
            root, a, b = mimic[sm.name]
            if root not in original_joints:
                raise MappingError(f"slot {slot!r} maps mimic joint {sm.name!r}, whose driver {root!r} is not an actuated joint")
            if a == 0.0:
                raise MappingError(f"slot {slot!r} maps mimic joint {sm.name!r} with multiplier 0 (a fixed joint): fix it instead")
            out[slot] = (root, sm.sign * a, sm.sign * b + sm.offset)
    return out


def mimic_couplings(slots: Mapping[str, SlotMap], mimic: Mimic | Any) -> tuple[Coupling, ...]:
    """Canonical couplings of the slots that map ``<mimic>`` joints (``mimic``: :func:`mimic_relations`
    or an OriginalHand), chains of mimics composed.

    Slots whose joints move with the same actuated joint R are coupled to one driver: the slot
    mapping R itself, else (R drives no slot: a proxy) the first of them in canonical order. With
    ``q_slot = alpha q_R + beta`` per slot: ``q_j = (alpha_j / alpha_d) q_d + beta_j - alpha_j beta_d / alpha_d``.
    """
    if hasattr(mimic, "mimic_root"):
        mimic = mimic_relations(slots, mimic)
    roots = {r for r, _, _ in mimic.values()}
    lin = _linear(slots, [*roots, *(sm.name for sm in slots.values() if sm.name not in mimic)], mimic)
    out = []
    for root in sorted(roots):
        group = [s for s in JOINT_NAMES if s in lin and lin[s][0] == root]
        direct = [s for s in group if slots[s].name == root]
        d = direct[0] if direct else group[0]
        _, ad, bd = lin[d]
        for s in group:
            if s == d or slots[s].name not in mimic:
                continue
            _, aj, bj = lin[s]
            src = f"urdf mimic {slots[s].name} -> {root}" + ("" if direct else f" (slot {d} drives {root})")
            out.append(Coupling(s, d, aj / ad, bj - aj * bd / ad, src))
    return tuple(out)


def original_joint_names(urdf: str | Path) -> list[str]:
    """Movable joint names of a URDF (path or XML text) in file order."""
    text = _read(urdf)
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise MappingError(f"original URDF is not valid XML: {exc}") from None
    names = []
    for j in root.iter("joint"):
        if j.get("type") in MOVABLE_TYPES:
            if j.find("mimic") is not None:
                continue  # mimic joints follow another joint and are not part of the action space
            names.append(j.get("name"))
    return names


def _read(urdf: str | Path) -> str:
    if isinstance(urdf, Path) or (isinstance(urdf, str) and not urdf.lstrip().startswith("<")):
        p = Path(urdf)
        if not p.is_file():
            raise MappingError(f"original URDF not found: {p}")
        return p.read_text()
    return str(urdf)


@dataclass
class ActionMap:
    """Maps joint vectors between an original hand and its canonical hand.

    Args:
        slots: canonical joint name -> :class:`SlotMap` (or a dict with name/sign/offset).
        original_joints: the original hand's joint names, in the order of its joint vectors.
        palm_origin: ``[x, y, z, roll, pitch, yaw]`` of the canonical palm frame in the original
            root frame (metres, fixed-axis radians); ``T_canonical = T_original_root @ T(palm_origin)``.
        fixed: canonical joint name -> constant value for slots no original joint drives.
        unmapped_default: original joint name -> value used by :meth:`to_original` for joints that
            drive no slot (default 0).
        couplings: declared canonical couplings (:class:`ohra.canonical.couplings.Coupling`);
            chains are resolved to their root driver.
        mimic: mimic joint -> (actuated root, multiplier, offset) for slots that map ``<mimic>``
            joints (:func:`mimic_relations`); their couplings are added (:func:`mimic_couplings`).
    """

    slots: Mapping[str, SlotMap]
    original_joints: Sequence[str]
    palm_origin: Sequence[float] = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    fixed: Mapping[str, float] = field(default_factory=dict)
    unmapped_default: Mapping[str, float] = field(default_factory=dict)
    couplings: Sequence[Coupling] = ()
    mimic: Mimic = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.slots, Mapping):
            raise MappingError(f"slots must be a mapping of canonical slot -> original joint (a name, a SlotMap or "
                               f"{{joint, sign, offset}}), got {type(self.slots).__name__} {self.slots!r:.60}")
        joints = self.original_joints
        if not isinstance(joints, (str, bytes)):
            try:
                joints = tuple(joints)  # once: a generator is read here, not emptied by the check
            except TypeError:
                raise MappingError(f"original_joints must be a sequence of joint names, got {joints!r:.80}") from None
        if isinstance(joints, (str, bytes)) or not all(isinstance(j, str) for j in joints):
            raise MappingError(f"original_joints must be a sequence of joint names, got {joints!r:.80}")
        self.original_joints = joints
        if len(set(self.original_joints)) != len(self.original_joints):
            dup = [n for n in self.original_joints if self.original_joints.count(n) > 1][0]
            raise MappingError(f"original joint {dup!r} appears twice in the original joint order")
        self.mimic = dict(self.mimic)
        raw = {k: (SlotMap.from_mapping(v) if isinstance(v, Mapping) else SlotMap(v) if isinstance(v, str) else v) for k, v in dict(self.slots).items()}
        try:
            self.couplings = cpl.resolve(list(self.couplings) + list(mimic_couplings(
                {k: v for k, v in raw.items() if k in JOINT_INDEX}, self.mimic)))
        except ParamsError as exc:
            raise MappingError(str(exc)) from None
        self.slots = slots = self._checked_slots()
        self._check_couplings()
        for slot in self.fixed:
            if slot not in JOINT_INDEX:
                raise MappingError(f"unknown canonical slot {slot!r} in fixed values")
            if slot in slots:
                raise MappingError(f"slot {slot!r} is both mapped and fixed")
        for name in self.unmapped_default:
            if name not in self.original_joints:
                raise MappingError(f"unmapped default names unknown original joint {name!r}")
        po = np.asarray(self.palm_origin, dtype=float)
        if po.shape != (6,) or not np.all(np.isfinite(po)):
            raise MappingError(f"palm_origin must be 6 finite numbers (xyz rpy), got {list(np.ravel(po))}")
        self.palm_origin = po
        n = len(self.original_joints)
        self._passive = {s: sm for s, sm in slots.items() if sm.name not in self.original_joints}
        lin = _linear(slots, self.original_joints, self.mimic)
        self._c_idx = np.array([JOINT_INDEX[s] for s in lin], dtype=int)
        self._o_idx = np.array([self.original_joints.index(j) for j, _, _ in lin.values()], dtype=int)
        self._alpha = np.array([a for _, a, _ in lin.values()])
        self._beta = np.array([b for _, _, b in lin.values()])
        # writers of the original vector: slots mapping a joint of it, else a free slot moving it through a mimic
        coupled = {c.slot for c in self.couplings}
        direct = [s for s in lin if slots[s].name in self.original_joints]
        proxy = [s for s in lin if s not in direct and s not in coupled and lin[s][0] not in {lin[d][0] for d in direct}]
        self._w = np.array([list(lin).index(s) for s in direct + proxy], dtype=int)
        self._canon_const = np.zeros(22)
        for slot, v in self.fixed.items():
            self._canon_const[JOINT_INDEX[slot]] = float(v)
        self._orig_const = np.zeros(n)
        for name, v in self.unmapped_default.items():
            self._orig_const[self.original_joints.index(name)] = float(v)
        self._T_palm = xyzrpy_to_matrix(po)

    def _checked_slots(self) -> dict[str, SlotMap]:
        """Validated slot maps; a joint outside the original vector is allowed for coupled slots only."""
        coupled = {c.slot for c in self.couplings}
        slots: dict[str, SlotMap] = {}
        used: dict[str, str] = {}
        for slot, sm in dict(self.slots).items():
            if slot not in JOINT_INDEX:
                raise MappingError(f"unknown canonical slot {slot!r}; expected one of {', '.join(JOINT_NAMES)}")
            if isinstance(sm, Mapping):
                sm = SlotMap.from_mapping(sm)
            elif isinstance(sm, str):
                sm = SlotMap(sm)
            if sm.name not in self.original_joints and sm.name not in self.mimic and slot not in coupled:
                raise MappingError(
                    f"slot {slot!r} names original joint {sm.name!r}, which is not a movable joint of the original hand "
                    f"(known: {', '.join(self.original_joints)}; a mimic joint is mapped only with its slot's coupling)"
                )
            if sm.name in used:
                raise MappingError(f"original joint {sm.name!r} is mapped twice (slots {used[sm.name]!r} and {slot!r})")
            used[sm.name] = slot
            slots[slot] = sm
        return slots

    def _check_couplings(self) -> None:
        for c in self.couplings:
            for s in (c.slot, c.driver):
                if s not in self.slots:
                    raise MappingError(f"coupling {c.slot} <- {c.driver}: slot {s!r} is not mapped")
        self._A, self._b = cpl.coupling_matrix(self.couplings)

    @classmethod
    def from_urdf(
        cls,
        urdf: str | Path,
        slots: Mapping[str, SlotMap | Mapping | str],
        palm_origin: Sequence[float] = (0.0,) * 6,
        fixed: Mapping[str, float] | None = None,
        unmapped_default: Mapping[str, float] | None = None,
    ) -> "ActionMap":
        """ActionMap whose original joint order is the movable joints of ``urdf`` (path or XML text) by
        name; slots that map ``<mimic>`` joints get their couplings from the URDF."""
        names = original_joint_names(urdf)
        mimic: dict[str, tuple[str, float, float]] = {}
        if "<mimic" in _read(urdf):
            from ohra.original.urdf import load_urdf

            mimic = mimic_relations(slots, load_urdf(urdf))
        return cls(slots, names, palm_origin, dict(fixed or {}), dict(unmapped_default or {}), mimic=mimic)

    @property
    def n_original(self) -> int:
        return len(self.original_joints)

    @property
    def mapped_slots(self) -> np.ndarray:
        """(22,) bool: canonical slots driven by an original joint (mimic joints included)."""
        m = np.zeros(22, dtype=bool)
        m[[JOINT_INDEX[s] for s in self.slots]] = True
        return m

    @property
    def free_slots(self) -> np.ndarray:
        """(22,) bool: slots not coupled to another (the independent canonical coordinates)."""
        return cpl.free_mask(self.couplings)

    @property
    def passive_joints(self) -> dict[str, str]:
        """Slot -> the original joint outside the joint vector (``<mimic>``) that it maps."""
        return {s: sm.name for s, sm in self._passive.items()}

    def passive_values(self, q_canon: np.ndarray) -> dict[str, np.ndarray]:
        """Original values of the passive (mimic) joints from their own slots of ``q_canon`` (22,) or
        (N,22) — not from the coupling — for :meth:`OriginalHand.link_poses`' ``passive``."""
        q = self._check(q_canon, 22, "canonical joint")
        return {sm.name: sm.sign * (q[..., JOINT_INDEX[s]] - sm.offset) for s, sm in self._passive.items()}

    def residual(self, q_canon: np.ndarray) -> np.ndarray:
        """(..., K) coupling residuals ``q[slot] - (a q[driver] + b)`` [rad] of canonical vector(s)."""
        return cpl.residual(self.couplings, self._check(q_canon, 22, "canonical joint"))

    def project(self, q_canon: np.ndarray) -> np.ndarray:
        """Canonical vector(s) with every coupled slot set from its driver (free slots unchanged)."""
        return cpl.project(self.couplings, self._check(q_canon, 22, "canonical joint"))

    @property
    def mapped_original(self) -> np.ndarray:
        """(n_original,) bool: original joints set from a canonical slot (directly or through a mimic)."""
        m = np.zeros(self.n_original, dtype=bool)
        m[self._o_idx[self._w]] = True
        return m

    def _check(self, q: np.ndarray, n: int, what: str) -> np.ndarray:
        q = _numbers(q, f"{what} vector")
        if q.ndim not in (1, 2) or q.shape[-1] != n:
            raise MappingError(f"{what} vector must have shape ({n},) or (N, {n}), got {q.shape}")
        bad = np.argwhere(~np.isfinite(q))
        if len(bad):  # NaN would map to NaN joint targets silently
            raise MappingError(f"{what} vector holds {q[tuple(bad[0])]} at index {tuple(int(i) for i in bad[0])} "
                               f"({len(bad)} non-finite value(s)); joint values must be finite")
        return q

    def to_canonical(self, q_orig: np.ndarray) -> np.ndarray:
        """Original joint vector(s) (n,) or (N,n) -> canonical (22,) or (N,22)."""
        q = self._check(q_orig, self.n_original, "original joint")
        out = np.broadcast_to(self._canon_const, q.shape[:-1] + (22,)).copy()
        out[..., self._c_idx] = self._alpha * q[..., self._o_idx] + self._beta
        return cpl.project(self.couplings, out) if self.couplings else out

    def to_original(self, q_canon: np.ndarray) -> np.ndarray:
        """Canonical vector(s) (22,) or (N,22) -> original (n,) or (N,n); unmapped joints get their default.

        Only driving slots are read: coupled slots are taken from the coupling (see :meth:`residual`).
        """
        q = self._check(q_canon, 22, "canonical joint")
        if self.couplings:
            q = cpl.project(self.couplings, q)
        out = np.broadcast_to(self._orig_const, q.shape[:-1] + (self.n_original,)).copy()
        w = self._w
        out[..., self._o_idx[w]] = (q[..., self._c_idx[w]] - self._beta[w]) / self._alpha[w]
        return out

    def limits_to_canonical(self, lower: np.ndarray, upper: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Canonical (22,) limits from original limits (a negated joint swaps and negates its limits)."""
        lo = self._check(lower, self.n_original, "original lower-limit")
        up = self._check(upper, self.n_original, "original upper-limit")
        a = self._alpha * lo[self._o_idx] + self._beta
        b = self._alpha * up[self._o_idx] + self._beta
        clo, cup = self._canon_const.copy(), self._canon_const.copy()
        clo[self._c_idx] = np.minimum(a, b)
        cup[self._c_idx] = np.maximum(a, b)
        # a coupled slot reaches what its driver's range gives it
        return cpl.propagate_limits(self.couplings, clo, cup) if self.couplings else (clo, cup)

    def wrist_to_canonical(self, T_root: np.ndarray) -> np.ndarray:
        """Pose(s) of the original root frame (…,4,4) -> pose(s) of the canonical palm frame."""
        return _poses(T_root, "wrist_to_canonical: the original root pose") @ self._T_palm

    def wrist_to_original(self, T_palm: np.ndarray) -> np.ndarray:
        """Pose(s) of the canonical palm frame (…,4,4) -> pose(s) of the original root frame."""
        return _poses(T_palm, "wrist_to_original: the canonical palm pose") @ invert(self._T_palm)
