"""How well a canonical hand reproduces its original: joint, fingertip and surface errors.

For a hand and a form, N original configurations are sampled uniformly within the limits of the
*actuated* joints inside the hand (seeded): the joints that drive a slot, and those that drive none
but move links below the palm (which the canonical hand cannot follow: each is named in the notes as
an approximation, and its motion counts in the errors). Coupled joints follow their drivers (URDF
``<mimic>`` joints through the URDF itself, declared couplings through the action map). Each
configuration is mapped to canonical with the hand's :class:`ohra.ActionMap`, and both hands are
compared in the canonical palm frame:

* **joints**: distance from each canonical joint origin to the mapped original joint's axis line
  (a revolute joint's position along its own axis has no kinematic meaning); ``joint_origins``
  reports the plain distance between the original child-frame origin and the canonical joint origin.
* **tips**: canonical tip frame vs the *true* fingertip of the original finger: the end of the
  finger's geometry over every link it moves beyond its last mapped joint (links fixed to it and
  links moved by mimic or unmapped joints; collision geometry, else visual) at canonical zero: the
  centroid of its points within 1 mm of the farthest extent along the finger direction, moved out
  to that extent, and carried rigidly by the link that reaches farthest — never simply the last
  mapped link.
* **surface**: symmetric mean point-to-surface distance between the canonical capsule hand (palm
  cylinder + capsules) and the original geometry of the hand's links (the palm link and everything
  below it), over a few configurations. Original -> canonical distances are analytic; canonical ->
  original use ``trimesh`` closest-point queries. Hands whose palm mesh is missing show it here.

All statistics are mean / 95th percentile / max in millimetres, per finger and for the hand.
"""

from __future__ import annotations

import warnings
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ohra.canonical.couplings import describe
from ohra.canonical.kinematics import HandModel
from ohra.canonical.params import FINGER_SLICES, FINGERS, JOINT_NAMES
from ohra.original.keypoints import line_distance, original_keypoints, sample_original, unmapped_hand_joints
from ohra.original.measure import Measurement
from ohra.original.parse import ParseResult


@dataclass(frozen=True)
class Stats:
    mean: float
    p95: float
    max: float
    n: int

    @classmethod
    def of(cls, values_m: np.ndarray) -> "Stats":
        v = np.asarray(values_m, dtype=float).ravel() * 1e3
        v = v[np.isfinite(v)]
        if v.size == 0:
            return cls(float("nan"), float("nan"), float("nan"), 0)
        return cls(float(v.mean()), float(np.percentile(v, 95)), float(v.max()), int(v.size))

    def to_dict(self) -> dict[str, float]:
        return {"mean_mm": round(self.mean, 3), "p95_mm": round(self.p95, 3), "max_mm": round(self.max, 3), "n": self.n}


@dataclass
class FidelityReport:
    hand: str
    form: str
    samples: int
    joints: dict[str, Stats]
    joint_origins: dict[str, Stats]
    tips: dict[str, Stats]
    surface: dict[str, Stats] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    approximations: list[str] = field(default_factory=list)  # what the canonical form cannot express
    tips_held: Stats | None = None  # hand tip error with unmapped joints held (only when there are some)
    couplings: list[str] = field(default_factory=list)  # "slot = a * driver + b" lines

    def to_dict(self) -> dict[str, Any]:
        return {
            "hand": self.hand, "form": self.form, "samples": self.samples,
            "joints": {k: v.to_dict() for k, v in self.joints.items()},
            "joint_origins": {k: v.to_dict() for k, v in self.joint_origins.items()},
            "tips": {k: v.to_dict() for k, v in self.tips.items()},
            "surface": {k: v.to_dict() for k, v in self.surface.items()},
            "notes": self.notes,
            "approximations": self.approximations,
            "tips_unmapped_held": self.tips_held.to_dict() if self.tips_held is not None else None,
            "couplings": self.couplings,
        }

    def table(self, surface_hint: str | None = None) -> str:
        """Plain-text table: rows fingers + hand, columns tip / joint / surface mean, p95, max [mm].

        Without surface errors (``compare(..., surface=False)``) the surface column is left out and a
        line says so, followed by ``surface_hint`` (how to get them) when given.
        """
        rows = [f for f in FINGERS if f in self.tips] + ["hand"]
        with_surface = bool(self.surface)
        head = f"{'':8s} {'fingertip':>24s} {'joint (axis line)':>24s}" + (f" {'surface':>24s}" if with_surface else "")
        lines = [f"{self.hand} ({self.form}), {self.samples} configurations; errors in mm (mean / p95 / max)", head]

        def cell(d: dict[str, Stats], k: str) -> str:
            s = d.get(k)
            return f"{s.mean:7.2f} {s.p95:7.2f} {s.max:7.2f}" if s is not None and s.n else f"{'-':>23s}"

        for r in rows:
            lines.append(f"{r:8s} {cell(self.tips, r):>24s} {cell(self.joints, r):>24s}"
                         + (f" {cell(self.surface, r):>24s}" if with_surface else ""))
        if not with_surface:
            lines.append("surface: not computed" + (f"; {surface_hint}" if surface_hint else ""))
        if self.tips_held is not None:
            lines.append(f"fingertip with the unmapped joints held at their default (as the action map drives the "
                         f"original): {self.tips_held.mean:.2f} / {self.tips_held.p95:.2f} / {self.tips_held.max:.2f}")
        lines += [f"coupling: {c}" for c in self.couplings]
        lines += [f"approximation: {a}" for a in self.approximations]
        return "\n".join(lines)


def _joint_links(urdf: str) -> dict[str, str]:
    """Canonical joint name -> its child link (the frame at the joint origin)."""
    root = ET.fromstring(urdf)
    return {j.get("name"): j.find("child").get("link") for j in root.findall("joint")}


def keypoint_errors(res: ParseResult, samples: int = 200, seed: int = 0, unmapped: bool = True) -> tuple[dict, dict, dict]:
    """Per-finger joint (axis-line), joint-origin and fingertip errors [m] as arrays.

    ``unmapped``: also sample the actuated joints inside the hand that drive no slot (default);
    False holds them at their default, as the action map drives the original hand.
    """
    m = res.measurement
    hm = HandModel.from_params(res.params)
    q_orig = sample_original(m, samples, seed, unmapped=unmapped)
    ok = original_keypoints(m, q_orig)
    qc = np.clip(ok.q_canon, hm.lower, hm.upper)
    links = _joint_links(hm.urdf)
    mapped = [k for k in range(22) if np.isfinite(ok.joints[0, k, 0])]
    frames = [links[JOINT_NAMES[k]] for k in mapped]
    P = hm.frame_poses(qc, frames)[..., :3, 3]  # (N, K, 3)
    tips = hm.fingertips(qc)
    jerr, oerr, terr = {}, {}, {}
    for fi, f in enumerate(FINGERS):
        ks = [i for i, k in enumerate(mapped) if FINGER_SLICES[f].start <= k < FINGER_SLICES[f].stop]
        if not ks:
            continue
        kk = [mapped[i] for i in ks]
        jerr[f] = line_distance(P[:, ks], ok.joints[:, kk], ok.axes[:, kk])
        oerr[f] = np.linalg.norm(P[:, ks] - ok.joints[:, kk], axis=-1)
        if np.isfinite(ok.tips[0, fi, 0]) and np.isfinite(tips[0, fi, 0]):
            terr[f] = np.linalg.norm(tips[:, fi] - ok.tips[:, fi], axis=-1)
    return jerr, oerr, terr


# -- surface ---------------------------------------------------------------------------------------
def _capsule_signed(points: np.ndarray, p0: np.ndarray, p1: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Signed distance of points (P,3) to capsules (K) -> (P,K)."""
    d = p1 - p0
    L2 = np.maximum(np.sum(d * d, axis=1), 1e-18)
    w = points[:, None, :] - p0[None]
    t = np.clip(np.sum(w * d[None], axis=2) / L2, 0.0, 1.0)
    c = p0[None] + t[..., None] * d[None]
    return np.linalg.norm(points[:, None, :] - c, axis=2) - r[None]


def _palm_signed(points: np.ndarray, R: float, depth: float) -> np.ndarray:
    """Signed distance to the palm cylinder (axis +x, centre (0,0,R), radius R, length depth)."""
    x = np.abs(points[:, 0]) - depth / 2.0
    rad = np.hypot(points[:, 1], points[:, 2] - R) - R
    outside = np.hypot(np.maximum(x, 0.0), np.maximum(rad, 0.0))
    return outside + np.minimum(np.maximum(x, rad), 0.0)


def _sample_capsule(rng, p0, p1, r, n) -> np.ndarray:
    """~uniform surface samples of one capsule."""
    d = p1 - p0
    L = float(np.linalg.norm(d))
    z = d / L if L > 1e-12 else np.array([0.0, 0.0, 1.0])
    x = np.cross(z, [1.0, 0.0, 0.0])
    if np.linalg.norm(x) < 1e-6:
        x = np.cross(z, [0.0, 1.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    area_cyl, area_sph = 2 * np.pi * r * L, 4 * np.pi * r * r
    n_cyl = int(round(n * area_cyl / (area_cyl + area_sph)))
    th = rng.uniform(0, 2 * np.pi, n_cyl)
    s = rng.uniform(0, 1, n_cyl)
    cyl = p0 + s[:, None] * d + r * (np.cos(th)[:, None] * x + np.sin(th)[:, None] * y)
    u = rng.normal(size=(n - n_cyl, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    along = u @ z
    cap = np.where((along >= 0)[:, None], p1 + r * u, p0 + r * u)
    return np.vstack([cyl, cap])


def _sample_palm(rng, R, depth, n) -> np.ndarray:
    area_side, area_disc = 2 * np.pi * R * depth, np.pi * R * R
    n_side = int(round(n * area_side / (area_side + 2 * area_disc)))
    th = rng.uniform(0, 2 * np.pi, n_side)
    side = np.column_stack([rng.uniform(-depth / 2, depth / 2, n_side), R * np.cos(th), R + R * np.sin(th)])
    m = n - n_side
    rr = R * np.sqrt(rng.uniform(0, 1, m))
    ph = rng.uniform(0, 2 * np.pi, m)
    xs = np.where(rng.uniform(0, 1, m) < 0.5, -depth / 2, depth / 2)
    disc = np.column_stack([xs, rr * np.cos(ph), R + rr * np.sin(ph)])
    return np.vstack([side, disc])


def _original_samples(parts: list, labels: list[str], points: int, rng) -> tuple[np.ndarray, np.ndarray]:
    """Surface samples of the posed original meshes, proportional to area, with their finger labels."""
    import trimesh

    areas = np.array([p.area for p in parts])
    counts = np.maximum(1, np.round(points * areas / areas.sum()).astype(int))
    pts, lab = [], []
    for p, n, label in zip(parts, counts, labels):
        s, _ = trimesh.sample.sample_surface(p, int(n), seed=int(rng.integers(1 << 31)))
        pts.append(np.asarray(s))
        lab += [label] * len(s)
    return np.vstack(pts), np.array(lab)


def _canonical_samples(caps, palm: dict, points: int, rng) -> tuple[np.ndarray, np.ndarray]:
    """Surface samples of the capsule hand, proportional to area, kept only where on the union's surface."""
    c_pts, c_lab = [], []
    areas_c = [2 * np.pi * r * np.linalg.norm(b - a) + 4 * np.pi * r * r for a, b, r in zip(caps.p0, caps.p1, caps.radius)]
    area_palm = 2 * np.pi * palm["radius"] * palm["depth"] + 2 * np.pi * palm["radius"] ** 2
    tot = sum(areas_c) + area_palm
    for k in range(len(caps.link)):
        s = _sample_capsule(rng, caps.p0[k], caps.p1[k], caps.radius[k], max(8, int(points * areas_c[k] / tot)))
        c_pts.append(s)
        c_lab += [FINGERS[caps.finger[k]]] * len(s)
    s = _sample_palm(rng, palm["radius"], palm["depth"], max(8, int(points * area_palm / tot)))
    c_pts.append(s)
    c_lab += ["palm"] * len(s)
    pts, lab = np.vstack(c_pts), np.array(c_lab)
    inside = np.zeros(len(pts), dtype=bool)
    if len(caps.link):
        inside |= np.min(_capsule_signed(pts, caps.p0, caps.p1, caps.radius), axis=1) < -1e-6
    inside |= _palm_signed(pts, palm["radius"], palm["depth"]) < -1e-6
    return pts[~inside], lab[~inside]


def _hand_meshes(m: Measurement) -> tuple[dict, dict[str, str]]:
    """Geometry of the palm link and everything below it (link -> trimesh), and link -> finger."""
    finger_of = {l: f for f, fm in m.fingers.items() for l in fm.seg_links}
    meshes = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for l in m.hand.descendants(m.palm_link):
            g = m.hand.link_geometry(l)
            if g is not None:
                meshes[l] = g
    return meshes, finger_of


def surface_errors(res: ParseResult, configs: int = 3, points: int = 1500, seed: int = 0) -> dict[str, np.ndarray]:
    """Per-finger and hand symmetric surface distances [m] (concatenated over configurations)."""
    import trimesh

    m: Measurement = res.measurement
    hm = HandModel.from_params(res.params)
    rng = np.random.default_rng(seed)
    meshes, finger_of = _hand_meshes(m)
    q_orig = sample_original(m, configs - 1, seed + 1, unmapped=True) if configs > 1 else m.q0[None]
    qc = np.clip(original_keypoints(m, q_orig).q_canon, hm.lower, hm.upper)
    out: dict[str, list[np.ndarray]] = {k: [] for k in list(m.fingers) + ["hand"]}
    link_list = list(meshes)
    poses = m.hand.link_poses(q_orig, link_list) if link_list else None
    for c in range(q_orig.shape[0]):
        parts = []
        for i, l in enumerate(link_list):
            mm = meshes[l].copy()
            mm.apply_transform(m.T_palm_root @ poses[c, i])
            parts.append(mm)
        if not parts:
            continue
        o_pts, o_lab = _original_samples(parts, [finger_of.get(l, "palm") for l in link_list], points, rng)
        caps = hm.capsules(qc[c])
        sd = np.min(_capsule_signed(o_pts, caps.p0, caps.p1, caps.radius), axis=1) if len(caps.link) else np.full(len(o_pts), np.inf)
        d_o2c = np.abs(np.minimum(sd, _palm_signed(o_pts, hm.palm["radius"], hm.palm["depth"])))
        c_pts, c_lab = _canonical_samples(caps, hm.palm, points, rng)
        _, d_c2o, _ = trimesh.proximity.closest_point(trimesh.util.concatenate(parts), c_pts)
        for f in m.fingers:
            out[f].append(np.concatenate([d_o2c[o_lab == f], d_c2o[c_lab == f]]))
        out["hand"].append(np.concatenate([d_o2c, d_c2o]))
    return {k: np.concatenate(v) if v else np.array([]) for k, v in out.items()}


def approximations(res: ParseResult) -> list[str]:
    """What the canonical hand of ``res`` cannot express, one named item each."""
    m = res.measurement
    out = [n[len("approximation: "):] for n in res.notes if n.startswith("approximation: ") and "looks bent" not in n]
    for name in unmapped_hand_joints(m):
        j = m.hand.joints[name]
        out.append(f"joint {name!r} ([{j.lower:+.3f}, {j.upper:+.3f}] rad) moves links inside the hand but drives no "
                   f"slot of the {res.form} form: sampled over its range, the canonical hand cannot follow it")
    return out


def compare(
    hand: Any,
    form: str | None = "base",
    samples: int = 200,
    seed: int = 0,
    surface: bool = True,
    surface_configs: int = 3,
    surface_points: int = 1500,
) -> FidelityReport:
    """Fidelity of a :class:`ParseResult`, or of any hand :func:`ohra.hands.resolve_hand` accepts
    (registered name: committed params; spec YAML: parsed; params JSON with its spec) over ``samples`` >= 1
    random configurations (plus the canonical zero)."""
    if int(samples) < 1:
        from ohra.errors import OhraError

        raise OhraError(f"compare: samples must be >= 1, got {samples}")
    if isinstance(hand, ParseResult):
        res = hand
        name = res.spec.name
    else:
        from ohra.hands.resolve import resolve_hand

        ref = resolve_hand(hand, form)
        res, name = ref.parse_result(), ref.name
    jerr, oerr, terr = keypoint_errors(res, samples, seed)
    rep = FidelityReport(
        name, res.form, samples,
        {**{f: Stats.of(v) for f, v in jerr.items()}, "hand": Stats.of(np.concatenate([v.ravel() for v in jerr.values()]))},
        {**{f: Stats.of(v) for f, v in oerr.items()}, "hand": Stats.of(np.concatenate([v.ravel() for v in oerr.values()]))},
        {**{f: Stats.of(v) for f, v in terr.items()}, "hand": Stats.of(np.concatenate([v.ravel() for v in terr.values()]) if terr else np.array([]))},
        notes=list(res.notes),
        approximations=approximations(res),
        couplings=describe(res.couplings),
    )
    if unmapped_hand_joints(res.measurement):
        held = keypoint_errors(res, samples, seed, unmapped=False)[2]
        rep.tips_held = Stats.of(np.concatenate([v.ravel() for v in held.values()]) if held else np.array([]))
    if surface:
        se = surface_errors(res, surface_configs, surface_points, seed)
        rep.surface = {k: Stats.of(v) for k, v in se.items()}
    return rep


__all__ = ["compare", "FidelityReport", "Stats", "keypoint_errors", "surface_errors"]
