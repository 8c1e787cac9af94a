"""Left hands through their mirror images: the shipped grasp models sampling a hand as its mirror image
on the mirrored object (``GraspModel.sample(mirror=...)``, ``ohra.canonical.mirror``) vs as it is.

Stop 47 found that the shipped unified model does not carry to mirror images of its training hands
(shadow_hand_left 0/32 on the box against shadow_hand_right's 11/32): trained on one left hand (Allegro)
and one right (Shadow), it never learnt what handedness does. ``mirror="auto"`` (the default) samples a
hand as its mirror image when that image lies nearer the model's training hands in condition space.

Arms, paired over the same wrist rotations and diffusion noise (the same pair seeds), on the 13 unseen
objects of ``recipes/grasp_eval_objects.yaml`` with the protocol the model's data was filtered with,
canonical URDFs, ``-n`` grasps per (hand, object), raw samples (no refinement):

* ``default`` model: every registered hand whose mirror image the auto rule picks, sampled as it is
  ("off") and as its mirror image ("on");
* ``leap`` model (raw-parameter condition, trained on 66 right-hand LEAP variants): the mirror images
  (left hands) of the zero-shot study's three test variants, written as params JSON files under
  ``--runs``, off and on.

How it is read, written before the run (stop 48): for each model, pooled over its hands, on - off above two
standard errors (paired over grasps) reads as "mirroring helps", below minus two as "it hurts", else
"no change detectable". Per-hand rows are shown, not read. One sampling seed.

Run: python benchmarks/grasp_mirror.py [-n 20] [--workers 2]
  -> runs/grasp_mirror/ (resumable pairs, the mirrored LEAP params), benchmarks/results/grasp_mirror.{json,md}
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import run_script, script_parser, write_results  # noqa: E402
from grasp_study import ROOT, data_protocol, eval_objects, protocol_note  # noqa: E402

import numpy as np  # noqa: E402

from ohra.canonical.mirror import mirror_params  # noqa: E402
from ohra.hands import get_hand  # noqa: E402
from ohra.hands.registry import registered_hands  # noqa: E402
from ohra.learn.grasp.evaluate import evaluate_model, hand_label  # noqa: E402
from ohra.learn.grasp.model import load_grasp_model  # noqa: E402

LEAP_TEST = ("leap_3033", "leap_3303", "leap_3330")


def paired(off, on) -> tuple[float, float, int]:
    """on - off success [points] over the same grasps, its standard error, and the number of grasps."""
    d = np.concatenate([b.success.astype(float) - a.success.astype(float) for a, b in zip(off.pairs, on.pairs)])
    return 100 * d.mean(), 100 * d.std(ddof=1) / np.sqrt(len(d)), len(d)


def reading(change: float, se: float) -> str:
    return "mirroring helps" if change > 2 * se else ("it hurts" if change < -2 * se else "no change detectable")


def arm(model, hands: list, labels: list[str], objects: list, protocol, args, pairs: Path) -> dict:
    """Both settings for one model, per hand and pooled."""
    t0 = time.perf_counter()
    rep = {m: evaluate_model(model, hands, objects, n=args.n, seed=0, protocol=protocol, workers=args.workers,
                             mirror=m == "on", resume_dir=pairs, allow_seen=False)
           for m in ("off", "on")}
    rows = {}
    for h, label in zip(hands, labels):
        sel = {m: type(r)([p for p in r.pairs if p.hand == hand_label(h, h)], r.meta) for m, r in rep.items()}
        change, se, n = paired(sel["off"], sel["on"])
        rows[label] = {"off": float(np.mean([p.success_rate for p in sel["off"].pairs])),
                       "on": float(np.mean([p.success_rate for p in sel["on"].pairs])), "change": [change, se], "grasps": n}
    change, se, n = paired(rep["off"], rep["on"])
    return {"hands": rows, "pooled": [change, se], "grasps": n, "reading": reading(change, se),
            "seconds": time.perf_counter() - t0}


def main() -> None:
    ap = script_parser(__doc__, __file__)
    ap.add_argument("-n", type=int, default=20, help="grasps per (hand, object)")
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--objects-file", type=Path, default=ROOT / "recipes" / "grasp_eval_objects.yaml")
    ap.add_argument("--runs", type=Path, default=ROOT / "runs" / "grasp_mirror")
    ap.add_argument("--name", default="grasp_mirror")
    args = ap.parse_args()
    objects = eval_objects(args.objects_file)
    args.runs.mkdir(parents=True, exist_ok=True)

    default = load_grasp_model()
    hands = [h for h in registered_hands() if _has_base(h) and default.mirrors(h)]
    res = {"n": args.n, "objects": [o.name for o in objects], "models": {}}
    res["models"]["default"] = arm(default, hands, hands, objects, data_protocol([str(ROOT / "datasets" / "grasp_unified_s0")]),
                                   args, args.runs / "pairs")

    leap = load_grasp_model("leap")
    images = []
    for v in LEAP_TEST:
        image = mirror_params(get_hand(v)).params
        image.to_json(args.runs / f"{v}_mirror.json")  # for `ohra grasp sample --hand FILE`
        images.append(image)  # evaluated as params: labelled (and seeded) by content, not by a checkout's path
    assert all(leap.mirrors(h) for h in images), "the auto rule should mirror every left LEAP variant"
    res["models"]["leap"] = arm(leap, images, [f"{v} mirror image" for v in LEAP_TEST], objects,
                                data_protocol([str(ROOT / "datasets" / "leap_zeroshot_s0")]), args, args.runs / "pairs")
    res["protocol_note"] = protocol_note(data_protocol([str(ROOT / "datasets" / "grasp_unified_s0")]))

    lines = [f"Shipped grasp models sampling a hand as it is (off) and as its mirror image on the mirrored object (on): "
             f"{args.n} grasps per (hand, object) on {len(objects)} unseen objects, the same random wrist rotations and "
             f"noise in both, protocol {res['protocol_note']}, canonical URDFs, raw samples; paired over grasps. Rule "
             "written before the run (script docstring).", "",
             "| model | hand | off | on (mirror image) | change ± SE [points] |", "|---|---|---|---|---|"]
    for m, r in res["models"].items():
        for h, row in r["hands"].items():
            lines.append(f"| {m} | {h} | {100 * row['off']:.1f} % | {100 * row['on']:.1f} % | "
                         f"{row['change'][0]:+.1f} ± {row['change'][1]:.1f} |")
        lines.append(f"| {m} | pooled ({r['grasps']} grasps) | | | {r['pooled'][0]:+.1f} ± {r['pooled'][1]:.1f}: {r['reading']} |")
    write_results(args.name, res, "\n".join(lines))


def _has_base(name: str) -> bool:
    from ohra.canonical.params import BaseParams

    try:
        return isinstance(get_hand(name), BaseParams)
    except Exception:
        return False


if __name__ == "__main__":
    run_script(main, __file__)
