"""Is it the contact geometry? A canonical rotation policy on a *hybrid* hand: the original URDF (its
kinematics, joint limits, masses and inertias) with its collision geometry replaced by the canonical
hand's (the palm disc and the finger capsules), next to the original and the canonical URDF.

Each canonical collision shape rides on the original link that moves with it: for every canonical
link that carries one, the original link of the same finger (the palm's links for the palm) whose
frame keeps the most constant transform to it over random joint configurations, both hands posed by
the same canonical joint vector (the original through its action map) in the canonical palm frame.
How constant (the *fit*: the largest drift of the shape's end points over the configurations) is
reported: it is the kinematic mismatch between the two hands that the hybrid inherits.

The shipped canonical-URDF policy then runs through the action map on the original URDF, on the
hybrid and on its own URDF, from each URDF's own starting states (the canonical holding pose, as
``rotate eval --on-urdf original``), the same seeded episodes. If the hybrid turns the cube like the
canonical URDF, the original's link shapes are what stops it; if it fails like the original, the
cause lies in what the hybrid keeps from the original (kinematics, limits, inertias).

    python benchmarks/rotation_geometry.py [--policies rotate_leap_canonical ...] [--episodes 20]
    -> benchmarks/results/rotation_geometry.{json,md}
"""

from __future__ import annotations

import argparse
import dataclasses
import copy
import sys
import warnings
import xml.etree.ElementTree as ET
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import write_results  # noqa: E402

import numpy as np  # noqa: E402


def link_poses(hand, q_canon: np.ndarray) -> dict[str, np.ndarray]:
    """Link frames (4x4) in the canonical palm frame of a :class:`SimHand` posed by canonical ``q_canon``."""
    import pinocchio as pin

    root = ET.fromstring(hand.urdf)  # kinematics only: urdfdom does not read <capsule> collision shapes
    for link in root.iter("link"):
        for el in link.findall("collision") + link.findall("visual"):
            link.remove(el)
    model = pin.buildModelFromXML(ET.tostring(root, encoding="unicode"))
    data = model.createData()
    qs = dict(zip(hand.joints, hand.to_sim(q_canon)))
    qs.update({n: mul * qs[m] + off for n, (m, mul, off) in hand.mimic.items() if m in qs})
    q = pin.neutral(model)
    for jid in range(1, model.njoints):
        name = model.names[jid]
        if name in qs and model.joints[jid].nq == 1:
            q[model.joints[jid].idx_q] = qs[name]
    pin.forwardKinematics(model, data, q)
    pin.updateFramePlacements(model, data)
    out = {}
    for fid, f in enumerate(model.frames):
        if f.type == pin.FrameType.BODY:
            out[f.name] = hand.T_palm_root @ data.oMf[fid].homogeneous
    return out


def _origin(el: ET.Element) -> np.ndarray:
    from ohra.transforms import xyzrpy_to_matrix

    o = el.find("origin")
    xyz = [float(v) for v in (o.get("xyz", "0 0 0") if o is not None else "0 0 0").split()]
    rpy = [float(v) for v in (o.get("rpy", "0 0 0") if o is not None else "0 0 0").split()]
    return xyzrpy_to_matrix(np.array(xyz + rpy))


def _ends(geom: ET.Element) -> np.ndarray:
    """(2, 3) points spanning a collision shape in its own frame (a capsule's segment ends, else its centre twice)."""
    cap = geom.find("capsule")
    cyl = geom.find("cylinder")
    el = cap if cap is not None else cyl
    h = float(el.get("length")) / 2 if el is not None else 0.0
    return np.array([[0.0, 0.0, -h], [0.0, 0.0, h]])


def hybrid(original, canonical, configs: int = 8, seed: int = 0):
    """The original :class:`SimHand` with the canonical hand's collision shapes (see module doc), and the fit
    per canonical link: ``{link: (original link, drift in m)}``."""
    from ohra.transforms import matrix_to_xyzrpy

    rng = np.random.default_rng(seed)
    lo, hi = canonical.canon_lower, canonical.canon_upper
    qs = [np.zeros(22)] + [rng.uniform(lo, np.maximum(hi, lo)) for _ in range(configs - 1)]
    P_c = [link_poses(canonical, q) for q in qs]
    P_o = [link_poses(original, q) for q in qs]
    croot = ET.fromstring(canonical.urdf)
    oroot = ET.fromstring(original.urdf)
    olinks = {link.get("name"): link for link in oroot.iter("link")}
    for link in olinks.values():
        for col in link.findall("collision"):
            link.remove(col)
    fit = {}
    for link in croot.iter("link"):
        cols = link.findall("collision")
        if not cols:
            continue
        lc = link.get("name")
        f = canonical.link_finger.get(lc, -1)
        cands = [n for n, g in original.link_finger.items() if g == f and n in P_o[0]]
        best, best_drift, best_X = None, np.inf, None
        for lo_name in cands:
            X = [np.linalg.inv(po[lo_name]) @ pc[lc] for po, pc in zip(P_o, P_c)]
            drift = 0.0
            for col in cols:
                ends = (_origin(col) @ np.c_[_ends(col.find("geometry")), np.ones(2)].T)
                pts = [(x @ ends)[:3].T for x in X]
                drift = max(drift, max(float(np.linalg.norm(p - pts[0], axis=1).max()) for p in pts))
            if drift < best_drift - 1e-9:
                best, best_drift, best_X = lo_name, drift, X[0]
        if best is None:
            raise SystemExit(f"rotation_geometry: no original link of finger {f} for canonical link {lc!r}")
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
    hand = dataclasses.replace(original, urdf=ET.tostring(oroot, encoding="unicode"),
                               name=original.name.replace(":original", ":hybrid"))
    return hand, fit


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--policies", nargs="+", default=["rotate_leap_canonical", "rotate_shadow_canonical"])
    ap.add_argument("--episodes", type=int, default=20)
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--grasps", type=int, default=200, help="starting states generated for the hybrid hand")
    args = ap.parse_args(argv)
    from rotation_table3 import summary_cell

    from ohra.learn.rl.evaluate import Policy, evaluate_policy, on_urdf, shipped
    from ohra.sim.rotation.grasps import generate, load_or_generate
    from ohra.sim.rotation.task import resolve

    rows, fit_rows, data = [], [], {}
    for name in args.policies:
        pol = Policy(shipped(name))
        if pol.env_cfg.urdf != "canonical":
            raise SystemExit(f"{name} was trained on the {pol.env_cfg.urdf} URDF; this runs canonical-URDF policies")
        ocfg = on_urdf(pol.env_cfg, "original")
        otask = resolve(ocfg)
        hand, fit = hybrid(otask.hand, resolve(pol.env_cfg).hand)
        hgrasps = generate(resolve(dataclasses.replace(ocfg, grasp_count=args.grasps), hand))
        runs = {"original URDF": (ocfg, load_or_generate(otask), None),
                "hybrid (original, canonical collision shapes)": (ocfg, hgrasps, hand),
                "canonical URDF": (pol.env_cfg, pol.grasps, None)}
        res = {}
        for label, (cfg, gs, h) in runs.items():
            r = evaluate_policy(pol, cfg, args.episodes, args.seed, name, grasps=gs, hand=h).summary()
            res[label] = r
            rows.append(f"| {name} | {label} | {summary_cell(r, ' | ')} |")
            print(rows[-1], file=sys.stderr)
        drifts = np.array([d for _, d in fit.values()])
        data[name] = {"hand": pol.env_cfg.hand, "runs": res, "hybrid_grasps_kept": len(hgrasps.q),
                      "hybrid_grasps_tried": hgrasps.attempts,
                      "fit": {k: {"original_link": o, "drift_m": d} for k, (o, d) in fit.items()}}
        fit_rows.append(f"| {pol.env_cfg.hand} | {len(fit)} | {1000 * np.median(drifts):.1f} | {1000 * drifts.max():.1f} | "
                        + ", ".join(f"{k} -> {o}" for k, (o, _) in fit.items()) + " |")
    table = "\n".join([
        f"Canonical-URDF rotation policies through the action map on the original URDF, on the hybrid hand (the original "
        f"URDF with the canonical collision shapes) and on their own URDF, {args.episodes} episodes (seeds {args.seed}.."
        f"{args.seed + args.episodes - 1}), deterministic actions; each URDF's own starting states (hybrid: {args.grasps} "
        f"generated).", "",
        "| policy | hand | Steps-to-Fall | Cumulative Rotation [rad] | survived |", "|---|---|---|---|---|", *rows, "",
        "Hybrid fit: each canonical collision shape on the original link that moves with it; drift = largest motion of "
        "the shape's end points relative to that link over 8 joint configurations (the kinematic mismatch).", "",
        "| hand | shapes | drift median [mm] | drift max [mm] | canonical -> original link |", "|---|---|---|---|---|",
        *fit_rows])
    write_results("rotation_geometry", {"episodes": args.episodes, "seed": args.seed, "policies": data}, table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
