"""Coupled hand: canonical grasps (coupling rows in the NLP) replayed on the original URDF.

For the Inspire right hand (URDF mimic joints -> canonical couplings) and each object: the NLP's
starts (coupling rows on, projected starts), the converged solutions without self-intersection,
their largest coupling residual, and the share of them that pass the six-direction evaluation
(``mode="eval"``, default :class:`ohra.sim.Protocol`) on the canonical hand (coupled controller)
and on the original URDF (``GraspEvaluator.original``, i.e. ``ohra eval --original``). The change
is original minus canonical pass rate, in points; the issue's target is within +-5 points overall.

Run: python benchmarks/bench_couplings.py [--starts 8] [--objects box sphere ...] [--ycb MustardBottle ...]
-> benchmarks/results/couplings.{json,md}
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import write_results  # noqa: E402

import numpy as np  # noqa: E402

from ohra.canonical.couplings import residual  # noqa: E402
from ohra.canonical.kinematics import HandModel  # noqa: E402
from ohra.hands import resolve_hand  # noqa: E402
from ohra.objects.model import ObjectModel, resolve_objects  # noqa: E402
from ohra.paths import objects_root  # noqa: E402
from ohra.sim import GraspEvaluator, SimHand  # noqa: E402
from ohra.synth.init import initial_poses  # noqa: E402
from ohra.synth.nlp import GraspNLP, NLPSettings  # noqa: E402

HAND = "inspire_hand_right"


def solve(ref, obj: ObjectModel, starts: int, seed: int) -> tuple[np.ndarray, float, int]:
    """(converged grasps without self-intersection (N,31), their largest coupling residual [rad], starts)."""
    hand = HandModel.from_params(ref.params)
    nlp = GraspNLP(hand, obj, NLPSettings(couplings=ref.couplings))
    grasps, res = [], 0.0
    for st in initial_poses(hand, obj, starts, np.random.default_rng(seed), ref.couplings):
        r = nlp.solve(st["R0"], st["t0"], st["q0"], st["q_pref"])
        if r["success"] and not hand.self_collision(r["grasp"][9:]):
            grasps.append(r["grasp"])
            res = max(res, r["coupling_residual"], float(np.abs(residual(ref.couplings, r["grasp"][9:])).max()))
    return np.array(grasps).reshape(-1, 31), res, starts


def passes(ev: GraspEvaluator, grasps: np.ndarray) -> int:
    if not len(grasps):
        return 0
    rep = ev.evaluate(grasps, mode="eval")
    ev.close()
    return int(sum(r.success for r in rep.results))


def run_object(ref, obj: ObjectModel, starts: int, seed: int) -> dict:
    t = time.perf_counter()
    grasps, res, n = solve(ref, obj, starts, seed)
    canon = passes(GraspEvaluator(SimHand.from_params(ref.params, HAND, couplings=ref.couplings), obj), grasps)
    orig = passes(GraspEvaluator.original(HAND, obj, form=ref.form), grasps)
    k = max(len(grasps), 1)
    return {"object": obj.name, "starts": n, "grasps": int(len(grasps)), "max_residual_rad": res,
            "canonical_pass": canon, "original_pass": orig, "canonical_rate": canon / k, "original_rate": orig / k,
            "change_points": 100.0 * (orig - canon) / k, "seconds": time.perf_counter() - t}


def table(rows: list[dict], starts: int, seed: int) -> str:
    lines = [f"Inspire right hand ({HAND}), both forms, {starts} starts per object, seed {seed}: converged, non-self-intersecting",
             "canonical grasps evaluated (six directions, default protocol) on the coupled canonical hand and",
             "replayed on the original URDF (`ohra eval --original`). Change = original - canonical [points].", "",
             "| form | object | grasps | max coupling residual [rad] | canonical pass | original pass | change [points] |",
             "|---|---|---:|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(f"| {r['form']} | {r['object']} | {r['grasps']} | {r['max_residual_rad']:.1e} | {r['canonical_pass']} ({100 * r['canonical_rate']:.0f} %) "
                     f"| {r['original_pass']} ({100 * r['original_rate']:.0f} %) | {r['change_points']:+.1f} |")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--starts", type=int, default=8)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--objects", nargs="*", default=["box", "sphere", "cylinder", "capsule"])
    ap.add_argument("--ycb", nargs="*", default=[], help="YCB folders under <objects root>/ycb")
    ap.add_argument("--forms", nargs="*", default=["base", "extended"])
    a = ap.parse_args()
    objs = [ObjectModel.builtin(n) for n in a.objects] + [resolve_objects(str(objects_root() / "ycb" / n))[0] for n in a.ycb]
    rows = []
    for form in a.forms:
        ref = resolve_hand(HAND, form)
        part = []
        for obj in objs:
            part.append({"form": form, **run_object(ref, obj, a.starts, a.seed)})
            print(part[-1], flush=True)
        rows += part + [{"form": form, **overall(part)}]
    write_results("couplings", {"hand": HAND, "couplings": [x.to_dict() for x in ref.couplings], "starts": a.starts,
                                "seed": a.seed, "rows": rows}, table(rows, a.starts, a.seed))


def overall(rows: list[dict]) -> dict:
    """The "all" row: pass rates over every object's grasps together."""
    g = sum(r["grasps"] for r in rows)
    c, o = sum(r["canonical_pass"] for r in rows), sum(r["original_pass"] for r in rows)
    return {"object": "all", "starts": sum(r["starts"] for r in rows), "grasps": g,
               "max_residual_rad": max(r["max_residual_rad"] for r in rows), "canonical_pass": c, "original_pass": o,
               "canonical_rate": c / max(g, 1), "original_rate": o / max(g, 1), "change_points": 100.0 * (o - c) / max(g, 1),
               "seconds": sum(r["seconds"] for r in rows)}


if __name__ == "__main__":
    main()
