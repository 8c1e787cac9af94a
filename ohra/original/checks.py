"""Guard rails: a spec whose palm frame or signs contradict the canonical conventions is an error.

The canonical palm frame has ``+x`` along the palm normal (the side the fingers curl toward),
``+z`` finger-forward and ``+y`` toward the thumb of a right hand (DESIGN.md, Conventions). A palm
origin rotated by pi about z still gives a kinematically valid canonical hand, and flipping the
signs that the axis checks ask for even reproduces the fidelity numbers — but the result is the
mirror image of the convention (a right hand called left, fingers curling toward -x, flexion
negative). These checks look at the measured fingers (non-thumb fingers with a flexion joint):

* finger direction: fingers must point along ``+z`` of the palm frame;
* curl direction: flexing a finger into its range must move its tip toward ``+x`` (not ``-x``: a frame turned
  by pi; nor within 45 deg of ``+-y``: a frame turned by about pi/2 about z);
* flexion range: the canonical flexion range lies mostly on the positive side (fingers flex far
  more than they hyperextend);
* finger by finger: positive flexion curls each finger toward ``+x`` and no finger's range is mostly
  negative while the others' are positive (one finger whose flexion signs were all flipped together
  passes the majority rules and the per-slot axis checks, and the extended fit reproduces it exactly);

and when one fails they say which of palm frame, signs or handedness is wrong.
"""

from __future__ import annotations

import re

import numpy as np

from ohra.canonical.params import FINGERS, JOINT_INDEX
from ohra.errors import SpecError
from ohra.original.measure import Measurement
from ohra.original.spec import HandSpec

ORDER_TOLERANCE = 0.010  # m: a finger base this far on the wrong side of a later finger's is out of order (the
# registered hands keep 17-46 mm between neighbours; DG-5F's cupping little finger sits 2.5 mm inside its ring finger)
THUMB_SIDE_MIN = 0.005  # m: a thumb base nearer the fingers' mean y than this does not tell which side it is on
MIN_MID = 0.05  # rad: a flexion range whose middle is this close to 0 says nothing about its sign
CURL_COS = float(np.cos(np.radians(45.0)))  # a finger curling more than 45 deg away from +x (in the x-y plane): frame turned
TILT_COS = float(np.cos(np.radians(45.0)))  # most fingers more than 45 deg off +z: palm_origin tilted (roll / pitch)


def _flexion_slots(m: Measurement, f: str) -> list[str]:
    """Mapped movable j2-j4 slots of finger ``f`` whose signed axis is its flexion axis (within ~25
    deg); none when the finger's flexion axes disagree in sign (a single slot's sign is wrong: the
    axis checks of :mod:`ohra.original.estimate` name it)."""
    fm = m.fingers[f]
    out = []
    for s in fm.slots:
        if s.split("_joint")[1] not in ("2", "3", "4"):
            continue
        d = float(fm.a[s] @ fm.y)
        if d < -0.9:
            return []
        k = JOINT_INDEX[s]
        if d > 0.9 and m.upper[k] > m.lower[k]:
            out.append(s)
    return out


def _named_side(spec: HandSpec) -> str | None:
    """'right' / 'left' when the spec's name or URDF file says so, else None."""
    text = f"{spec.name} {spec.urdf}".lower()
    sides = {s for s in ("right", "left") if re.search(rf"(^|[^a-z]){s}|_{s[0]}(\.|_|$)", text)}
    return sides.pop() if len(sides) == 1 else None


def _thumb_side(m: Measurement) -> str | None:
    """'right' when the thumb base sits on +y of the palm frame, 'left' on -y, None without a thumb."""
    if "thumb" not in m.fingers:
        return None
    fm = m.fingers["thumb"]
    y = float(fm.p[fm.slots[0]][1])
    return None if abs(y) < 1e-4 else ("right" if y > 0 else "left")


def check_palm_frame(m: Measurement, spec: HandSpec, form: str) -> list[str]:
    """Raise :class:`SpecError` when the fingers contradict the palm frame convention; else notes.

    Returns notes (e.g. handedness differing from the name when everything else is consistent).
    When movable joints lie between the URDF's root and the palm (an arm, a wrist), the error says
    so: a palm_origin written for the hand alone is then off by the arm.
    """
    try:
        return _check_palm_frame(m, spec, form)
    except SpecError as exc:
        hint = arm_hint(m, spec)
        if not hint:
            raise
        raise SpecError(f"{exc} ({hint})") from None


def arm_hint(m: Measurement, spec: HandSpec) -> str:
    """'' or a sentence naming the movable joints between the URDF's root and the palm link (an arm
    or a wrist under a palm_origin written for the hand alone), and ``root_link:`` as the way out."""
    above = [j.name for l in m.hand.ancestors(m.palm_link)[:-1] if (j := m.hand.parent_joint[l]).type != "fixed"][::-1]
    if not above or spec.root_link is not None:
        return ""
    return (f"{len(above)} movable joint(s) lie between the URDF's root {m.hand.root!r} and the palm link "
            f"{m.palm_link!r}: {', '.join(above[:4])}{' ...' if len(above) > 4 else ''}; if that is an arm, name the "
            "hand's own root link with root_link: and give palm_origin in its frame")


def _offset_hint(m: Measurement, spec: HandSpec, form: str, fingers: list[str]) -> str:
    """'' or a clause naming the nonzero offsets on ``fingers``' slots: a wrong offset bends a finger at canonical zero
    or shifts its range, which the frame and sign rules read as a turned palm frame or reversed signs (an offset
    written as the angle at which the joint is straight, not its negative, sent users round between those two)."""
    fs = spec.form(form)
    with_offset = [(s, fs.slots[s]) for f in fingers for s in m.fingers[f].slots if abs(fs.slots[s].offset) > 0.0]
    if not with_offset:
        return ""
    shown = ", ".join(f"{s} (joint {sm.name!r}, sign {sm.sign:+g}, offset {sm.offset:+g})" for s, sm in with_offset[:4])
    return (f"; unless the offsets are wrong ({shown}{' ...' if len(with_offset) > 4 else ''}): q_canon = sign * q_orig + "
            "offset and canonical zero is a straight finger, so a joint straight at original angle a takes offset = "
            "-sign * a")


def _check_palm_frame(m: Measurement, spec: HandSpec, form: str) -> list[str]:
    fingers = [f for f in FINGERS[1:] if f in m.fingers]
    where = f"{spec.source}: forms.{form}"
    back = [f for f in fingers if float(m.fingers[f].z[2]) < 0]
    if fingers and len(back) > len(fingers) / 2:
        raise SpecError(f"{where}: the fingers ({', '.join(back)}) point toward -z of the palm frame: palm_origin "
                        f"is rotated (z must point from the wrist toward the fingertips){_offset_hint(m, spec, form, back)}")
    tilted = [f for f in fingers if f not in back and float(m.fingers[f].z[2]) < TILT_COS]
    if fingers and len(tilted) > len(fingers) / 2:
        # between "along +z" and "toward -z": a roll or pitch in palm_origin; the parse went through with fingertip
        # errors of centimetres (registered hands: every finger within 32 deg of +z, most within 13)
        d = np.mean([m.fingers[f].z for f in tilted], axis=0)
        off = float(np.degrees(np.arccos(np.clip(d[2] / max(float(np.linalg.norm(d)), 1e-12), -1.0, 1.0))))
        toward = ", ".join(f"{'+' if d[k] > 0 else '-'}{'xy'[k]}" for k in (0, 1) if abs(d[k]) > 0.25 * np.linalg.norm(d[:2]))
        raise SpecError(f"{where}: the fingers ({', '.join(tilted)}) point {off:.0f} deg away from +z of the palm frame "
                        f"(toward {toward}): palm_origin is tilted (its roll or pitch); +z must point from the wrist along "
                        f"the fingers{_offset_hint(m, spec, form, tilted)}")
    ahead = [(f, float(m.fingers[f].p[m.fingers[f].slots[0]][2])) for f in fingers if m.fingers[f].slots]
    below = [(f, z) for f, z in ahead if z < 0]
    if ahead and len(below) > len(ahead) / 2:
        raise SpecError(f"{where}: the finger bases ({', '.join(f'{f} z = {1e3 * z:.0f} mm' for f, z in below)}) lie behind "
                        "the palm frame's origin: palm_origin must sit at the wrist end of the palm, below the knuckles "
                        "along +z (check its xyz, in metres)")
    curl, mids, curl_dirs = [], [], []
    for f in fingers:
        slots = _flexion_slots(m, f)
        mid = [0.5 * (m.lower[JOINT_INDEX[s]] + m.upper[JOINT_INDEX[s]]) for s in slots]
        mid = [v for v in mid if abs(v) > MIN_MID]
        if not mid:
            continue
        sign = 1.0 if np.mean(mid) > 0 else -1.0
        mids.append((f, sign))
        x_f = np.cross(m.fingers[f].y, m.fingers[f].z)  # where +flexion moves the tip
        curl.append((f, float(sign * x_f[0])))
        d = sign * x_f[:2]
        curl_dirs.append((f, d / max(float(np.linalg.norm(d)), 1e-12)))
    bad_curl = [f for f, c in curl if c < 0]
    neg = [f for f, sgn in mids if sgn < 0]
    named, thumb = _named_side(spec), _thumb_side(m)
    side = [(f, d) for f, d in curl_dirs if abs(d[0]) < CURL_COS]  # within 45 deg of +-y (not -x: turned by pi)
    if curl_dirs and len(side) > len(curl_dirs) / 2:
        # a palm frame turned by ~90 deg about z: the fingers curl toward +-y, which neither check above sees
        # (each finger still points along +z and flexes into positive angles)
        phi = float(np.arctan2(np.mean([d[1] for _, d in side]), np.mean([d[0] for _, d in side])))
        raise SpecError(
            f"{where}: fingers {', '.join(f for f, _ in side)} curl {np.degrees(abs(phi)):.0f} deg away from +x of the palm "
            f"frame (toward {'+' if phi > 0 else '-'}y): palm_origin is rotated about z; +x must be the palm normal, the "
            f"side the fingers curl toward. Rotate palm_origin about its z axis by {phi:+.4f} rad (with rpy [0, 0, yaw]: "
            f"yaw {phi:+.4f})"
        )
    if curl and len(bad_curl) > len(curl) / 2:
        if neg and len(neg) == len(bad_curl):
            what = ("the flexion joints' canonical ranges are negative: their signs were flipped to satisfy the axis "
                    "checks, which hides a palm frame whose +x points to the back of the hand")
        else:
            what = "the palm normal +x points to the back of the hand"
        mirror = (f"; the thumb sits on {'+' if thumb == 'right' else '-'}y, i.e. a {thumb} hand by the canonical "
                  f"convention, although the hand is named {named}") if named and thumb and named != thumb else ""
        fix = "undo those sign flips" if neg and len(neg) == len(bad_curl) else "keep the joints' signs (flexion positive)"
        raise SpecError(
            f"{where}: fingers {', '.join(bad_curl)} curl toward -x of the palm frame: {what}{mirror}. Rotate palm_origin "
            f"by pi about z (rpy yaw + 3.1416) and {fix}"
        )
    if neg and len(neg) > len(mids) / 2:
        raise SpecError(f"{where}: finger{'s' if len(neg) > 1 else ''} {', '.join(neg)} flex{'' if len(neg) > 1 else 'es'} "
                        f"toward negative canonical angles: the signs of {'their' if len(neg) > 1 else 'its'} flexion joints "
                        f"are reversed (canonical flexion is positive, toward the palm normal +x){_offset_hint(m, spec, form, neg)}")
    # the rules above need most fingers to agree; one finger (of two, three, four) whose flexion signs were all
    # flipped together passes them, and the per-slot axis checks too (its own flexion axis flips with its signs),
    # while the fit reproduces the original exactly with positive angles opening that finger
    spec_form = spec.form(form)

    def named_slots(fs: list[str]) -> str:
        # every mapped slot of the finger turning about its flexion axis (j1 too: LEAP's extended form flexes there)
        def turning(f: str) -> list[str]:
            fm = m.fingers[f]
            return [s for s in fm.slots if float(fm.a[s] @ fm.y) > 0.9]

        return "; ".join(f"{f}: " + ", ".join(f"{s} (joint {spec_form.slots[s].name!r}, sign {spec_form.slots[s].sign:+g})"
                                               for s in turning(f)) for f in fs)

    def verb(fs: list[str], v: str) -> str:
        return v if len(fs) > 1 else v + ("es" if v.endswith("x") else "s")

    if neg:
        pos = [f for f, sgn in mids if sgn > 0]
        raise SpecError(f"{where}: finger{'s' if len(neg) > 1 else ''} {', '.join(neg)} flex{'' if len(neg) > 1 else 'es'} "
                        f"toward negative canonical angles while {', '.join(pos)} {verb(pos, 'flex')} toward positive ones: the signs of "
                        f"{'their' if len(neg) > 1 else 'its'} flexion joints are reversed ({named_slots(neg)}); flip each "
                        f"of those signs (canonical flexion is positive, toward the palm normal +x){_offset_hint(m, spec, form, neg)}")
    # what is left to check finger by finger: positive flexion must curl the tip toward +x (this also covers fingers
    # whose range is symmetric, e.g. D'Claw's, which say nothing through their range's sign)
    flexing = [f for f in fingers if _flexion_slots(m, f)]
    opening = [f for f in flexing if float(np.cross(m.fingers[f].y, m.fingers[f].z)[0]) < 0]
    closing = [f for f in flexing if f not in opening]
    if opening:
        if closing:
            raise SpecError(f"{where}: positive flexion curls finger{'s' if len(opening) > 1 else ''} {', '.join(opening)} "
                            f"toward -x of the palm frame (the back of the hand) while {', '.join(closing)} {verb(closing, 'curl')} toward +x: "
                            f"the signs of {'their' if len(opening) > 1 else 'its'} flexion joints are reversed "
                            f"({named_slots(opening)}); flip each of those signs{_offset_hint(m, spec, form, opening)}")
        raise SpecError(f"{where}: positive flexion curls every finger ({', '.join(opening)}) toward -x of the palm frame: "
                        "either the palm normal +x points to the back of the hand (rotate palm_origin by pi about z, rpy "
                        f"yaw + 3.1416) or every flexion sign is reversed{_offset_hint(m, spec, form, opening)}")
    _check_finger_order(m, spec, form, where)
    if named and thumb and named != thumb:
        return [f"check: the thumb sits on the {thumb}-hand side (y {'>' if thumb == 'right' else '<'} 0) of the palm "
                f"frame although the hand is named {named}"]
    return []


def _check_finger_order(m: Measurement, spec: HandSpec, form: str, where: str) -> None:
    """Raise when the fingers' bases are not ordered index, middle, ring, little away from the thumb side of the
    palm (+y for a thumb on +y): a spec that maps a URDF finger to the wrong canonical finger passes every
    other check and fits its URDF as well as the right spec, but hands the VAE and the grasp model a hand whose
    fingers have other identities."""
    if "thumb" not in m.fingers or not m.fingers["thumb"].slots:
        return
    th = m.fingers["thumb"]
    ys = {f: float(fm.p[fm.slots[0]][1]) for f in FINGERS[1:] if (fm := m.fingers.get(f)) is not None and fm.slots}
    if len(ys) < 2:
        return
    # the thumb's side of the fingers, not of the palm origin: an origin set off the hand's centre line moves every y
    y_thumb = float(th.p[th.slots[0]][1]) - float(np.mean(list(ys.values())))
    if abs(y_thumb) < THUMB_SIDE_MIN:  # Barrett, Dex3: the thumb opposes the fingers on their centre line
        return
    side = 1.0 if y_thumb > 0 else -1.0
    order = [f for f in FINGERS[1:] if f in ys]
    bad = [(a, b) for i, a in enumerate(order) for b in order[i + 1:] if side * (ys[a] - ys[b]) < -ORDER_TOLERANCE]
    if not bad:
        return
    spec_form = spec.form(form)
    a, b = bad[0]
    first = {f: spec_form.slots[m.fingers[f].slots[0]].name for f in ys}
    raise SpecError(
        f"{where}: the fingers are out of order across the palm: {a} (base y = {1e3 * ys[a]:+.1f} mm, joint "
        f"{first[a]!r}) lies {abs(1e3 * (ys[a] - ys[b])):.1f} mm farther from the thumb side ({'+' if side > 0 else '-'}y) "
        f"than {b} (y = {1e3 * ys[b]:+.1f} mm, joint {first[b]!r}); index, middle, ring and little go away from the "
        f"thumb in that order ({', '.join(f'{f} {1e3 * ys[f]:+.1f} mm' for f in order)}): check which URDF finger each "
        "canonical finger's joints name")


__all__ = ["check_palm_frame"]
