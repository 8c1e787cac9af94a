"""Is it the contact geometry? A canonical rotation policy on a *hybrid* hand: the original URDF (its
kinematics, joint limits, masses and inertias) with its collision geometry replaced by the canonical
hand's (the palm disc and the finger capsules), next to the original and the canonical URDF.

The hybrid is :func:`ohra.sim.hybrid.with_canonical_collisions`: each canonical collision shape rides on
the original link that moves with it; how well (the *drift* of the shape's end points relative to that
link over 8 joint configurations, the kinematic mismatch the hybrid inherits) is reported.

The shipped canonical-URDF policy then runs through the action map on the original URDF, on the
hybrid and on its own URDF, from each URDF's own starting states (the canonical holding pose, as
``rotate eval --on-urdf original``), the same seeded episodes. If the hybrid turns the cube like the
canonical URDF, the original's link shapes are what stops it; if it fails like the original, the
cause lies in what the hybrid keeps from the original (kinematics, limits, inertias).

How much should a few millimetres matter? ``--sensitivity`` also runs each policy on its canonical hand
with every finger capsule's radius 0.5 mm larger or smaller (1 mm would make a LEAP thumb capsule shorter than
its diameter, which the params refuse) and every finger segment 1 mm longer (fingertips up to 3 mm farther out; the palm,
hence the cube, unchanged; starting states generated for each), the scale of the hybrid's kinematic mismatch.

    python benchmarks/rotation_geometry.py [--policies rotate_leap_canonical ...] [--episodes 20] [--sensitivity]
    -> benchmarks/results/rotation_geometry.{json,md}
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import run_script, script_parser, write_results  # noqa: E402

import numpy as np  # noqa: E402


def perturbed(task) -> dict:
    """The canonical hand of ``task`` (a resolved canonical-URDF task) with mm-level changes (see module doc), by label."""
    from ohra.sim.hands import SimHand

    p = task.params
    present = p.finger_radii > 0
    changes = {"canonical URDF, finger radii +0.5 mm": {"finger_radii": np.where(present, p.finger_radii + 0.0005, 0.0)},
               "canonical URDF, finger radii -0.5 mm": {"finger_radii": np.where(present, p.finger_radii - 0.0005, 0.0)},
               "canonical URDF, finger segments +1 mm": {"finger_lengths": np.where(p.finger_lengths > 0, p.finger_lengths + 0.001, 0.0)}}
    return {label: SimHand.from_params(dataclasses.replace(p, **kw), name=task.hand.name) for label, kw in changes.items()}


def main(argv: list[str] | None = None) -> int:
    ap = script_parser(__doc__, __file__)
    ap.add_argument("--policies", nargs="+", default=["rotate_leap_canonical", "rotate_shadow_canonical"])
    ap.add_argument("--episodes", type=int, default=20)
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--grasps", type=int, default=200, help="starting states generated for the hybrid (and perturbed) hands")
    ap.add_argument("--sensitivity", action="store_true", help="also the canonical hands with mm-level changes")
    args = ap.parse_args(argv)
    from rotation_table3 import summary_cell

    from ohra.learn.rl.evaluate import Policy, evaluate_policy, on_urdf, shipped
    from ohra.sim.hybrid import with_canonical_collisions
    from ohra.sim.rotation.grasps import generate, load_or_generate
    from ohra.sim.rotation.task import resolve

    rows, fit_rows, data = [], [], {}
    for name in args.policies:
        pol = Policy(shipped(name))
        if pol.env_cfg.urdf != "canonical":
            raise SystemExit(f"{name} was trained on the {pol.env_cfg.urdf} URDF; this runs canonical-URDF policies")
        ocfg = on_urdf(pol.env_cfg, "original")
        otask = resolve(ocfg)
        ctask = resolve(pol.env_cfg)
        hand, fit = with_canonical_collisions(otask.hand, ctask.hand)
        hgrasps = generate(resolve(dataclasses.replace(ocfg, grasp_count=args.grasps), hand))
        runs = {"original URDF": (ocfg, load_or_generate(otask), None),
                "hybrid (original, canonical collision shapes)": (ocfg, hgrasps, hand),
                "canonical URDF": (pol.env_cfg, pol.grasps, None)}
        if args.sensitivity:
            for label, h in perturbed(ctask).items():
                runs[label] = (pol.env_cfg, generate(resolve(dataclasses.replace(pol.env_cfg, grasp_count=args.grasps), h)), h)
        res = {}
        for label, (cfg, gs, h) in runs.items():
            ev = evaluate_policy(pol, cfg, args.episodes, args.seed, name, grasps=gs, hand=h)
            r = ev.summary()
            # per episode too: a spread like +-10 rad is one stray episode, and the JSON should show which
            res[label] = {**r, "per_episode": {"steps_to_fall": [int(x) for x in ev.steps_to_fall],
                                               "cumulative_rotation": [float(x) for x in ev.cumulative_rotation]}}
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
    run_script(main, __file__)
