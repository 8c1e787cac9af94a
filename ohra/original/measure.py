"""Measure an original hand in the canonical palm frame at the configuration of canonical zero.

Everything here is read off the original URDF under a :class:`~ohra.original.spec.HandSpec`'s
mapping of one form (no hand names anywhere); :mod:`ohra.original.estimate` turns the result into
parameters. Rules (see also :mod:`ohra.original.parse`):

* joint positions and axes: the child frame of each mapped original joint; the axis is multiplied
  by the slot's sign.
* finger frame: ``z`` points from the first joint after the base to the fingertip, ``y`` is the
  flexion axis (j3, else j4, else j2; thumb: j4, else j5, else j3) made orthogonal to ``z``.
* stations along a finger: base (j1/j2), middle joint (j3 / thumb j3,j4), distal joint (j4 / thumb
  j5) and the fingertip.
* fingertip point (the *true* fingertip): the centroid of the geometry points of every link the
  finger moves beyond its last mapped joint (links fixed to it, links moved by ``<mimic>`` joints or
  unmapped joints, posed at canonical zero) within 1 mm of its farthest extent along the finger
  direction, moved out to that extent, carried rigidly by the link that reaches farthest. Without
  geometry: the distal joint plus the previous segment's length (warned). Links moved by joints
  that drive no slot are noted (the canonical finger cannot follow them).
* canonical zero: mimic joints mapped to a slot are posed from their own slot (0), not from their
  coupling, so a straight canonical finger is measured on the straight original finger; a finger
  that is still bent at canonical zero is noted with the slot offset that would straighten it.
* palm radius: half the mean of the palm geometry's extents in y and z (the disc's plane); without
  palm geometry, from the knuckle spread (warned). Finger radius: half the mean cross-section width
  of each segment link, median over the finger's links.
* geometry: collision elements when the link has any, else visual ones, else nothing.
* limits: the ActionMap's (a negated joint swaps and negates its limits; offsets are added); fixed
  slots get ``[v, v]``.

Frames: every point and axis is in the canonical palm frame (metres), ``T_palm = T_root @
T(palm_origin)``.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np

from ohra.canonical.params import FINGER_SLICES, FINGERS, JOINT_INDEX, JOINT_NAMES
from ohra.errors import ParseError, user_stacklevel
from ohra.original.action import ActionMap
from ohra.original.spec import FormSpec, HandSpec
from ohra.original.urdf import OriginalHand
from ohra.transforms import invert, xyzrpy_to_matrix

TIP_BAND = 1e-3  # m: geometry points this close to the farthest extent form the fingertip

STATION_SLOTS = {
    # finger -> slots defining stations (base, middle joint, distal joint)
    "thumb": (("thumb_joint1", "thumb_joint2"), ("thumb_joint3", "thumb_joint4"), ("thumb_joint5",)),
    "index": (("index_joint1", "index_joint2"), ("index_joint3",), ("index_joint4",)),
    "middle": (("middle_joint1", "middle_joint2"), ("middle_joint3",), ("middle_joint4",)),
    "ring": (("ring_joint1", "ring_joint2"), ("ring_joint3",), ("ring_joint4",)),
    "little": (("little_joint1", "little_joint2"), ("little_joint3",), ("little_joint4",)),
}
FLEX_PREF = {"thumb": ("thumb_joint4", "thumb_joint5", "thumb_joint3")}
for _f in FINGERS[1:]:
    FLEX_PREF[_f] = (f"{_f}_joint3", f"{_f}_joint4", f"{_f}_joint2")


class ParseWarning(UserWarning):
    """Something was estimated instead of measured (the message says what and why)."""


@dataclass
class FingerMeasure:
    """One canonical finger measured on the original hand (palm frame, canonical zero, metres)."""

    slots: list[str]  # mapped canonical slots of this finger, canonical order
    p: dict[str, np.ndarray]  # slot -> joint position (3,)
    a: dict[str, np.ndarray]  # slot -> signed unit axis (3,)
    stations: list[np.ndarray | None]  # base, middle joint, distal joint, tip (None: no joint there)
    z: np.ndarray  # finger direction
    y: np.ndarray  # flexion axis (orthogonal to z)
    tip: np.ndarray
    radius: float | None
    seg_links: list[str]
    distal_links: list[str]
    tip_link: str = ""  # the link that carries the fingertip point


@dataclass
class Measurement:
    """The original hand measured under one form's mapping (palm frame, canonical zero)."""

    hand: OriginalHand
    action_map: ActionMap
    T_palm_root: np.ndarray  # (4,4) root frame -> palm frame
    q0: np.ndarray  # original configuration of canonical zero
    lower: np.ndarray  # (22,) canonical limits [rad]
    upper: np.ndarray
    fingers: dict[str, FingerMeasure]
    palm_link: str
    palm_radius: float
    finger_radius: dict[str, float]
    tip_links: dict[str, list[str]]
    notes: list[str] = field(default_factory=list)
    passive0: dict[str, np.ndarray] = field(default_factory=dict)  # mimic joint values at canonical zero

    @property
    def couplings(self):
        """The canonical couplings of this form (from the action map)."""
        return self.action_map.couplings


# -- small geometry helpers ------------------------------------------------------------------------
def unit(v: np.ndarray) -> np.ndarray:
    """``v`` normalised (a zero vector stays zero)."""
    n = float(np.linalg.norm(v))
    return v / n if n > 1e-12 else v * 0.0


def fixed_descendants(hand: OriginalHand, link: str) -> list[str]:
    """``link`` and the links attached below it through fixed joints only."""
    out, stack = [], [link]
    while stack:
        x = stack.pop()
        out.append(x)
        for j in hand.joints.values():
            if j.parent == x and j.type == "fixed":
                stack.append(j.child)
    return out


def _closest_point_on_b(pa: np.ndarray, da: np.ndarray, pb: np.ndarray, db: np.ndarray) -> np.ndarray:
    """Point on line b closest to line a (pb when the lines are parallel)."""
    w = pa - pb
    a, b, c = da @ da, da @ db, db @ db
    d, e = da @ w, db @ w
    den = a * c - b * b
    if abs(den) < 1e-9:
        return pb.copy()
    t = (a * e - b * d) / den
    return pb + t * db


def farthest(points: np.ndarray, origin: np.ndarray, z: np.ndarray) -> np.ndarray:
    """The fingertip point: centroid of the points within TIP_BAND of the farthest extent along z,
    moved out to that extent (a flat or rounded finger end gives a point on its axis)."""
    s = (points - origin) @ z
    top = s.max()
    c = points[s >= top - TIP_BAND].mean(axis=0)
    return c + (top - (c - origin) @ z) * z


def warn_estimated(notes: list[str], msg: str) -> None:
    """Record ``msg`` as an estimate in ``notes`` and warn with :class:`ParseWarning`."""
    notes.append("estimated: " + msg)
    warnings.warn(msg, ParseWarning, stacklevel=user_stacklevel())


def geometry_points(hand: OriginalHand, links: list[str], T_links: dict[str, np.ndarray]) -> np.ndarray | None:
    """(P,3) vertices of the links' geometry posed by ``T_links`` (link -> (4,4)), or None."""
    pts = []
    for l in links:
        m = hand.link_geometry(l)
        if m is None:
            continue
        v = np.asarray(m.vertices)
        T = T_links[l]
        pts.append(v @ T[:3, :3].T + T[:3, 3])
    return np.vstack(pts) if pts else None


# -- the measurement -------------------------------------------------------------------------------
def _palm_link(hand: OriginalHand, fs: FormSpec) -> str:
    """The lowest common ancestor of the mapped joints' parent links."""
    chains = [hand.ancestors(hand.joints[sm.name].parent)[::-1] for sm in fs.slots.values()]
    palm_link = hand.root
    for level in zip(*chains):
        if len(set(level)) == 1:
            palm_link = level[0]
        else:
            break
    return palm_link


def check_joints_below_palm(hand: OriginalHand, spec: HandSpec, fs: FormSpec, notes: list[str]) -> None:
    """Refuse a finger slot mapped to a joint that moves every other finger too (a wrist or arm
    joint above the palm: the fit would absorb its motion into a finger and the palm frame would
    ride on the arm); note one that moves some other fingers (a palm piece the canonical finger
    cannot share)."""
    by_finger: dict[str, list[str]] = {}
    for slot, sm in fs.slots.items():
        by_finger.setdefault(slot.rsplit("_joint", 1)[0], []).append(slot)
    if len(by_finger) < 2:
        return
    for f, slots in by_finger.items():
        for slot in slots:
            joint = fs.slots[slot].name
            below = set(hand.descendants(hand.joints[joint].child))
            moved = {g: [fs.slots[s].name for s in gs if hand.joints[fs.slots[s].name].parent in below]
                     for g, gs in by_finger.items() if g != f}
            moved = {g: js for g, js in moved.items() if js}
            if not moved:
                continue
            what = ", ".join(f"{g} ({js[0]!r}{' ...' if len(js) > 1 else ''})" for g, js in moved.items())
            if len(moved) == len(by_finger) - 1:
                raise ParseError(
                    f"{spec.source}: slot {slot!r} maps joint {joint!r}, which moves every other finger too: {what}; "
                    f"a wrist or arm joint above the palm cannot drive a finger slot; map a joint inside the {f} finger "
                    f"(joints above the palm stay at 0)"
                )
            msg = f"slot {slot!r} maps joint {joint!r}, which also moves the {what} finger(s); the canonical {f} finger moves alone"
            notes.append("approximation: " + msg)
            warnings.warn(msg, ParseWarning, stacklevel=user_stacklevel())


def _stations(f: str, p: dict[str, np.ndarray], a: dict[str, np.ndarray]) -> list[np.ndarray | None]:
    """Base, middle-joint and distal-joint stations of finger ``f`` (None: no joint there)."""
    stations: list[np.ndarray | None] = []
    for k, group in enumerate(STATION_SLOTS[f]):
        mapped = [s for s in group if s in p]
        if not mapped:
            stations.append(None)
        elif len(mapped) == 2 and k == 0:
            # two joints share the base: the point on the second joint's axis closest to the first's
            s1, s2 = mapped
            stations.append(_closest_point_on_b(p[s1], a[s1], p[s2], a[s2]))
        else:
            stations.append(p[mapped[-1]] if k == 0 else p[mapped[0]])
    return stations


def _direction_and_tip(
    f: str, stations: list, p_last: np.ndarray, dist_pts: np.ndarray | None, last_link: str, source: str, notes: list[str]
) -> tuple[np.ndarray, np.ndarray]:
    """Finger direction z and fingertip point: from the first joint station after the base to the
    distal geometry; without distal geometry one segment beyond the last joint (warned)."""
    joint_pts = [s for s in stations if s is not None]
    ref = next((s for s in stations[1:] if s is not None), joint_pts[0])
    if dist_pts is not None:
        z = unit(dist_pts.mean(axis=0) - ref)
        if np.linalg.norm(dist_pts.mean(axis=0) - ref) < 1e-6:
            z = unit(p_last - joint_pts[0])
        tip = farthest(dist_pts, p_last, z)
        if len(joint_pts) >= 2:  # refine the direction through the tip
            z = unit(tip - ref) if np.linalg.norm(tip - ref) > 1e-6 else z
            tip = farthest(dist_pts, p_last, z)
        return z, tip
    if len(joint_pts) < 2:
        raise ParseError(f"{source}: finger {f!r} has one mapped joint and no distal geometry: cannot tell its length")
    z = unit(joint_pts[-1] - joint_pts[-2])
    seg = float(np.linalg.norm(joint_pts[-1] - joint_pts[-2]))
    warn_estimated(notes, f"{f} fingertip: link {last_link!r} has no geometry; tip placed one segment "
                          f"({seg * 1e3:.1f} mm) beyond the last joint")
    return z, p_last + z * seg


def _flexion_axis(f: str, slots: list[str], a: dict[str, np.ndarray], z: np.ndarray) -> np.ndarray:
    """The finger's flexion axis orthogonal to z (preferred slots first, then any axis, else any normal)."""
    for group in (FLEX_PREF[f], slots):
        for s in group:
            if s in a:
                cand = a[s] - (a[s] @ z) * z
                if np.linalg.norm(cand) > 0.3:
                    return unit(cand)
    return unit(np.cross(z, [1.0, 0.0, 0.0])) if abs(z[0]) < 0.9 else unit(np.cross(z, [0.0, 1.0, 0.0]))


def _segment_radius(hand: OriginalHand, seg_links: list[str], T_links: dict, y: np.ndarray, z: np.ndarray) -> float | None:
    """Median half mean cross-section width of the segment links around the finger direction."""
    radii = []
    xax = np.cross(y, z)
    for l in seg_links:
        pts = geometry_points(hand, [l], T_links)
        if pts is None or len(pts) < 4:
            continue
        radii.append(0.25 * (np.ptp(pts @ xax) + np.ptp(pts @ y)))
    return float(np.median(radii)) if radii else None


def _last_slot(slots: list[str]) -> str:
    """The finger's last mapped slot, ignoring the little finger's metacarpal joint0 when possible."""
    real = [s for s in slots if not s.endswith("joint0")]
    return real[-1] if real else slots[-1]


def _measure_finger(
    hand: OriginalHand, spec: HandSpec, fs: FormSpec, f: str, T_links: dict[str, np.ndarray], notes: list[str]
) -> FingerMeasure | None:
    """Joint frames, stations, direction, fingertip and radius of canonical finger ``f`` (None: unmapped)."""
    slots = [s for s in JOINT_NAMES[FINGER_SLICES[f]] if s in fs.slots]
    if not slots:
        return None
    p, a = {}, {}
    for s in slots:
        sm = fs.slots[s]
        j = hand.joints[sm.name]
        T = T_links[j.child]
        p[s] = T[:3, 3].copy()
        a[s] = unit(T[:3, :3] @ j.axis) * sm.sign
    stations = _stations(f, p, a)
    last_slot = _last_slot(slots)
    last_link = hand.joints[fs.slots[last_slot].name].child
    distal_links = fixed_descendants(hand, last_link)
    moved = distal_links + [l for l in hand.descendants(last_link) if l not in distal_links]
    _note_unfollowed(hand, f, fs, moved, last_link, notes)
    seg_links: list[str] = []
    for s in slots:
        if not s.endswith("joint0"):
            seg_links += fixed_descendants(hand, hand.joints[fs.slots[s].name].child)
    seg_links += [l for l in moved if l not in seg_links]  # mimic-driven links are part of the finger
    dist_pts, owner = _points_with_owner(hand, moved, T_links)
    z, tip = _direction_and_tip(f, stations, p[last_slot], dist_pts, last_link, spec.source, notes)
    tip_link = _rigid_root(hand, owner[int(np.argmax((dist_pts - tip) @ z))]) if dist_pts is not None else last_link
    y = _flexion_axis(f, slots, a, z)
    stations.append(tip)
    _note_bends(f, fs, stations, p, a, y, notes)
    radius = _segment_radius(hand, seg_links, T_links, y, z)
    return FingerMeasure(slots, p, a, stations, z, y, tip, radius, seg_links, distal_links, tip_link)


def _points_with_owner(hand: OriginalHand, links: list[str], T_links: dict) -> tuple[np.ndarray | None, list[str]]:
    """Geometry points of ``links`` (as :func:`geometry_points`) and the link of each point."""
    pts, owner = [], []
    for l in links:
        p = geometry_points(hand, [l], T_links)
        if p is not None:
            pts.append(p)
            owner += [l] * len(p)
    return (np.vstack(pts) if pts else None), owner


def _rigid_root(hand: OriginalHand, link: str) -> str:
    """The first link at or above ``link`` whose parent joint is not fixed (they move together)."""
    while link in hand.parent_joint and hand.parent_joint[link].type == "fixed":
        link = hand.parent_joint[link].parent
    return link


def _note_unfollowed(hand: OriginalHand, f: str, fs: FormSpec, moved: list[str], last_link: str, notes: list[str]) -> None:
    """Warn about joints beyond the finger's last mapped joint that move links but drive no slot."""
    mapped = {sm.name for sm in fs.slots.values()}
    loose = []
    for l in moved:
        j = hand.parent_joint.get(l)
        if l != last_link and j is not None and j.type != "fixed" and j.name not in mapped:
            loose.append(f"{j.name!r}" + (f" (mimic of {j.mimic[0]!r})" if j.mimic else " (unmapped)"))
    if loose:
        msg = (f"{f}: joint(s) {', '.join(loose)} move links beyond the finger's last mapped joint but drive no slot: the "
               f"canonical finger holds them at canonical zero (map them to slots to follow them)")
        notes.append("approximation: " + msg)
        warnings.warn(msg, ParseWarning, stacklevel=user_stacklevel())


def _note_unmapped_mimics(hand: OriginalHand, fs: FormSpec, palm_link: str, fingers: dict, notes: list[str]) -> None:
    """Warn about ``<mimic>`` joints inside the hand that drive no slot and move a finger from *below*
    its last mapped joint (e.g. a palm piece that carries fingers and follows the thumb): the canonical
    hand holds them at canonical zero. Joints beyond a finger's last mapped joint are noted per finger
    (:func:`_note_unfollowed`)."""
    mapped = {sm.name for sm in fs.slots.values()}
    below = set(hand.descendants(palm_link))
    beyond: set[str] = set()
    for fm in fingers.values():
        beyond.update(hand.descendants(hand.joints[fs.slots[_last_slot(fm.slots)].name].child))
    for name in hand.mimic_joints:
        j = hand.joints[name]
        if name in mapped or j.parent not in below or j.child in beyond:
            continue
        moved = set(hand.descendants(j.child))
        hit = [f for f, fm in fingers.items() if moved & set(fm.seg_links)]
        if not hit:
            continue
        msg = (f"joint {name!r} (mimic of {j.mimic[0]!r}) moves the {', '.join(hit)} finger(s) but drives no slot: the "
               f"canonical hand holds it at canonical zero, so its motion counts in the errors (map it to a slot to follow it)")
        notes.append("approximation: " + msg)
        warnings.warn(msg, ParseWarning, stacklevel=user_stacklevel())


BEND_NOTE = np.radians(15.0)  # noted above this (joint origins sit off the finger axis by a few degrees)


def _note_bends(f: str, fs: FormSpec, stations: list, p: dict, a: dict, y: np.ndarray, notes: list[str]) -> None:
    """Note joints where the finger is bent at canonical zero (the template's zero is straight),
    with the slot offset that would make canonical zero straight."""
    for k in (1, 2):
        if stations[k] is None or stations[k - 1] is None:
            continue
        nxt = next((s for s in stations[k + 1:] if s is not None), None)
        d_in, d_out = stations[k] - stations[k - 1], (nxt - stations[k]) if nxt is not None else None
        group = [s for s in STATION_SLOTS[f][k] if s in a]
        if d_out is None or not group or np.linalg.norm(d_in) < 1e-6 or np.linalg.norm(d_out) < 1e-6:
            continue
        slot = max(group, key=lambda s: np.linalg.norm(np.cross(a[s], unit(d_in))))
        ax = a[slot]
        u, v = d_in - (d_in @ ax) * ax, d_out - (d_out @ ax) * ax
        bend = float(np.arctan2(np.cross(u, v) @ ax, u @ v))  # + = flexed toward the palm
        if abs(bend) > BEND_NOTE:
            sm = fs.slots[slot]
            notes.append(f"approximation: at canonical zero the {f} finger looks bent {np.degrees(bend):+.1f} deg at {slot} "
                         f"(joint {sm.name!r}); offset {sm.offset + bend:+.4f} on {slot} would make canonical zero straight")


def _palm_radius(
    hand: OriginalHand, palm_link: str, fingers: dict[str, FingerMeasure], T_links: dict, r_guess: float, notes: list[str]
) -> float:
    """Palm disc radius from the palm geometry (palm link and links fixed to it), else the knuckle spread."""
    finger_links = set()
    for fm in fingers.values():
        finger_links.update(fm.seg_links)
    palm_links = [l for l in fixed_descendants(hand, palm_link) if l not in finger_links]
    palm_pts = geometry_points(hand, palm_links, T_links)
    if palm_pts is not None:
        return float(0.25 * (np.ptp(palm_pts[:, 1]) + np.ptp(palm_pts[:, 2])))
    bases = np.array([fm.stations[0] if fm.stations[0] is not None else fm.p[fm.slots[0]]
                      for f, fm in fingers.items() if f != "thumb"] or [np.zeros(3)])
    spread = (bases[:, 1].max() - bases[:, 1].min()) / 2.0 + r_guess
    height = max(bases[:, 2].max() / 2.0, 1e-3)
    palm_radius = 0.5 * (spread + height)
    missing = list(hand.missing_meshes)
    warn_estimated(notes, f"palm radius {palm_radius * 1e3:.1f} mm from the knuckle spread: palm link {palm_link!r} has no geometry"
                   + (f" (missing mesh {', '.join(missing)})" if missing else ""))
    return float(palm_radius)


def measure(hand: OriginalHand, spec: HandSpec, form: str) -> Measurement:
    """Measure joint frames, fingertips and radii of ``hand`` under ``spec``'s ``form`` mapping."""
    am = spec.action_map(form, hand)
    fs = spec.form(form)
    notes: list[str] = []
    q0 = am.to_original(np.zeros(22))
    passive0 = am.passive_values(np.zeros(22))
    T_palm_root = invert(xyzrpy_to_matrix(spec.palm_origin))
    poses = hand.link_poses(q0, passive=passive0)
    T_links = {l: T_palm_root @ poses[i] for i, l in enumerate(hand.links)}
    lower, upper = am.limits_to_canonical(hand.lower, hand.upper)
    for slot, v in fs.fixed.items():
        lower[JOINT_INDEX[slot]] = upper[JOINT_INDEX[slot]] = v
    check_joints_below_palm(hand, spec, fs, notes)
    palm_link = _palm_link(hand, fs)
    fingers: dict[str, FingerMeasure] = {}
    for f in FINGERS:
        fm = _measure_finger(hand, spec, fs, f, T_links, notes)
        if fm is not None:
            fingers[f] = fm
    _note_unmapped_mimics(hand, fs, palm_link, fingers, notes)
    tip_links = {f: fm.distal_links for f, fm in fingers.items()}
    rad_known = [fm.radius for fm in fingers.values() if fm.radius is not None]
    r_guess = float(np.median(rad_known)) if rad_known else 0.01
    palm_radius = _palm_radius(hand, palm_link, fingers, T_links, r_guess, notes)
    finger_radius: dict[str, float] = {}
    for f, fm in fingers.items():
        if fm.radius is None:
            finger_radius[f] = r_guess
            warn_estimated(notes, f"{f} radius {r_guess * 1e3:.1f} mm borrowed from the other fingers: its links have no geometry")
        else:
            finger_radius[f] = fm.radius
    return Measurement(hand, am, T_palm_root, q0, lower, upper, fingers, palm_link, palm_radius,
                       finger_radius, tip_links, notes, passive0)


__all__ = ["measure", "Measurement", "FingerMeasure", "ParseWarning", "geometry_points", "fixed_descendants", "unit"]
