"""A hybrid hand for attributing simulation differences: an original URDF with the canonical collision shapes.

The hybrid keeps everything of the original :class:`SimHand` (kinematics, joint limits, masses,
inertias, the action map) and replaces its collision geometry by the canonical hand's palm disc and
finger capsules. Comparing original, hybrid and canonical separates what the link *shapes* do from
what the rest of the URDF does (used by ``benchmarks/rotation_geometry.py``).

Each canonical collision shape rides on the original link that moves with it: among the original
links of the same finger (the palm's links for the palm), the one whose frame keeps the most constant
transform to the canonical link over random joint configurations, both hands posed by the same
canonical joint vector (the original through its action map) in the canonical palm frame. How
constant is reported as the *drift* (m): the largest motion of the shape's end points relative to
that link, i.e. the kinematic mismatch the hybrid inherits.
"""

from __future__ import annotations

import copy
import dataclasses
import warnings
import xml.etree.ElementTree as ET
from functools import lru_cache

import numpy as np

from ohra.errors import GraspError
from ohra.sim.hands import SimHand
from ohra.transforms import matrix_to_xyzrpy, xyzrpy_to_matrix


@lru_cache(maxsize=8)
def _kinematic_model(urdf: str):
    """Pinocchio model of a prepared URDF, kinematics only (urdfdom does not read ``<capsule>`` shapes)."""
    import pinocchio as pin

    root = ET.fromstring(urdf)
    for link in root.iter("link"):
        for el in link.findall("collision") + link.findall("visual"):
            link.remove(el)
    return pin.buildModelFromXML(ET.tostring(root, encoding="unicode"))


def link_frames(hand: SimHand, q_canon: np.ndarray) -> dict[str, np.ndarray]:
    """Every link frame (4x4, metres) of ``hand`` in the canonical palm frame, posed by canonical ``q_canon`` (22,)."""
    import pinocchio as pin

    model = _kinematic_model(hand.urdf)
    data = model.createData()
    qs = dict(zip(hand.joints, hand.to_sim(np.asarray(q_canon, dtype=float))))
    qs.update({n: mul * qs[m] + off for n, (m, mul, off) in hand.mimic.items() if m in qs})
    q = pin.neutral(model)
    for jid in range(1, model.njoints):
        name = model.names[jid]
        if name in qs and model.joints[jid].nq == 1:
            q[model.joints[jid].idx_q] = qs[name]
    pin.forwardKinematics(model, data, q)
    pin.updateFramePlacements(model, data)
    return {f.name: hand.T_palm_root @ data.oMf[i].homogeneous
            for i, f in enumerate(model.frames) if f.type == pin.FrameType.BODY}


def _origin(el: ET.Element) -> np.ndarray:
    o = el.find("origin")
    get = (lambda k: o.get(k, "0 0 0")) if o is not None else (lambda k: "0 0 0")
    return xyzrpy_to_matrix(np.array([float(v) for v in get("xyz").split()] + [float(v) for v in get("rpy").split()]))


def _ends(col: ET.Element) -> np.ndarray:
    """(4, 2) homogeneous end points of a collision shape in its link frame (a capsule's or cylinder's
    axis ends, else its centre twice)."""
    g = col.find("geometry")
    el = next((g.find(k) for k in ("capsule", "cylinder") if g is not None and g.find(k) is not None), None)
    h = float(el.get("length")) / 2 if el is not None else 0.0
    return _origin(col) @ np.array([[0.0, 0.0], [0.0, 0.0], [-h, h], [1.0, 1.0]])


def with_canonical_collisions(original: SimHand, canonical: SimHand, configs: int = 8,
                              seed: int = 0) -> tuple[SimHand, dict[str, tuple[str, float]]]:
    """The hybrid of ``original`` (an original-URDF :class:`SimHand`) and ``canonical`` (its canonical hand),
    and the fit ``{canonical link: (original link it rides on, drift in m)}`` (see module doc).
    ``configs`` joint configurations (the first all zeros, the rest uniform in the canonical limits, seeded)."""
    if original.canonical or not canonical.canonical:
        raise GraspError(f"with_canonical_collisions needs an original and a canonical hand, got {original.name!r} "
                         f"and {canonical.name!r}")
    rng = np.random.default_rng(seed)
    lo, hi = canonical.canon_lower, np.maximum(canonical.canon_upper, canonical.canon_lower)
    qs = [np.zeros(22)] + [rng.uniform(lo, hi) for _ in range(max(configs, 2) - 1)]
    Pc = [link_frames(canonical, q) for q in qs]
    Po = [link_frames(original, q) for q in qs]
    oroot = ET.fromstring(original.urdf)
    olinks = {link.get("name"): link for link in oroot.iter("link")}
    for link in olinks.values():
        for col in link.findall("collision"):
            link.remove(col)
    fit: dict[str, tuple[str, float]] = {}
    for link in ET.fromstring(canonical.urdf).iter("link"):
        cols = link.findall("collision")
        if not cols:
            continue
        lc = link.get("name")
        finger = canonical.link_finger.get(lc, -1)
        best, best_drift, best_X = None, np.inf, None
        for lo_name in (n for n, f in original.link_finger.items() if f == finger and n in Po[0] and n in olinks):
            X = [np.linalg.inv(po[lo_name]) @ pc[lc] for po, pc in zip(Po, Pc)]
            drift = max(float(np.linalg.norm((x @ _ends(c) - X[0] @ _ends(c))[:3], axis=0).max()) for x in X for c in cols)
            if drift < best_drift - 1e-12:
                best, best_drift, best_X = lo_name, drift, X[0]
        if best is None:
            raise GraspError(f"{original.name}: no original link of finger {finger} to carry canonical link {lc!r}")
        fit[lc] = (best, best_drift)
        for col in cols:
            new = copy.deepcopy(col)
            with warnings.catch_warnings():  # a gimbal-locked rpy still gives the same rotation back
                warnings.simplefilter("ignore", UserWarning)
                xyzrpy = matrix_to_xyzrpy(best_X @ _origin(col))
            o = new.find("origin")
            if o is None:
                o = ET.SubElement(new, "origin")
            o.set("xyz", " ".join(f"{v:.9g}" for v in xyzrpy[:3]))
            o.set("rpy", " ".join(f"{v:.9g}" for v in xyzrpy[3:]))
            olinks[best].append(new)
    name = original.name.replace(":original", "") + ":hybrid"
    return dataclasses.replace(original, urdf=ET.tostring(oroot, encoding="unicode"), name=name), fit


__all__ = ["link_frames", "with_canonical_collisions"]
