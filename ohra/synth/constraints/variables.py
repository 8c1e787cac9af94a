"""Decision variables, parameters and the hand's geometry in the object frame, shared by every family.

Variables ``x = [t (3), w (3), q (nq), f (3 * n_contacts)]``: palm translation ``t`` (object frame, m),
a rotation-vector increment ``w`` about the sampled orientation ``R0`` (``R = R0 Exp(w)``), the movable
joints ``q`` (rad, canonical order) and one force per contact (object frame, normalised units: the
minimum normal force is 1). Parameters ``p = [vec(R0) (9, column-major), q_pref (nq)]``.

The hand is seen by the constraints as spheres: each finger capsule's two end spheres (and a middle
sphere on links whose core is at least 2 cm long), and spheres of the palm's half-thickness over its
disc. Contacts are the end sphere of the last present segment of every present finger, plus a point
of the palm face when the palm is a contact (hands with fewer than three fingers, whose point
contacts cannot resist every wrench, or ``NLPSettings.palm_contact``).
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ohra.canonical.kinematics import SEGMENTS, HandModel
from ohra.canonical.urdfgen import palm_geometry
from ohra.synth.constraints.sdf import SdfQuery
from ohra.synth.fk import frame_transforms, rotvec_matrix

LONG_CORE = 0.02  # m: capsules with a core segment this long get a middle sphere


@dataclass(frozen=True)
class Sphere:
    """A sphere of the hand's surface: centre (3x1 SX, object frame, m) and radius (m).

    ``finger`` is the finger index (0 thumb .. 4 little; -1 the palm), ``link`` the link name and
    ``end`` where on the capsule's core segment the centre sits (0 start, 1 end, 2 middle).
    """

    centre: ca.SX
    radius: float
    finger: int
    link: str
    end: int


@dataclass(frozen=True)
class Contact:
    """A contact site: sphere ``centre`` and ``radius`` (palm: a point of its face, radius 0), the
    outward object ``normal`` at the centre, the contact ``point`` ``centre - radius * normal`` (object
    frame, m) and the ``force`` the hand applies to the object there (3x1, normalised units)."""

    centre: ca.SX
    radius: float
    normal: ca.SX
    point: ca.SX
    force: ca.SX


@dataclass(frozen=True)
class GraspVariables:
    """Symbols of one grasp NLP and the hand geometry as expressions of them (see module docstring).

    ``clearance_spheres`` must stay clear of the object, ``palm_spheres`` too (or may touch it when
    the palm is a contact), ``pair_spheres`` of different fingers must stay apart.
    """

    t: ca.SX
    w: ca.SX
    q: ca.SX
    f: ca.SX
    R0: ca.SX
    q_pref: ca.SX
    R: ca.SX
    movable: np.ndarray  # canonical indices of the movable joints (the order of q)
    sdf: SdfQuery
    contacts: tuple[Contact, ...]
    contact_links: tuple[str, ...]
    palm_contact: bool
    clearance_spheres: tuple[Sphere, ...]
    palm_spheres: tuple[Sphere, ...]
    pair_spheres: tuple[Sphere, ...]
    # every finger capsule's core ends (start, end: 3x1 SX, object frame, m), radius [m] and finger
    # index, in ``hand.capsule_specs`` order (the exact finger-pair rows separate these)
    capsules: tuple[tuple[ca.SX, ca.SX, float, int], ...] = ()

    @property
    def x(self) -> ca.SX:
        return ca.vertcat(self.t, self.w, self.q, self.f)

    @property
    def p(self) -> ca.SX:
        return ca.vertcat(ca.reshape(self.R0, 9, 1), self.q_pref)


def contact_links(hand: HandModel) -> tuple[str, ...]:
    """The last present segment of every present finger, in finger order."""
    last: dict[int, tuple[int, str]] = {}
    for link, fi, _, _ in hand.capsule_specs:
        seg = SEGMENTS.index(link.split("_")[1])
        if fi not in last or seg > last[fi][0]:
            last[fi] = (seg, link)
    return tuple(last[f][1] for f in sorted(last))


def grasp_variables(hand: HandModel, sdf: SdfQuery, palm_contact: bool = False, middle_spheres: str = "all") -> GraspVariables:
    """Variables and geometry of a grasp of ``hand`` on the object behind ``sdf``.

    ``palm_contact`` makes the palm a contact also for hands with three or more fingers;
    ``middle_spheres`` ("all", "fingertips", "none") says which long links' middle spheres enter the
    finger-pair constraints (every long link's middle is always kept clear of the object).
    """
    movable = np.flatnonzero(hand.movable_joints)
    tips = contact_links(hand)
    palm_contact = len(tips) < 3 or palm_contact
    n_c = len(tips) + (1 if palm_contact else 0)
    t, w, q = ca.SX.sym("t", 3), ca.SX.sym("w", 3), ca.SX.sym("q", len(movable))
    f, R0, q_pref = ca.SX.sym("f", 3 * n_c), ca.SX.sym("R0", 3, 3), ca.SX.sym("q_pref", len(movable))
    q_full = ca.SX.zeros(22)
    fixed = hand.neutral()  # absent and fixed joints sit at 0 clamped into their limits
    for k in range(22):
        q_full[k] = fixed[k]
    for i, k in enumerate(movable):
        q_full[int(k)] = q[i]
    R = R0 @ rotvec_matrix(w)
    clear, pairs, contacts, capsules = _finger_spheres(hand, q_full, R, t, sdf, tips, middle_spheres)
    palm, palm_site = _palm_spheres(hand, R, t)
    if palm_contact:
        contacts.append((palm_site, 0.0, sdf.normal(palm_site)))
    forces = [f[3 * i : 3 * i + 3] for i in range(n_c)]
    sites = tuple(Contact(c, r, n, c - r * n if r else c, fi) for (c, r, n), fi in zip(contacts, forces))
    return GraspVariables(t, w, q, f, R0, q_pref, R, movable, sdf, sites, tips, palm_contact, tuple(clear), tuple(palm), tuple(pairs),
                          tuple(capsules))


def _finger_spheres(hand: HandModel, q_full: ca.SX, R: ca.SX, t: ca.SX, sdf: SdfQuery, tips: tuple[str, ...], middle_spheres: str):
    """(clearance spheres, pair spheres, contact (centre, radius, normal) list, core ends) of every
    finger capsule."""
    caps = hand.capsule_specs
    poses = dict(zip([c[0] for c in caps], frame_transforms(hand, q_full, [c[0] for c in caps]))) if caps else {}
    clear: list[Sphere] = []
    pairs: list[Sphere] = []
    contacts: list[tuple[ca.SX, float, ca.SX]] = []
    capsules: list[tuple[ca.SX, ca.SX, float, int]] = []
    for link, fi, r, L in caps:
        Rl, pl = poses[link]
        a = R @ (pl + Rl @ ca.SX([0, 0, r])) + t
        b = R @ (pl + Rl @ ca.SX([0, 0, L - r])) + t
        capsules.append((a, b, r, fi))
        long = L - 2 * r >= LONG_CORE
        mid = 0.5 * (a + b)
        ends = [(a, 0), (mid, 2), (b, 1)] if long else [(a, 0), (b, 1)]
        if link in tips:
            contacts.append((b, r, sdf.normal(b)))
            ends = ends[:-1]  # the contact sphere touches the object instead
        clear += [Sphere(c, r, fi, link, e) for c, e in ends]
        pairs += [Sphere(a, r, fi, link, 0), Sphere(b, r, fi, link, 1)]
        if long and (middle_spheres == "all" or (middle_spheres == "fingertips" and link in tips)):
            pairs.append(Sphere(mid, r, fi, link, 2))  # long links can cross mid-segment
    return clear, pairs, contacts, capsules


def _palm_spheres(hand: HandModel, R: ca.SX, t: ca.SX) -> tuple[list[Sphere], ca.SX]:
    """Spheres of the palm's half-thickness over its disc (a 4x4 grid clipped to the disc), and the
    palm's contact site: the centre of its face, half a thickness out along the palm normal."""
    R_palm, depth = palm_geometry(hand.params)
    pr = depth / 2.0
    out = []
    for y in np.linspace(-(R_palm - pr), R_palm - pr, 4):
        for z in np.linspace(pr, 2 * R_palm - pr, 4):
            if y * y + (z - R_palm) ** 2 <= (R_palm - pr) ** 2 + 1e-9:
                out.append(Sphere(R @ ca.SX([0.0, y, z]) + t, pr, -1, "palm", 0))
    return out, R @ ca.SX([depth / 2.0, 0.0, R_palm]) + t
