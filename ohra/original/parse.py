"""Parse an original hand URDF + :class:`~ohra.original.spec.HandSpec` into canonical parameters.

Everything is measured in the canonical palm frame (``T_palm = T_root @ T(palm_origin)``) with the
original hand at the configuration that maps to canonical ``q = 0`` (``ActionMap.to_original(0)``).
The rules are general (no hand names anywhere):

* joint positions and axes: the child frame of each mapped original joint; the axis is multiplied
  by the slot's sign. Axes the template fixes (finger flexion +y, abduction +x, thumb j3 +x, j4/j5
  +y) are checked against the signs: an opposite axis is a :class:`SpecError` telling the fix.
* finger frame: ``z`` points from the first joint after the base to the fingertip, ``y`` is the
  flexion axis (j3, else j4, else j2; thumb: j4, else j5, else j3) made orthogonal to ``z``.
* stations along a finger: base (j1/j2), middle joint (j3 / thumb j3,j4), distal joint (j4 / thumb
  j5) and the fingertip. Link lengths are distances between consecutive stations (collapsed stations
  follow the templates' rules); the **distal length** reaches the fingertip point.
* fingertip point: the centroid of the distal link's geometry points (with links fixed to it) within
  1 mm of its farthest extent along the finger direction, moved out to that extent. Without geometry: the distal joint plus the previous segment's length (warned).
* palm radius: half the mean of the palm geometry's extents in y and z (the disc's plane); without
  palm geometry, from the knuckle spread (warned). Finger radius: half the mean cross-section width
  of each segment link, median over links (base: all fingers; extended: per finger), capped so every
  capsule is at least as long as its diameter.
* geometry: collision elements when the link has any, else visual ones, else nothing.
* limits: the ActionMap's (a negated joint swaps and negates its limits; offsets are added); fixed
  slots get ``[v, v]``.

The optional **fit** refines the continuous kinematic parameters (lengths, base positions and
orientations, free axes) with ``scipy.optimize.least_squares`` so that canonical fingertips and joint
positions match the original ones over seeded random configurations mapped with the ActionMap;
capsule lengths stay >= their diameter. Joint positions are compared as the distance from the
canonical joint origin to the original joint's axis line (a revolute joint's position along its own
axis carries no kinematic meaning). The fit is deterministic (seeded sampling, deterministic solver).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from ohra.original.action import ActionMap
from ohra.errors import ParamsError, SpecError, ParseError
from ohra.original.spec import HandSpec, load_spec
from ohra.original.urdf import OriginalHand, load_urdf
from ohra.canonical.params import (
    EXT_ROW_JOINTS,
    EXT_ROW_START,
    FINGER_SLICES,
    FINGERS,
    JOINT_INDEX,
    JOINT_NAMES,
    BaseParams,
    ExtendedParams,
    link_presence,
)
from ohra.transforms import invert, inverse_rpy, matrix_to_rpy, rpy_to_matrix, xyzrpy_to_matrix

Params = BaseParams | ExtendedParams
DECIMALS = 6  # committed numbers: micrometres / microradians
MIN_CAPSULE_MARGIN = 1e-5  # m, capsule length >= diameter + margin


class ParseWarning(UserWarning):
    """Something was estimated instead of measured (the message says what and why)."""


# ------------------------------------------------------------------------------------------------
# Measurements of the original hand
# ------------------------------------------------------------------------------------------------
@dataclass
class FingerMeasure:
    """One canonical finger measured on the original hand (palm frame, canonical zero)."""

    slots: list[str]  # mapped canonical slots of this finger, canonical order
    p: dict[str, np.ndarray]  # slot -> joint position
    a: dict[str, np.ndarray]  # slot -> signed unit axis
    stations: list[np.ndarray | None]  # base, middle joint, distal joint, tip (None: no joint there)
    z: np.ndarray  # finger direction
    y: np.ndarray  # flexion axis (orthogonal to z)
    tip: np.ndarray
    radius: float | None
    seg_links: list[str]
    distal_links: list[str]


@dataclass
class Measurement:
    hand: OriginalHand
    action_map: ActionMap
    T_palm_root: np.ndarray  # root frame -> palm frame
    q0: np.ndarray  # original configuration of canonical zero
    lower: np.ndarray  # (22,) canonical limits
    upper: np.ndarray
    fingers: dict[str, FingerMeasure]
    palm_link: str
    palm_radius: float
    finger_radius: dict[str, float]
    tip_links: dict[str, list[str]]
    notes: list[str] = field(default_factory=list)


def _finger_of(slot: str) -> str:
    return slot.split("_")[0]


def _unit(v: np.ndarray) -> np.ndarray:
    n = float(np.linalg.norm(v))
    return v / n if n > 1e-12 else v * 0.0


def _fixed_descendants(hand: OriginalHand, link: str) -> list[str]:
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


TIP_BAND = 1e-3  # m: geometry points this close to the farthest extent form the fingertip


def _farthest(points: np.ndarray, origin: np.ndarray, z: np.ndarray) -> np.ndarray:
    """The fingertip point: centroid of the points within TIP_BAND of the farthest extent along z,
    moved out to that extent (a flat or rounded finger end gives a point on its axis)."""
    s = (points - origin) @ z
    top = s.max()
    c = points[s >= top - TIP_BAND].mean(axis=0)
    return c + (top - (c - origin) @ z) * z


def _warn(notes: list[str], msg: str) -> None:
    notes.append("estimated: " + msg)
    warnings.warn(msg, ParseWarning, stacklevel=3)


def _geometry_points(hand: OriginalHand, links: list[str], T_links: dict[str, np.ndarray]) -> np.ndarray | None:
    pts = []
    for l in links:
        m = hand.link_geometry(l)
        if m is None:
            continue
        v = np.asarray(m.vertices)
        T = T_links[l]
        pts.append(v @ T[:3, :3].T + T[:3, 3])
    return np.vstack(pts) if pts else None


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


def measure(hand: OriginalHand, spec: HandSpec, form: str) -> Measurement:
    """Measure joint frames, fingertips and radii of ``hand`` under ``spec``'s ``form`` mapping."""
    am = spec.action_map(form, hand.movable_joints)
    fs = spec.form(form)
    notes: list[str] = []
    q0 = am.to_original(np.zeros(22))
    T_palm_root = invert(xyzrpy_to_matrix(spec.palm_origin))
    poses = hand.link_poses(q0)
    T_links = {l: T_palm_root @ poses[i] for i, l in enumerate(hand.links)}
    lower, upper = am.limits_to_canonical(hand.lower, hand.upper)
    for slot, v in fs.fixed.items():
        lower[JOINT_INDEX[slot]] = upper[JOINT_INDEX[slot]] = v

    # the palm: lowest common ancestor of the mapped joints' parent links
    chains = [hand.ancestors(hand.joints[sm.name].parent)[::-1] for sm in fs.slots.values()]
    palm_link = hand.root
    for level in zip(*chains):
        if len(set(level)) == 1:
            palm_link = level[0]
        else:
            break

    fingers: dict[str, FingerMeasure] = {}
    tip_links: dict[str, list[str]] = {}
    for f in FINGERS:
        slots = [s for s in JOINT_NAMES[FINGER_SLICES[f]] if s in fs.slots]
        if not slots:
            continue
        p, a = {}, {}
        for s in slots:
            sm = fs.slots[s]
            j = hand.joints[sm.name]
            T = T_links[j.child]
            p[s] = T[:3, 3].copy()
            a[s] = _unit(T[:3, :3] @ j.axis) * sm.sign
        stations: list[np.ndarray | None] = []
        groups = STATION_SLOTS[f]
        for k, group in enumerate(groups):
            mapped = [s for s in group if s in p]
            if not mapped:
                stations.append(None)
            elif len(mapped) == 2 and k == 0:
                # two joints share the base: the point on the second joint's axis closest to the first's
                s1, s2 = mapped
                stations.append(_closest_point_on_b(p[s1], a[s1], p[s2], a[s2]))
            else:
                stations.append(p[mapped[-1]] if k == 0 else p[mapped[0]])
        last_slot = [s for s in slots if not s.endswith("joint0")][-1] if any(not s.endswith("joint0") for s in slots) else slots[-1]
        last_link = hand.joints[fs.slots[last_slot].name].child
        distal_links = _fixed_descendants(hand, last_link)
        tip_links[f] = distal_links
        seg_links = []
        for s in slots:
            if s.endswith("joint0"):
                continue
            seg_links += _fixed_descendants(hand, hand.joints[fs.slots[s].name].child)
        # finger direction: from the first joint station after the base to the distal geometry
        p_last = p[last_slot]
        dist_pts = _geometry_points(hand, distal_links, T_links)
        joint_pts = [s for s in stations if s is not None]
        ref = next((s for s in stations[1:] if s is not None), joint_pts[0])
        if dist_pts is not None:
            z = _unit(dist_pts.mean(axis=0) - ref)
            if np.linalg.norm(dist_pts.mean(axis=0) - ref) < 1e-6:
                z = _unit(p_last - joint_pts[0])
            tip = _farthest(dist_pts, p_last, z)
            if len(joint_pts) >= 2:  # refine the direction through the tip
                z = _unit(tip - ref) if np.linalg.norm(tip - ref) > 1e-6 else z
                tip = _farthest(dist_pts, p_last, z)
        else:
            if len(joint_pts) < 2:
                raise ParseError(
                    f"{spec.source}: finger {f!r} has one mapped joint and no distal geometry: cannot tell its length"
                )
            z = _unit(joint_pts[-1] - joint_pts[-2])
            seg = float(np.linalg.norm(joint_pts[-1] - joint_pts[-2]))
            tip = p_last + z * seg
            _warn(notes, f"{f} fingertip: link {last_link!r} has no geometry; tip placed one segment ({seg * 1e3:.1f} mm) beyond the last joint")
        y = None
        for s in FLEX_PREF[f]:
            if s in a:
                cand = a[s] - (a[s] @ z) * z
                if np.linalg.norm(cand) > 0.3:
                    y = _unit(cand)
                    break
        if y is None:  # no flexion-like joint: any axis orthogonal to z
            for s in slots:
                cand = a[s] - (a[s] @ z) * z
                if np.linalg.norm(cand) > 0.3:
                    y = _unit(cand)
                    break
        if y is None:
            y = _unit(np.cross(z, [1.0, 0.0, 0.0])) if abs(z[0]) < 0.9 else _unit(np.cross(z, [0.0, 1.0, 0.0]))
        stations.append(tip)
        # radius: cross-section of each segment link around the finger direction
        radii = []
        xax = np.cross(y, z)
        for l in seg_links:
            pts = _geometry_points(hand, [l], T_links)
            if pts is None or len(pts) < 4:
                continue
            wx = np.ptp(pts @ xax)
            wy = np.ptp(pts @ y)
            radii.append(0.25 * (wx + wy))
        fingers[f] = FingerMeasure(slots, p, a, stations, z, y, tip, float(np.median(radii)) if radii else None,
                                   seg_links, distal_links)

    # palm radius from the palm geometry (palm link and links fixed to it), in the disc's plane
    finger_links = set()
    for fm in fingers.values():
        finger_links.update(fm.seg_links)
    palm_links = [l for l in _fixed_descendants(hand, palm_link) if l not in finger_links]
    palm_pts = _geometry_points(hand, palm_links, T_links)
    bases = np.array([fm.stations[0] if fm.stations[0] is not None else fm.p[fm.slots[0]]
                      for f, fm in fingers.items() if f != "thumb"] or [np.zeros(3)])
    rad_known = [fm.radius for fm in fingers.values() if fm.radius is not None]
    r_guess = float(np.median(rad_known)) if rad_known else 0.01
    if palm_pts is not None:
        palm_radius = 0.25 * (np.ptp(palm_pts[:, 1]) + np.ptp(palm_pts[:, 2]))
    else:
        spread = (bases[:, 1].max() - bases[:, 1].min()) / 2.0 + r_guess
        height = max(bases[:, 2].max() / 2.0, 1e-3)
        palm_radius = 0.5 * (spread + height)
        missing = [m for m in hand.missing_meshes]
        _warn(notes, f"palm radius {palm_radius * 1e3:.1f} mm from the knuckle spread: palm link {palm_link!r} has no geometry"
              + (f" (missing mesh {', '.join(missing)})" if missing else ""))

    finger_radius: dict[str, float] = {}
    for f, fm in fingers.items():
        if fm.radius is None:
            finger_radius[f] = r_guess
            _warn(notes, f"{f} radius {r_guess * 1e3:.1f} mm borrowed from the other fingers: its links have no geometry")
        else:
            finger_radius[f] = fm.radius
    return Measurement(hand, am, T_palm_root, q0, lower, upper, fingers, palm_link, float(palm_radius),
                       finger_radius, tip_links, notes)


# ------------------------------------------------------------------------------------------------
# Initial parameters from measurements
# ------------------------------------------------------------------------------------------------
def _frame(y: np.ndarray, z: np.ndarray) -> np.ndarray:
    return np.column_stack([np.cross(y, z), y, z])


def _stations_filled(st: list[np.ndarray | None]) -> list[np.ndarray]:
    """Fill stations without a joint with the next defined one (templates collapse absent offsets)."""
    out: list[np.ndarray | None] = list(st)
    for k in range(len(out) - 2, -1, -1):
        if out[k] is None:
            out[k] = out[k + 1]
    return out  # type: ignore[return-value]


def _check_axis(spec: HandSpec, form: str, slot: str, a: np.ndarray, expected: np.ndarray, what: str, notes: list[str], strict: bool) -> None:
    d = float(a @ expected)
    name = spec.form(form).slots[slot].name
    if d < -0.5:
        sign = spec.form(form).slots[slot].sign
        raise SpecError(
            f"{spec.source}: forms.{form} slot {slot!r} (joint {name!r}): with sign {sign:+g} its axis points opposite to "
            f"the canonical {what} axis (dot {d:+.2f}); use sign {-sign:+g}"
        )
    if d < 0.9 and strict:
        msg = f"{slot} (joint {name!r}) axis deviates from the canonical {what} axis by {np.degrees(np.arccos(np.clip(d, -1, 1))):.0f} deg"
        notes.append("approximation: " + msg)


def initial_extended(m: Measurement, spec: HandSpec, form: str = "extended") -> ExtendedParams:
    """Extended parameters straight from the measurements (before any fit)."""
    present = (m.lower != 0) | (m.upper != 0)
    lengths = np.zeros((5, 3))
    origins = np.zeros((12, 6))
    axes = np.zeros((12, 3))
    radii = np.zeros(5)
    notes = m.notes
    for fi, f in enumerate(FINGERS):
        if f not in m.fingers:
            continue
        fm = m.fingers[f]
        R = _frame(fm.y, fm.z)
        radii[fi] = m.finger_radius[f]
        st = _stations_filled(fm.stations)
        names = JOINT_NAMES[FINGER_SLICES[f]]
        if f == "thumb":
            j1, j2 = names[0] in fm.p, names[1] in fm.p
            p1 = fm.p.get(names[0], st[0])
            p2 = fm.p.get(names[1], p1)
            origins[0, :3], origins[0, 3:] = p1, matrix_to_rpy(R)
            origins[1, :3] = R.T @ (p2 - p1)
            prox = float((st[1] - p2) @ fm.z) if (j1 or j2) else 0.0
            # the j3 origin carries what the proximal length (along z) does not
            origins[2, :3] = R.T @ (st[1] - p2) - np.array([0.0, 0.0, prox])
            axes[0] = R.T @ fm.a[names[0]] if j1 else (1.0, 0.0, 0.0)
            axes[1] = R.T @ fm.a[names[1]] if j2 else (0.0, 1.0, 0.0)
            axes[2] = R.T @ fm.a[names[2]] if names[2] in fm.a else (1.0, 0.0, 0.0)
            for s in names[3:]:
                if s in fm.a:
                    _check_axis(spec, form, s, fm.a[s], fm.y, "thumb flexion (+y)", notes, True)
            lengths[0] = (prox, (st[2] - st[1]) @ fm.z, (st[3] - st[2]) @ fm.z)
            if not (j1 or j2):
                # the template always adds the proximal length to the j3 origin: cancel it
                origins[2, 2] -= lengths[0, 0]
            continue
        row = EXT_ROW_START[fi]
        k = JOINT_INDEX[names[0]]
        if f == "little":
            e_slot = names[0]
            if e_slot in fm.p:
                ye = fm.a[e_slot]
                ze = _unit(fm.z - (fm.z @ ye) * ye)
                Re = _frame(ye, ze)
                origins[9, :3], origins[9, 3:] = fm.p[e_slot], matrix_to_rpy(Re)
                axes[9] = (0.0, 1.0, 0.0)
            else:
                Re = np.eye(3)
                axes[9] = (0.0, 1.0, 0.0)
            row, k = 10, JOINT_INDEX["little_joint1"]
            names = names[1:]
        sj1, sj2 = names[0], names[1]
        j1, j2 = sj1 in fm.p, sj2 in fm.p
        p1 = fm.p.get(sj1, st[0])
        p2 = fm.p.get(sj2, p1)
        if f == "little":
            origins[10, :3], origins[10, 3:] = p1, matrix_to_rpy(Re.T @ R)
        else:
            origins[row, :3], origins[row, 3:] = p1, matrix_to_rpy(R)
        jo1 = R.T @ (p2 - p1)
        if not j2 and not j1:
            jo1 = np.zeros(3)
        origins[row + 1, :3] = jo1
        axes[row] = R.T @ fm.a[sj1] if j1 else (1.0, 0.0, 0.0)
        axes[row + 1] = R.T @ fm.a[sj2] if j2 else (0.0, 1.0, 0.0)
        for s in names[2:]:
            if s in fm.a:
                _check_axis(spec, form, s, fm.a[s], fm.y, f"{f} flexion (+y)", notes, True)
        prox = float(jo1[2] + (st[1] - p2) @ fm.z) if (j1 or j2) else 0.0
        lengths[fi] = (prox, (st[2] - st[1]) @ fm.z, (st[3] - st[2]) @ fm.z)
    return _finish_extended(m, present, radii, lengths, origins, axes)


def _finish_extended(m, present, radii, lengths, origins, axes) -> ExtendedParams:
    links = link_presence(present)
    for fi, f in enumerate(FINGERS):
        segs = [lengths[fi, s] for s in range(3) if links[f][s]]
        if segs and radii[fi] > 0:
            radii[fi] = min(radii[fi], (min(segs) - MIN_CAPSULE_MARGIN) / 2.0)
            if radii[fi] <= 1e-3:
                raise ParseError(f"finger {f!r}: a segment is only {min(segs) * 1e3:.2f} mm long; check the joint mapping")
        for s in range(3):
            if not links[f][s]:
                lengths[fi, s] = max(lengths[fi, s], 0.0)
    axes = np.where(np.linalg.norm(axes, axis=1, keepdims=True) > 0, axes / np.maximum(np.linalg.norm(axes, axis=1, keepdims=True), 1e-12), axes)
    return ExtendedParams(
        palm_radius=m.palm_radius,
        finger_radii=radii,
        finger_lengths=np.maximum(lengths, 0.0),
        joint_origins=origins,
        joint_axes=axes,
        joint_lowers=m.lower.copy(),
        joint_uppers=m.upper.copy(),
    )


def initial_base(m: Measurement, spec: HandSpec, form: str = "base") -> BaseParams:
    """Base parameters straight from the measurements (palm-aligned fingers, shared lengths)."""
    present = (m.lower != 0) | (m.upper != 0)
    links = link_presence(present)
    notes = m.notes
    finger_xyz = np.zeros((5, 3))
    thumb_rpy = np.zeros(3)
    thumb_axes = np.zeros((2, 3))
    extra = np.zeros(6)
    thumb_len = np.zeros(3)
    seg_lens: list[list[float]] = [[], [], []]
    ex, ey = np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
    for fi, f in enumerate(FINGERS):
        if f not in m.fingers:
            continue
        fm = m.fingers[f]
        st = _stations_filled(fm.stations)
        lens = [float(np.linalg.norm(st[k + 1] - st[k])) for k in range(3)]
        names = JOINT_NAMES[FINGER_SLICES[f]]
        if f == "thumb":
            R = _frame(fm.y, fm.z)
            finger_xyz[0] = st[0]
            thumb_rpy = matrix_to_rpy(R)
            for k in range(2):
                if names[k] in fm.a:
                    thumb_axes[k] = R.T @ fm.a[names[k]]
            if names[2] in fm.a:
                _check_axis(spec, form, names[2], fm.a[names[2]], R[:, 0], "thumb j3 (+x of the thumb frame)", notes, True)
            for s in names[3:]:
                if s in fm.a:
                    _check_axis(spec, form, s, fm.a[s], fm.y, "thumb flexion (+y of the thumb frame)", notes, True)
            thumb_len = np.array(lens)
            continue
        Re = np.eye(3)
        if f == "little":
            if names[0] in fm.p:
                ye = fm.a[names[0]]
                ze = _unit(fm.z - (fm.z @ ye) * ye)
                Re = _frame(ye, ze)
                extra = np.concatenate([fm.p[names[0]], matrix_to_rpy(Re)])
            names = names[1:]
        finger_xyz[fi] = st[0]
        if names[0] in fm.a:
            _check_axis(spec, form, names[0], fm.a[names[0]], ex, f"{f} abduction (+x)", notes, True)
        for s in names[1:]:
            if s in fm.a:
                _check_axis(spec, form, s, fm.a[s], ey, f"{f} flexion (+y)", notes, True)
        for k in range(3):
            if links[f][k]:
                seg_lens[k].append(lens[k])
    finger_len = np.array([float(np.mean(s)) if s else 0.0 for s in seg_lens])
    radii = [m.finger_radius[f] for f in m.fingers]
    r = float(np.median(radii))
    present_lens = [thumb_len[k] for k in range(3) if links["thumb"][k]]
    present_lens += [finger_len[k] for k in range(3) if any(links[f][k] for f in FINGERS[1:])]
    if present_lens:
        r = min(r, (min(present_lens) - MIN_CAPSULE_MARGIN) / 2.0)
        if r <= 1e-3:
            raise ParseError(f"a finger segment is only {min(present_lens) * 1e3:.2f} mm long; check the joint mapping")
    return BaseParams(
        palm_radius=m.palm_radius,
        finger_radius=r,
        finger_lengths=np.vstack([thumb_len, finger_len]),
        finger_xyz=finger_xyz,
        little_extra_origin=extra,
        thumb_rpy=thumb_rpy,
        thumb_axes=thumb_axes,
        joint_lowers=m.lower.copy(),
        joint_uppers=m.upper.copy(),
    )


# ------------------------------------------------------------------------------------------------
# Canonical forward kinematics straight from parameter arrays (mirrors the URDF templates)
# ------------------------------------------------------------------------------------------------
def _rpy_matrix(rpy: np.ndarray) -> np.ndarray:
    """Rz(yaw) Ry(pitch) Rx(roll) (fixed-axis rpy), without scipy's per-call overhead."""
    cr, sr = np.cos(rpy[0]), np.sin(rpy[0])
    cp, sp = np.cos(rpy[1]), np.sin(rpy[1])
    cy, sy = np.cos(rpy[2]), np.sin(rpy[2])
    return np.array([
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ])


def _T(xyzrpy: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = _rpy_matrix(xyzrpy[3:6])
    T[:3, 3] = xyzrpy[:3]
    return T


def _rot_batch(axis: np.ndarray, q: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(axis)
    axis = axis / n if n > 1e-12 else np.array([1.0, 0.0, 0.0])
    x, y, z = axis
    K = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    s, c = np.sin(q)[:, None, None], np.cos(q)[:, None, None]
    out = np.zeros((q.shape[0], 4, 4))
    out[:, :3, :3] = np.eye(3) + s * K + (1.0 - c) * (K @ K)
    out[:, 3, 3] = 1.0
    return out


def _tz(d: float) -> np.ndarray:
    T = np.eye(4)
    T[2, 3] = d
    return T


def ext_arrays_from_base(v: np.ndarray, present: np.ndarray) -> dict[str, np.ndarray]:
    """Extended kinematic arrays of a base parameter vector (as :meth:`BaseParams.to_extended`)."""
    fl = v[2:8].reshape(2, 3)
    fxyz = v[8:23].reshape(5, 3)
    e = v[23:29]
    trpy = v[29:32]
    tax = v[32:38].reshape(2, 3)
    lengths = np.vstack([fl[0], np.tile(fl[1], (4, 1))])
    o = np.zeros((12, 6))
    ax = np.zeros((12, 3))
    o[0, :3], o[0, 3:] = fxyz[0], trpy
    ax[0] = tax[0] if present[0] else (1.0, 0.0, 0.0)
    ax[1] = tax[1] if present[1] else (0.0, 1.0, 0.0)
    if not (present[0] or present[1]):
        o[2, 2] = -fl[0, 0]
    ax[2] = (1.0, 0.0, 0.0)
    for fi in (1, 2, 3):
        r = EXT_ROW_START[fi]
        o[r, :3] = fxyz[fi]
        ax[r], ax[r + 1] = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0)
    o[9] = e
    ax[9] = (0.0, 1.0, 0.0)
    o[10, :3] = fxyz[4]
    o[10, 3:] = inverse_rpy(e[3:])
    ax[10], ax[11] = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0)
    return {"lengths": lengths, "origins": o, "axes": ax}


def ext_arrays(p: ExtendedParams) -> dict[str, np.ndarray]:
    return {"lengths": p.finger_lengths, "origins": p.joint_origins, "axes": p.joint_axes}


def canonical_keypoints(
    arr: dict[str, np.ndarray], present: np.ndarray, q: np.ndarray, fingers: tuple[str, ...] = FINGERS
) -> tuple[np.ndarray, np.ndarray]:
    """Joint origins (N,22,3) and fingertips (N,5,3) of a canonical hand (standard templates).

    Mirrors ``urdf/templates/{base,extended}.urdf.j2``; tested against :class:`ohra.HandModel`.
    Only ``fingers`` are evaluated (the other rows stay NaN).
    """
    q = np.atleast_2d(q)
    N = q.shape[0]
    fl, o, ax = arr["lengths"], arr["origins"], arr["axes"]
    a = present
    links = link_presence(present)
    J = np.full((N, 22, 3), np.nan)
    tips = np.full((N, 5, 3), np.nan)
    ey = np.array([0.0, 1.0, 0.0])
    I = np.broadcast_to(np.eye(4), (N, 4, 4))

    def step(T, placement, k, axis):
        T = T @ placement
        J[:, k] = T[:, :3, 3]
        return T @ _rot_batch(axis if a[k] else _default_axis(k), q[:, k])

    if "thumb" in fingers:
        T = step(I, _T(o[0]), 0, ax[0])
        T = step(T, _T(o[1]), 1, ax[1])
        o2 = o[2].copy()
        o2[2] += fl[0, 0]
        T = step(T, _T(o2), 2, ax[2])
        T = step(T, np.eye(4), 3, ey)
        T = step(T, _tz(fl[0, 1] if (a[2] or a[3]) else 0.0), 4, ey)
        if any(links["thumb"]):
            tips[:, 0] = (T @ _tz(fl[0, 2] if links["thumb"][2] else 0.0))[:, :3, 3]
    for fi, f in ((1, "index"), (2, "middle"), (3, "ring")):
        if f not in fingers:
            continue
        r, k = EXT_ROW_START[fi], JOINT_INDEX[f"{f}_joint1"]
        T = step(I, _T(o[r]), k, ax[r])
        T = step(T, _T(o[r + 1]), k + 1, ax[r + 1])
        T = step(T, _tz(fl[fi, 0] - o[r + 1, 2] if (a[k] or a[k + 1]) else 0.0), k + 2, ey)
        T = step(T, _tz(fl[fi, 1] if a[k + 2] else 0.0), k + 3, ey)
        if any(links[f]):
            tips[:, fi] = (T @ _tz(fl[fi, 2] if links[f][2] else 0.0))[:, :3, 3]
    if "little" in fingers:
        T = step(I, _T(o[9]), 17, ax[9])
        kn = np.zeros(6)
        kn[:3] = _rpy_matrix(o[9, 3:]).T @ (o[10, :3] - o[9, :3])
        kn[3:] = o[10, 3:]
        T = step(T, _T(kn), 18, ax[10])
        T = step(T, _T(o[11]), 19, ax[11])
        T = step(T, _tz(fl[4, 0] - o[11, 2] if (a[18] or a[19]) else 0.0), 20, ey)
        T = step(T, _tz(fl[4, 1] if a[20] else 0.0), 21, ey)
        if any(links["little"]):
            tips[:, 4] = (T @ _tz(fl[4, 2] if links["little"][2] else 0.0))[:, :3, 3]
    return J, tips


def _default_axis(k: int) -> np.ndarray:
    name = JOINT_NAMES[k]
    x = name in ("thumb_joint1", "thumb_joint3", "index_joint1", "middle_joint1", "ring_joint1", "little_joint1")
    return np.array([1.0, 0.0, 0.0]) if x else np.array([0.0, 1.0, 0.0])


# ------------------------------------------------------------------------------------------------
# Original keypoints
# ------------------------------------------------------------------------------------------------
@dataclass
class OriginalKeypoints:
    """Original-hand keypoints in the palm frame for a batch of configurations."""

    q_orig: np.ndarray  # (N, n)
    q_canon: np.ndarray  # (N, 22)
    joints: np.ndarray  # (N, 22, 3) mapped joint positions (NaN unmapped)
    axes: np.ndarray  # (N, 22, 3) their signed axes
    tips: np.ndarray  # (N, 5, 3) fingertip points (NaN absent)


def tip_points_local(m: Measurement) -> dict[str, tuple[str, np.ndarray]]:
    """The fingertip point of each finger as (link, point in that link's frame)."""
    poses = m.hand.link_poses(m.q0)
    idx = {l: i for i, l in enumerate(m.hand.links)}
    out = {}
    for f, fm in m.fingers.items():
        link = m.tip_links[f][0]
        T = m.T_palm_root @ poses[idx[link]]
        out[f] = (link, invert(T)[:3, :3] @ fm.tip + invert(T)[:3, 3])
    return out


def original_keypoints(m: Measurement, q_orig: np.ndarray) -> OriginalKeypoints:
    hand, am = m.hand, m.action_map
    q_orig = np.atleast_2d(q_orig)
    N = q_orig.shape[0]
    slot_links = {s: hand.joints[sm.name].child for s, sm in am.slots.items()}
    tipl = tip_points_local(m)
    want = sorted(set(slot_links.values()) | {l for l, _ in tipl.values()})
    P = hand.link_poses(q_orig, want)
    Tp = m.T_palm_root @ P
    w = {l: i for i, l in enumerate(want)}
    joints = np.full((N, 22, 3), np.nan)
    axes = np.full((N, 22, 3), np.nan)
    for s, l in slot_links.items():
        T = Tp[:, w[l]]
        joints[:, JOINT_INDEX[s]] = T[:, :3, 3]
        sm = am.slots[s]
        axes[:, JOINT_INDEX[s]] = (T[:, :3, :3] @ hand.joints[sm.name].axis) * sm.sign
    tips = np.full((N, 5, 3), np.nan)
    for f, (l, pt) in tipl.items():
        T = Tp[:, w[l]]
        tips[:, FINGERS.index(f)] = T[:, :3, :3] @ pt + T[:, :3, 3]
    return OriginalKeypoints(q_orig, am.to_canonical(q_orig), joints, axes, tips)


def sample_original(m: Measurement, n: int, seed: int) -> np.ndarray:
    """(n, dof) original configurations uniform within the mapped joints' limits (unmapped joints
    stay at their canonical-zero value), preceded by canonical zero itself when that lies within the
    original limits (Barrett's bent distal links, e.g., cannot straighten)."""
    hand, am = m.hand, m.action_map
    rng = np.random.default_rng(seed)
    q = np.tile(m.q0, (n, 1))
    mapped = am.mapped_original
    lo, up = hand.lower[mapped], hand.upper[mapped]
    q[:, mapped] = lo + rng.random((n, int(mapped.sum()))) * (up - lo)
    q0 = m.q0[mapped]
    if np.all((q0 >= lo - 1e-9) & (q0 <= up + 1e-9)):
        q = np.vstack([m.q0[None], q])
    return q


def line_distance(points: np.ndarray, line_pts: np.ndarray, line_dirs: np.ndarray) -> np.ndarray:
    """Distance of points to lines (through line_pts along unit line_dirs); (...,3) -> (...)."""
    d = points - line_pts
    return np.linalg.norm(d - np.sum(d * line_dirs, axis=-1, keepdims=True) * line_dirs, axis=-1)


# ------------------------------------------------------------------------------------------------
# Fit
# ------------------------------------------------------------------------------------------------
JOINT_WEIGHT = 0.5  # joint-position residuals relative to fingertip residuals
ALONG_AXIS_WEIGHT = 0.2
REG_WEIGHT = 1e-3  # pull toward the measured values (fixes directions the data cannot see)


def _free_mask_base(p: BaseParams) -> tuple[np.ndarray, np.ndarray]:
    """Free entries of the 82-vector and lower bounds (capsule >= diameter)."""
    v = p.to_vector()
    free = np.zeros(v.size, dtype=bool)
    lb = np.full(v.size, -np.inf)
    links = p.link_presence()
    a = p.present_joints
    r = p.finger_radius
    for s in range(3):
        if links["thumb"][s]:
            free[2 + s] = True
            lb[2 + s] = 2 * r + MIN_CAPSULE_MARGIN
        if any(links[f][s] for f in FINGERS[1:]):
            free[5 + s] = True
            lb[5 + s] = 2 * r + MIN_CAPSULE_MARGIN
    for fi, f in enumerate(FINGERS):
        if any(links[f]):
            free[8 + 3 * fi : 11 + 3 * fi] = True
    if a[17]:
        free[23:29] = True
    if any(links["thumb"]):
        free[29:32] = True
    if a[0]:
        free[32:35] = True
    if a[1]:
        free[35:38] = True
    return free, lb


def _free_mask_ext(p: ExtendedParams) -> tuple[np.ndarray, np.ndarray]:
    v = p.to_vector()
    free = np.zeros(v.size, dtype=bool)
    lb = np.full(v.size, -np.inf)
    links = p.link_presence()
    a = p.present_joints
    OFF_L, OFF_O, OFF_A = 6, 21, 93
    for fi, f in enumerate(FINGERS):
        if not any(links[f]):
            continue
        r = p.finger_radii[fi]
        for s in range(3):
            if links[f][s]:
                free[OFF_L + 3 * fi + s] = True
                lb[OFF_L + 3 * fi + s] = 2 * r + MIN_CAPSULE_MARGIN
        start = EXT_ROW_START[fi]
        rows = range(start, start + (3 if fi in (0, 4) else 2))
        for row in rows:
            free[OFF_O + 6 * row : OFF_O + 6 * row + 6] = True
        for row in rows:  # free axes of present joints
            if a[JOINT_INDEX[EXT_ROW_JOINTS[row]]]:
                free[OFF_A + 3 * row : OFF_A + 3 * row + 3] = True
    # little metacarpal frame only matters when j0 is present
    if not a[17]:
        free[OFF_O + 6 * 9 : OFF_O + 6 * 10] = False
    # redundant rotations (the j1 frame's rotation and the free axes already span them): keep at 0
    for row in (1, 2, 4, 6, 8, 11):
        free[OFF_O + 6 * row + 3 : OFF_O + 6 * row + 6] = False
    return free, lb


@dataclass
class FitResult:
    initial_rms_mm: float
    final_rms_mm: float
    iterations: int
    samples: int


def _group_masks(base: bool) -> list[tuple[tuple[str, ...], np.ndarray]]:
    """Independent parameter groups: (fingers, mask over the parameter vector).

    Extended fingers share nothing, so each is fitted alone; base non-thumb fingers share their
    lengths and are fitted together.
    """
    size = 82 if base else 173
    out = []
    if base:
        thumb = np.zeros(size, dtype=bool)
        thumb[[2, 3, 4, 8, 9, 10, *range(29, 38)]] = True
        out.append((("thumb",), thumb))
        out.append((FINGERS[1:], ~thumb))
        return out
    for fi, f in enumerate(FINGERS):
        mk = np.zeros(size, dtype=bool)
        mk[1 + fi] = True
        mk[6 + 3 * fi : 9 + 3 * fi] = True
        start = EXT_ROW_START[fi]
        for row in range(start, start + (3 if fi in (0, 4) else 2)):
            mk[21 + 6 * row : 27 + 6 * row] = True
            mk[93 + 3 * row : 96 + 3 * row] = True
        out.append(((f,), mk))
    return out


def fit(params: Params, m: Measurement, samples: int = 96, seed: int = 0) -> tuple[Params, FitResult]:
    """Least-squares refinement of the continuous kinematic parameters (see module docstring)."""
    base = isinstance(params, BaseParams)
    present = params.present_joints
    q_orig = sample_original(m, samples, seed)
    ok = original_keypoints(m, q_orig)
    qc = np.clip(ok.q_canon, params.joint_lowers, params.joint_uppers)
    v0 = params.to_vector()
    free_all, lb_all = _free_mask_base(params) if base else _free_mask_ext(params)  # type: ignore[arg-type]
    v = v0.copy()
    sq0 = sq1 = 0.0
    n_err = 0
    nfev = 0
    for fingers, group in _group_masks(base):
        free = free_all & group
        if not free.any():
            continue
        fidx = [FINGERS.index(f) for f in fingers]
        jmask = np.zeros(22, dtype=bool)
        for f in fingers:
            jmask[FINGER_SLICES[f]] = True
        jmask &= ~np.isnan(ok.joints[0, :, 0])
        tmask = np.zeros(5, dtype=bool)
        tmask[fidx] = True
        tmask &= ~np.isnan(ok.tips[0, :, 0])
        lb = lb_all[free]
        x0 = np.maximum(v[free], lb)
        ref = v.copy()

        def arrays(x, ref=ref, free=free):
            w = ref.copy()
            w[free] = x
            if base:
                return ext_arrays_from_base(w, present)
            return {"lengths": w[6:21].reshape(5, 3), "origins": w[21:93].reshape(12, 6), "axes": w[93:129].reshape(12, 3)}

        def residuals(x, arrays=arrays, fingers=fingers, jmask=jmask, tmask=tmask, x0=x0):
            J, tips = canonical_keypoints(arrays(x), present, qc, fingers)
            rt = (tips[:, tmask] - ok.tips[:, tmask]).ravel()
            dj = J[:, jmask] - ok.joints[:, jmask]
            ax = ok.axes[:, jmask]
            along = np.sum(dj * ax, axis=-1, keepdims=True) * ax
            # a joint's position along its own axis is kinematically free: weigh it lightly
            rj = JOINT_WEIGHT * ((dj - along) + ALONG_AXIS_WEIGHT * along).ravel()
            return np.concatenate([rt, rj, REG_WEIGHT * (x - x0)])

        r0 = residuals(x0)
        sol = least_squares(residuals, x0, bounds=(lb, np.full_like(lb, np.inf)), method="trf",
                            max_nfev=300, ftol=1e-9, xtol=1e-9, gtol=1e-9)
        v[free] = sol.x
        k = x0.size
        sq0 += float(np.sum(r0[:-k] ** 2))
        sq1 += float(np.sum(sol.fun[:-k] ** 2))
        n_err += int(tmask.sum() + jmask.sum()) * qc.shape[0]
        nfev += int(sol.nfev)
    v = _normalise(v, base)
    new = (BaseParams if base else ExtendedParams).from_vector(np.round(v, DECIMALS) + 0.0)
    rms0 = float(np.sqrt(sq0 / max(n_err, 1)) * 1e3)
    rms1 = float(np.sqrt(sq1 / max(n_err, 1)) * 1e3)
    return new, FitResult(rms0, rms1, nfev, samples)


def _normalise(v: np.ndarray, base: bool) -> np.ndarray:
    v = v.copy()
    if base:
        for s in (slice(32, 35), slice(35, 38)):
            n = np.linalg.norm(v[s])
            if n > 1e-12:
                v[s] /= n
    else:
        axes = v[93:129].reshape(12, 3)
        n = np.linalg.norm(axes, axis=1, keepdims=True)
        axes = np.where(n > 1e-12, axes / np.maximum(n, 1e-12), axes)
        v[93:129] = axes.ravel()
        # wrap rpy into (-pi, pi]
        o = v[21:93].reshape(12, 6)
        o[:, 3:] = (o[:, 3:] + np.pi) % (2 * np.pi) - np.pi
        v[21:93] = o.ravel()
    return v


# ------------------------------------------------------------------------------------------------
# Overrides and the public entry point
# ------------------------------------------------------------------------------------------------
def apply_overrides(params: Params, spec: HandSpec, form: str) -> Params:
    d = params.to_dict()
    for o in spec.overrides_for(form):
        if o.name not in d:
            if o.form is None:
                continue  # a key of the other form
            raise SpecError(f"{spec.source}: override {o.key!r}: no such key in {form} params ({', '.join(d)})")
        if not o.index:
            d[o.name] = o.value
            continue
        tgt = d[o.name]
        try:
            for i in o.index[:-1]:
                tgt = tgt[i]
            tgt[o.index[-1]] = float(o.value)
        except (IndexError, TypeError):
            raise SpecError(f"{spec.source}: override {o.key!r}: index out of range for {o.name!r}") from None
    try:
        return type(params).from_dict(d)
    except ParamsError as exc:
        raise SpecError(f"{spec.source}: overrides make invalid {form} params: {exc}") from None


@dataclass
class ParseResult:
    params: Params
    form: str
    spec: HandSpec
    measurement: Measurement
    initial: Params
    fit: FitResult | None
    notes: list[str]

    @property
    def action_map(self) -> ActionMap:
        return self.measurement.action_map

    @property
    def hand(self) -> OriginalHand:
        return self.measurement.hand


def load_original_for(spec: HandSpec, hands_root: str | Path | None = None) -> OriginalHand:
    path = spec.urdf_path(hands_root)
    if not path.is_file():
        from ohra.errors import AssetsNotFoundError

        raise AssetsNotFoundError(f"{spec.source}: original URDF not found at {path} (set OHRA_HANDS_ROOT)")
    hand = load_urdf(path)
    spec.check_joints(hand.movable_joints)
    return hand


def parse(
    spec: HandSpec | str | Path,
    form: str = "base",
    fit_params: bool = True,
    hands_root: str | Path | None = None,
    hand: OriginalHand | None = None,
) -> ParseResult:
    """Original URDF + spec -> canonical params of ``form`` (``"base"`` or ``"extended"``)."""
    if not isinstance(spec, HandSpec):
        spec = load_spec(spec)
    if form not in ("base", "extended"):
        raise SpecError(f"unknown form {form!r}; expected 'base' or 'extended'")
    spec.form(form)
    if hand is None:
        hand = load_original_for(spec, hands_root)
    else:
        spec.check_joints(hand.movable_joints)
    m = measure(hand, spec, form)
    try:
        init = initial_base(m, spec, form) if form == "base" else initial_extended(m, spec, form)
    except ParamsError as exc:
        raise ParseError(f"{spec.source}: measured {form} parameters are invalid: {exc}") from None
    params: Params = init
    fr = None
    if fit_params:
        params, fr = fit(init, m, spec.fit_samples, spec.fit_seed)
    else:
        params = type(init).from_vector(np.round(_normalise(init.to_vector(), form == "base"), DECIMALS) + 0.0)
    params = apply_overrides(params, spec, form)
    notes = list(m.notes) + [f"override {o.key} = {o.value}: {o.reason}" for o in spec.overrides_for(form)]
    return ParseResult(params, form, spec, m, init, fr, notes)


__all__ = [
    "parse", "measure", "fit", "ParseResult", "FitResult", "Measurement", "ParseWarning",
    "canonical_keypoints", "original_keypoints", "sample_original", "line_distance", "apply_overrides",
]
