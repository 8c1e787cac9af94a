"""The unified grasp model on more data and more steps, on the full evaluation of the study (issue 13).

The committed study (``grasp_study.py``, Tables 4-6) trained its unified model on the first 23 seeds
of ``recipes/grasp_unified.yaml`` (9,431 robust grasps) for 12,000 steps. This script trains the same
model (architecture, batch, seed, VAE condition) on every folder given, once per step budget, and
evaluates each exactly as the study evaluated its unified model (``-n`` grasps per (hand, unseen
object) of ``recipes/grasp_eval_objects.yaml``, sampling seed 0, the data's protocol, canonical
URDFs), next to the committed evaluation (``runs/grasp_study/eval_unified.json``; refused when its
objects, grasps per pair, seed or protocol differ).

How it is read, written before any of these models was trained (stop 44):
1. data: the model of the smallest budget (12,000 steps) on all folders vs the committed unified
   model. Pooled over the three hands (3,900 grasps each), a difference of more than two standard
   errors (independent binomials) reads as "more data helped", less as "no change detectable at this
   budget"; per-hand differences are shown, not read as verdicts.
2. steps: each larger budget vs the smallest, both on all folders, with the same rule.
One training seed and one sampling seed; no further runs in the stop that sees the numbers. The shipped
model and Tables 4-6 stay the committed study's whatever this shows: a model that wins by the rule is
the candidate for the next full study.

Resumable: each training run and evaluation is cached under ``--runs`` (``_study_cache.py``); two
processes may train two budgets at once (``--steps 12000`` in one, ``--steps 24000`` in the other),
and a last call with every budget writes the table from the cache.

Run: python benchmarks/grasp_scale_up.py --data datasets/grasp_unified_s* [--steps 12000 24000] [-n 100]
       [--threads 1] [--workers 1] [--runs runs/grasp_scale_up] [--baseline runs/grasp_study]
  -> benchmarks/results/grasp_scale_up.{json,md}
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import natural_sorted, run_script, script_parser, write_results  # noqa: E402
from _study_cache import cached, eval_key, run_key  # noqa: E402
from grasp_study import PAPER, ROOT, data_protocol, eval_objects, evaluated, protocol_note, trained  # noqa: E402

import numpy as np  # noqa: E402


def baseline(runs: Path, objects: list, n: int, protocol) -> dict:
    """The committed study's unified evaluation, only when made on the same objects, grasps per pair,
    seed and protocol as this script's (else the comparison would not be like for like)."""
    path = runs / "eval_unified.json"
    old = json.loads(path.read_text())
    want = eval_key(run_key(runs / "unified"), hands=list(old["key"]["hands"]), objects=[o.name for o in objects], n=n,
                    seed=0, original=False, protocol=protocol)
    if cached(path, want) is None:
        raise SystemExit(f"{path}: made with other evaluation settings than this run's; pass the same -n and objects")
    return old


def pooled(ev: dict, hands: list[str], keys: list[str] | None = None) -> np.ndarray:
    """The per-grasp verdicts of ``hands`` (of the ``"<hand>/<object>"`` pairs in ``keys`` only, when given), concatenated."""
    return np.concatenate([np.asarray(v) for k, v in sorted(ev["success"].items())
                           if k.split("/", 1)[0] in hands and (keys is None or k in keys)])


def rates(ev: dict, hands: list[str]) -> dict:
    """Success per hand and pooled over ``hands`` of one evaluation."""
    return {"per_hand": {h: float(pooled(ev, [h]).mean()) for h in hands}, "pooled": float(pooled(ev, hands).mean())}


def paired_comparison(a: dict, b: dict, hands: list[str], what: str, readings: tuple[str, str] | None) -> dict:
    """b - a paired over the same grasps (rotations), pooled and per hand; ``readings`` (above +2 SE, below
    -2 SE) read the pooled difference, None: shown, not read."""
    from grasp_study import paired_change

    d, se = paired_change(a, b, hands)
    reading = ("shown, not read" if readings is None else readings[0] if d > 2 * se else readings[1] if d < -2 * se
               else "no change detectable")
    return {"what": what, "pooled": [d, se], "reading": reading, "per_hand": {h: list(paired_change(a, b, h)) for h in hands}}


def comparison_lines(comparisons: list[dict], hands: list[str], head: str = "comparison (paired over the same rotations)") -> list[str]:
    """Markdown rows of :func:`paired_comparison` results: per hand and pooled difference ± SE, and the reading."""
    lines = [f"| {head} | " + " | ".join(hands) + " | pooled ± SE [points] | reading |", "|---|" + "---|" * (len(hands) + 2)]
    for c in comparisons:
        lines.append(f"| {c['what']} | " + " | ".join(f"{c['per_hand'][h][0]:+.1f} ± {c['per_hand'][h][1]:.1f}" for h in hands)
                     + f" | {c['pooled'][0]:+.1f} ± {c['pooled'][1]:.1f} | {c['reading']} |")
    return lines


def require_data_of(run: Path, data: list[str]) -> None:
    """Exit with one line unless ``data`` are the folders (same content) the run was trained on."""
    from _study_cache import data_fingerprint

    if run_key(run)["data"] != data_fingerprint(data):
        raise SystemExit(f"--data differ from the data of {run}: pass the folders it was trained on")


def difference(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """b - a success [points] and its standard error, as two independent binomial samples."""
    pa, pb = a.mean(), b.mean()
    return 100 * (pb - pa), 100 * np.sqrt(pa * (1 - pa) / len(a) + pb * (1 - pb) / len(b))


def verdict(d: float, se: float, what: str) -> str:
    if d > 2 * se:
        return f"{what} helped"
    if d < -2 * se:
        return f"{what} hurt"
    return "no change detectable"


def table(res: dict) -> str:
    hands, rows = res["hands"], res["rows"]
    lines = [f"Unified grasp model (VAE condition, seed 0) vs training data and steps: {res['n']} sampled grasps per "
             f"(hand, object) on {len(res['objects'])} unseen objects, protocol {res['protocol_note']}, canonical URDFs. "
             "Rule written before training (script docstring): pooled difference > 2 SE reads as a change.", "",
             "| model | data | steps | train min (1 thread) | " + " | ".join(hands) + " | pooled |",
             "|---|---|---|---|" + "---|" * (len(hands) + 1)]
    for r in rows:
        lines.append(f"| {r['name']} | {r['grasps']} grasps ({r['folders']} folders) | {r['steps']} | "
                     + (f"{r['train_min']:.0f}" if r.get("train_min") else "-") + " | "
                     + " | ".join(f"{100 * r['per_hand'][h]:.1f} %" for h in hands) + f" | {100 * r['pooled']:.1f} % |")
    lines.append("| paper (reported, Isaac Gym) | 24,764 grasps | - | - | " + " | ".join(f"{PAPER.get(h, '-')} %" for h in hands)
                 + " | - |")
    lines += ["", "| comparison | " + " | ".join(hands) + " | pooled ± SE [points] | reading |", "|---|" + "---|" * (len(hands) + 2)]
    for c in res["comparisons"]:
        lines.append(f"| {c['what']} | " + " | ".join(f"{c['per_hand'][h][0]:+.1f} ± {c['per_hand'][h][1]:.1f}" for h in hands)
                     + f" | {c['pooled'][0]:+.1f} ± {c['pooled'][1]:.1f} | {c['reading']} |")
    return "\n".join(lines)


def main() -> None:
    ap = script_parser(__doc__, __file__)
    ap.add_argument("--data", nargs="+", required=True)
    ap.add_argument("--hands", nargs="+", default=list(PAPER))
    ap.add_argument("--objects-file", type=Path, default=ROOT / "recipes" / "grasp_eval_objects.yaml")
    ap.add_argument("--steps", type=int, nargs="+", default=[12000, 24000], help="step budgets, one model each")
    ap.add_argument("-n", type=int, default=100, help="sampled grasps per (hand, object)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--workers", type=int, default=1, help="simulation processes")
    ap.add_argument("--runs", default=str(ROOT / "runs" / "grasp_scale_up"))
    ap.add_argument("--baseline", type=Path, default=ROOT / "runs" / "grasp_study", help="the committed study's runs")
    ap.add_argument("--name", default="grasp_scale_up", help="results name")
    ap.add_argument("--quiet", action="store_true")
    args = ap.parse_args()
    args.data = natural_sorted(args.data)
    objects = eval_objects(args.objects_file)
    protocol = data_protocol(args.data)
    base = baseline(args.baseline, objects, args.n, protocol)
    base_cfg = json.loads((args.baseline / "unified" / "metrics.json").read_text())
    rows = [{"name": "committed unified (Tables 4-6)", "steps": base_cfg["steps"], "grasps": base_cfg["data"]["grasps"],
             "folders": len(run_key(args.baseline / "unified")["data"]), "ev": base,
             "train_min": base_cfg["train_seconds_total"] / 60}]
    for steps in sorted(args.steps):
        a = argparse.Namespace(**{**vars(args), "steps": steps})
        name = f"unified-{steps}"
        model = trained(name, args.data, args.hands, a)
        ev = evaluated(model, name, args.hands, objects, False, protocol, a)
        m = json.loads((Path(args.runs) / name / "metrics.json").read_text())
        rows.append({"name": name, "steps": steps, "grasps": m["data"]["grasps"], "folders": len(args.data), "ev": ev,
                     "train_min": m["train_seconds_total"] / 60, "eval_s": ev.get("seconds")})
    for r in rows:
        r["per_hand"] = {h: float(pooled(r["ev"], [h]).mean()) for h in args.hands}
        r["pooled"] = float(pooled(r["ev"], args.hands).mean())

    def compare(a: dict, b: dict, what: str, lever: str) -> dict:
        d, se = difference(pooled(a["ev"], args.hands), pooled(b["ev"], args.hands))
        return {"what": what, "pooled": [d, se], "reading": verdict(d, se, lever),
                "per_hand": {h: list(difference(pooled(a["ev"], [h]), pooled(b["ev"], [h]))) for h in args.hands}}

    comps = [compare(rows[0], rows[1], f"{rows[1]['name']} - committed (data)", "more data")] if len(rows) > 1 else []
    comps += [compare(rows[1], r, f"{r['name']} - {rows[1]['name']} (steps)", "more steps") for r in rows[2:]]
    res = {"hands": args.hands, "n": args.n, "objects": [o.name for o in objects], "data": args.data,
           "protocol_note": protocol_note(protocol), "comparisons": comps,
           "rows": [{k: v for k, v in r.items() if k != "ev"} for r in rows]}
    write_results(args.name, res, table(res))  # prints it too


if __name__ == "__main__":
    run_script(main, __file__)
