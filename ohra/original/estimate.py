"""Initial canonical parameters straight from a :class:`~ohra.original.measure.Measurement`.

* Axes the template fixes (finger flexion +y, abduction +x, thumb j3 +x, j4/j5 +y) are checked
  against the slot signs: an opposite axis is a :class:`SpecError` telling the fix; a deviation over
  ~25 degrees is noted as an approximation.
* Link lengths are distances between consecutive stations (collapsed stations follow the
  templates' rules); the **distal length** reaches the fingertip point.
* Finger radii are capped so every capsule is at least as long as its diameter.

Extended: each finger keeps its own frame (rows of ``joint_origins`` in the finger's frame, free
axes). Base: palm-aligned fingers sharing the non-thumb segment lengths (their mean).
"""

from __future__ import annotations

import numpy as np

from ohra.canonical.params import (
    EXT_ROW_START,
    FINGER_SLICES,
    FINGERS,
    JOINT_NAMES,
    BaseParams,
    ExtendedParams,
    link_presence,
)
from ohra.errors import ParseError, SpecError
from ohra.original.measure import FingerMeasure, Measurement, unit
from ohra.original.spec import HandSpec
from ohra.transforms import matrix_to_rpy

MIN_CAPSULE_MARGIN = 1e-5  # m, capsule length >= diameter + margin
EX, EY = np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])


def frame(y: np.ndarray, z: np.ndarray) -> np.ndarray:
    """(3,3) rotation with columns x = y x z, y, z."""
    return np.column_stack([np.cross(y, z), y, z])


def stations_filled(st: list[np.ndarray | None]) -> list[np.ndarray]:
    """Fill stations without a joint with the next defined one (templates collapse absent offsets)."""
    out: list[np.ndarray | None] = list(st)
    for k in range(len(out) - 2, -1, -1):
        if out[k] is None:
            out[k] = out[k + 1]
    return out  # type: ignore[return-value]


def check_axis(spec: HandSpec, form: str, slot: str, a: np.ndarray, expected: np.ndarray, what: str, notes: list[str]) -> None:
    """Raise :class:`SpecError` when ``a`` opposes the template's ``expected`` axis; note deviations."""
    d = float(a @ expected)
    name = spec.form(form).slots[slot].name
    if d < -0.5:
        sign = spec.form(form).slots[slot].sign
        raise SpecError(
            f"{spec.source}: forms.{form} slot {slot!r} (joint {name!r}): with sign {sign:+g} its axis points opposite to "
            f"the canonical {what} axis (dot {d:+.2f}); use sign {-sign:+g}"
        )
    if d < 0.9:
        msg = f"{slot} (joint {name!r}) axis deviates from the canonical {what} axis by {np.degrees(np.arccos(np.clip(d, -1, 1))):.0f} deg"
        notes.append("approximation: " + msg)


def _little_metacarpal(fm: FingerMeasure, slot: str) -> np.ndarray:
    """Rotation of the little finger's metacarpal (joint0) frame: y its axis, z the finger direction."""
    if slot not in fm.p:
        return np.eye(3)
    ye = fm.a[slot]
    return frame(ye, unit(fm.z - (fm.z @ ye) * ye))


# -- extended --------------------------------------------------------------------------------------
def _thumb_extended(m: Measurement, spec: HandSpec, form: str, fm: FingerMeasure, origins, axes, lengths) -> None:
    """Thumb rows 0-2 of origins/axes and lengths[0] (in place)."""
    R = frame(fm.y, fm.z)
    st = stations_filled(fm.stations)
    names = JOINT_NAMES[FINGER_SLICES["thumb"]]
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
            check_axis(spec, form, s, fm.a[s], fm.y, "thumb flexion (+y)", m.notes)
    lengths[0] = (prox, (st[2] - st[1]) @ fm.z, (st[3] - st[2]) @ fm.z)
    if not (j1 or j2):
        # the template always adds the proximal length to the j3 origin: cancel it
        origins[2, 2] -= lengths[0, 0]


def _finger_extended(m: Measurement, spec: HandSpec, form: str, fi: int, f: str, origins, axes, lengths) -> None:
    """Rows of a non-thumb finger (little: also its metacarpal row 9) and lengths[fi] (in place)."""
    fm = m.fingers[f]
    R = frame(fm.y, fm.z)
    st = stations_filled(fm.stations)
    names = JOINT_NAMES[FINGER_SLICES[f]]
    row = EXT_ROW_START[fi]
    if f == "little":
        Re = _little_metacarpal(fm, names[0])
        if names[0] in fm.p:
            origins[9, :3], origins[9, 3:] = fm.p[names[0]], matrix_to_rpy(Re)
        axes[9] = (0.0, 1.0, 0.0)
        row = 10
        names = names[1:]
    sj1, sj2 = names[0], names[1]
    j1, j2 = sj1 in fm.p, sj2 in fm.p
    p1 = fm.p.get(sj1, st[0])
    p2 = fm.p.get(sj2, p1)
    origins[row, :3], origins[row, 3:] = p1, matrix_to_rpy(Re.T @ R if f == "little" else R)
    jo1 = R.T @ (p2 - p1) if (j1 or j2) else np.zeros(3)
    origins[row + 1, :3] = jo1
    axes[row] = R.T @ fm.a[sj1] if j1 else (1.0, 0.0, 0.0)
    axes[row + 1] = R.T @ fm.a[sj2] if j2 else (0.0, 1.0, 0.0)
    # j1 / j2 are free axes here (either may be the MCP flexion: LEAP and Sharpa flex at j1), but a flexion
    # axis opposed to the finger's (a flipped sign) would make positive canonical angles extend the finger
    for s in (sj1, sj2):
        if s in fm.a and float(fm.a[s] @ fm.y) < -0.5:
            check_axis(spec, form, s, fm.a[s], fm.y, f"{f} flexion (+y)", m.notes)
    for s in names[2:]:
        if s in fm.a:
            check_axis(spec, form, s, fm.a[s], fm.y, f"{f} flexion (+y)", m.notes)
    prox = float(jo1[2] + (st[1] - p2) @ fm.z) if (j1 or j2) else 0.0
    lengths[fi] = (prox, (st[2] - st[1]) @ fm.z, (st[3] - st[2]) @ fm.z)


def initial_extended(m: Measurement, spec: HandSpec, form: str = "extended") -> ExtendedParams:
    """Extended parameters straight from the measurements (before any fit)."""
    present = (m.lower != 0) | (m.upper != 0)
    lengths = np.zeros((5, 3))
    origins = np.zeros((12, 6))
    axes = np.zeros((12, 3))
    radii = np.zeros(5)
    for fi, f in enumerate(FINGERS):
        if f not in m.fingers:
            continue
        radii[fi] = m.finger_radius[f]
        if f == "thumb":
            _thumb_extended(m, spec, form, m.fingers[f], origins, axes, lengths)
        else:
            _finger_extended(m, spec, form, fi, f, origins, axes, lengths)
    return _finish_extended(m, present, radii, lengths, origins, axes)


def _finish_extended(m: Measurement, present, radii, lengths, origins, axes) -> ExtendedParams:
    """Cap radii by the shortest present segment, clean lengths and axes, build the params."""
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
    n = np.linalg.norm(axes, axis=1, keepdims=True)
    axes = np.where(n > 0, axes / np.maximum(n, 1e-12), axes)
    return ExtendedParams(
        palm_radius=m.palm_radius,
        finger_radii=radii,
        finger_lengths=np.maximum(lengths, 0.0),
        joint_origins=origins,
        joint_axes=axes,
        joint_lowers=m.lower.copy(),
        joint_uppers=m.upper.copy(),
    )


# -- base ------------------------------------------------------------------------------------------
def _thumb_base(m: Measurement, spec: HandSpec, form: str, fm: FingerMeasure, lens: list[float]):
    """Thumb position, rpy, (2,3) axes and lengths of the base form."""
    names = JOINT_NAMES[FINGER_SLICES["thumb"]]
    R = frame(fm.y, fm.z)
    thumb_axes = np.zeros((2, 3))
    for k in range(2):
        if names[k] in fm.a:
            thumb_axes[k] = R.T @ fm.a[names[k]]
    if names[2] in fm.a:
        check_axis(spec, form, names[2], fm.a[names[2]], R[:, 0], "thumb j3 (+x of the thumb frame)", m.notes)
    for s in names[3:]:
        if s in fm.a:
            check_axis(spec, form, s, fm.a[s], fm.y, "thumb flexion (+y of the thumb frame)", m.notes)
    return stations_filled(fm.stations)[0], matrix_to_rpy(R), thumb_axes, np.array(lens)


def _base_radius(m: Measurement, links, thumb_len: np.ndarray, finger_len: np.ndarray, spec: HandSpec | None = None) -> float:
    """The shared finger radius: median of the measured ones, capped by the shortest present segment."""
    r = float(np.median([m.finger_radius[f] for f in m.fingers]))
    segment = ("proximal", "middle", "distal")
    present = [(thumb_len[k], f"thumb {segment[k]}") for k in range(3) if links["thumb"][k]]
    present += [(finger_len[k], f"non-thumb {segment[k]} (shared by the fingers in the base form)")
                for k in range(3) if any(links[f][k] for f in FINGERS[1:])]
    if present:
        length, which = min(present)
        r = min(r, (length - MIN_CAPSULE_MARGIN) / 2.0)
        if r <= 1e-3:
            where = f"{spec.source}: forms.base: " if spec is not None else ""
            raise ParseError(f"{where}the {which} segment is only {length * 1e3:.2f} mm long: check the joint mapping "
                             "(a slot mapped to a joint of another finger or station, e.g. the thumb's rotation on "
                             "thumb_joint3 instead of thumb_joint1)")
    return r


def initial_base(m: Measurement, spec: HandSpec, form: str = "base") -> BaseParams:
    """Base parameters straight from the measurements (palm-aligned fingers, shared lengths)."""
    present = (m.lower != 0) | (m.upper != 0)
    links = link_presence(present)
    finger_xyz = np.zeros((5, 3))
    thumb_rpy, thumb_axes, thumb_len = np.zeros(3), np.zeros((2, 3)), np.zeros(3)
    extra = np.zeros(6)
    seg_lens: list[list[float]] = [[], [], []]
    for fi, f in enumerate(FINGERS):
        if f not in m.fingers:
            continue
        fm = m.fingers[f]
        st = stations_filled(fm.stations)
        lens = [float(np.linalg.norm(st[k + 1] - st[k])) for k in range(3)]
        names = JOINT_NAMES[FINGER_SLICES[f]]
        if f == "thumb":
            finger_xyz[0], thumb_rpy, thumb_axes, thumb_len = _thumb_base(m, spec, form, fm, lens)
            continue
        if f == "little":
            if names[0] in fm.p:
                extra = np.concatenate([fm.p[names[0]], matrix_to_rpy(_little_metacarpal(fm, names[0]))])
            names = names[1:]
        finger_xyz[fi] = st[0]
        if names[0] in fm.a:
            check_axis(spec, form, names[0], fm.a[names[0]], EX, f"{f} abduction (+x)", m.notes)
        for s in names[1:]:
            if s in fm.a:
                check_axis(spec, form, s, fm.a[s], EY, f"{f} flexion (+y)", m.notes)
        for k in range(3):
            if links[f][k]:
                seg_lens[k].append(lens[k])
    finger_len = np.array([float(np.mean(s)) if s else 0.0 for s in seg_lens])
    return BaseParams(
        palm_radius=m.palm_radius,
        finger_radius=_base_radius(m, links, thumb_len, finger_len, spec),
        finger_lengths=np.vstack([thumb_len, finger_len]),
        finger_xyz=finger_xyz,
        little_extra_origin=extra,
        thumb_rpy=thumb_rpy,
        thumb_axes=thumb_axes,
        joint_lowers=m.lower.copy(),
        joint_uppers=m.upper.copy(),
    )


__all__ = ["initial_base", "initial_extended", "check_axis", "MIN_CAPSULE_MARGIN"]
