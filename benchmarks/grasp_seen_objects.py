"""The unified grasp model on objects it was trained on vs objects it never saw (issue 13).

Success on unseen objects is well below the paper's (README, Table 5 analogue). This measures how much
of that is object generalisation: the committed study's unified model is evaluated exactly as in the
study (``-n`` grasps per (hand, object), sampling seed 0, uniformly random wrist rotations, the data's
protocol, canonical URDFs) on 13 of its training objects chosen like the 13 evaluation objects (three
YCB objects, two shapes of every procedural family: ``recipes/grasp_seen_objects.yaml``), and
compared with its unseen-object evaluation (``runs/grasp_study/eval_unified.json``).

How it is read, written before this evaluation was run (stop 44): pooled over the three hands (3,900
grasps each), seen - unseen above two standard errors (independent binomials) reads as "an object
generalisation gap": more objects in training are a lever; within two standard errors, the model does
as well on objects it never saw, and the gap to the paper lies in what it learnt from its data (its fit of
the grasp distribution, the data's own pass rate under this protocol), not in generalisation. Per-hand
differences are shown, not read as verdicts. One sampling seed; no further runs in the stop that sees it.

Added after the run, not part of the rule (so read as description): the optimiser's own outcome on the
same (hand, training object) pairs, summed over the data's manifests (``n_sim_passed`` and robust
``n_grasps`` per candidate), and the rank correlation of the model's per-pair success with them: whether
the model succeeds where the optimiser's candidates pass.

Run: python benchmarks/grasp_seen_objects.py --data datasets/grasp_unified_s{0..22} [-n 100] [--workers 1]
       [--runs runs/grasp_study]  -> benchmarks/results/grasp_seen_objects.{json,md}
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import natural_sorted, run_script, script_parser, write_results  # noqa: E402
from _study_cache import cached, eval_key, run_key, store  # noqa: E402
from grasp_scale_up import baseline, difference, pooled  # noqa: E402
from grasp_study import PAPER, ROOT, data_protocol, eval_objects, protocol_note  # noqa: E402

import numpy as np  # noqa: E402
from scipy.stats import spearmanr  # noqa: E402

from ohra.data.dataset import read_manifest  # noqa: E402
from ohra.learn.grasp.evaluate import evaluate_model  # noqa: E402
from ohra.learn.grasp.model import load_grasp_model  # noqa: E402


def optimiser_outcomes(data: list[str]) -> dict[str, np.ndarray]:
    """``"<hand>/<object>"`` -> [candidates, solved, passed the six-direction test once, robust grasps kept],
    summed over the folders' manifests."""
    out: dict[str, np.ndarray] = {}
    for d in data:
        man = read_manifest(Path(d) / "manifest.json") or {}
        for h, e in man.get("hands", {}).items():
            for k, sh in e.get("shards", {}).items():
                row = np.array([sh.get(f, 0) for f in ("n_candidates", "n_solved", "n_sim_passed", "n_grasps")], dtype=float)
                out[f"{h}/{k}"] = out.get(f"{h}/{k}", np.zeros(4)) + row
    return out


def main() -> None:
    ap = script_parser(__doc__, __file__)
    ap.add_argument("--data", nargs="+", required=True, help="the data the model was trained on (its protocol)")
    ap.add_argument("--hands", nargs="+", default=list(PAPER))
    ap.add_argument("--seen-file", type=Path, default=ROOT / "recipes" / "grasp_seen_objects.yaml")
    ap.add_argument("--unseen-file", type=Path, default=ROOT / "recipes" / "grasp_eval_objects.yaml")
    ap.add_argument("-n", type=int, default=100)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--runs", type=Path, default=ROOT / "runs" / "grasp_study")
    ap.add_argument("--name", default="grasp_seen_objects")
    args = ap.parse_args()
    args.data = natural_sorted(args.data)
    protocol = data_protocol(args.data)
    unseen_objs, seen_objs = eval_objects(args.unseen_file), eval_objects(args.seen_file)
    unseen = baseline(args.runs, unseen_objs, args.n, protocol)
    model = load_grasp_model(args.runs / "unified")
    trained_on = model.meta.get("train_objects", {})  # name -> mesh hash
    if missing := [o.name for o in seen_objs if trained_on.get(o.name) != o.mesh_hash]:
        raise SystemExit(f"{args.seen_file}: {missing} not among the model's training objects (by name and mesh hash)")
    path = args.runs / "eval_unified_seen.json"
    key = eval_key(run_key(args.runs / "unified"), hands=args.hands, objects=[o.name for o in seen_objs], n=args.n, seed=0,
                   original=False, protocol=protocol)
    if (seen := cached(path, key)) is None:
        t0 = time.perf_counter()
        rep = evaluate_model(model, args.hands, seen_objs, n=args.n, seed=0, protocol=protocol, workers=args.workers,
                             allow_seen=True)
        seen = store(path, key, {"per_hand": rep.per_hand(),
                                 "success": {p.hand + "/" + p.object: p.success.astype(int).tolist() for p in rep.pairs},
                                 "seconds": time.perf_counter() - t0})
    comp = {h: difference(pooled(unseen, [h]), pooled(seen, [h])) for h in args.hands}
    d, se = difference(pooled(unseen, args.hands), pooled(seen, args.hands))
    reading = "an object generalisation gap" if d > 2 * se else ("seen below unseen" if d < -2 * se else "no gap detectable")
    res = {"hands": args.hands, "n": args.n, "protocol_note": protocol_note(protocol),
           "seen_objects": [o.name for o in seen_objs], "unseen_objects": [o.name for o in unseen_objs],
           "seen": {h: float(pooled(seen, [h]).mean()) for h in args.hands},
           "unseen": {h: float(pooled(unseen, [h]).mean()) for h in args.hands},
           "seen_minus_unseen": {h: list(v) for h, v in comp.items()}, "pooled": [d, se], "reading": reading,
           "seen_pairs": {k: sum(v) / len(v) for k, v in seen["success"].items()}}
    opt = optimiser_outcomes(args.data)
    keys = sorted(res["seen_pairs"])
    res["optimiser"] = {}
    for h in args.hands:
        cand, _, passed, robust = sum(opt[k] for k in keys if k.startswith(h + "/"))
        res["optimiser"][h] = {"candidates": int(cand), "passed_per_candidate": float(passed / cand),
                               "robust_per_candidate": float(robust / cand)}
    model_rate = [res["seen_pairs"][k] for k in keys]
    res["spearman_model_vs_optimiser_passed"] = float(spearmanr(model_rate, [opt[k][2] / opt[k][0] for k in keys]).statistic)
    res["spearman_model_vs_optimiser_robust"] = float(spearmanr(model_rate, [opt[k][3] / opt[k][0] for k in keys]).statistic)
    lines = [f"The committed unified model (`runs/grasp_study/unified`) on {len(seen_objs)} training objects vs the "
             f"{len(unseen_objs)} unseen evaluation objects: {args.n} grasps per (hand, object), sampling seed 0, protocol "
             f"{res['protocol_note']}, canonical URDFs. Rule written before the run (script docstring).", "",
             "| hand | seen (training objects) | unseen | seen - unseen ± SE [points] |", "|---|---|---|---|"]
    for h in args.hands:
        lines.append(f"| {h} | {100 * res['seen'][h]:.1f} % | {100 * res['unseen'][h]:.1f} % | {comp[h][0]:+.1f} ± {comp[h][1]:.1f} |")
    lines.append(f"| pooled | {100 * pooled(seen, args.hands).mean():.1f} % | {100 * pooled(unseen, args.hands).mean():.1f} % | "
                 f"{d:+.1f} ± {se:.1f}: {reading} |")
    lines += ["", "Seen objects: " + ", ".join(res["seen_objects"]) + ".", "",
              "Described after the run (not part of the rule): the optimiser's own candidates on the same (hand, training "
              "object) pairs, over the data's manifests, and the rank correlation of the model's per-pair success with them "
              f"over the {len(keys)} pairs.", "",
              "| hand | model, seen objects | optimiser: passed once per candidate | optimiser: robust grasps kept per candidate | candidates |",
              "|---|---|---|---|---|"]
    for h in args.hands:
        o = res["optimiser"][h]
        lines.append(f"| {h} | {100 * res['seen'][h]:.1f} % | {100 * o['passed_per_candidate']:.1f} % | "
                     f"{100 * o['robust_per_candidate']:.1f} % | {o['candidates']} |")
    lines += ["", f"Spearman rank correlation of the model's per-pair success with the optimiser's: "
              f"{res['spearman_model_vs_optimiser_passed']:.2f} (passed once), {res['spearman_model_vs_optimiser_robust']:.2f} (robust)."]
    write_results(args.name, res, "\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    run_script(main, __file__)
