"""How the unified grasp model's success on unseen objects grows with its training data (issue 13).

The same model, steps, batch and seed trained on the first 1, 2, ... dataset folders given (in
order: each folder is one more seed of the same recipe), each evaluated with the same sampled
grasps per (hand, object) on a fixed subset of the evaluation objects, with the protocol the data
was filtered with. It answers "is data the limit?" before the full study is run: if success still
rises with each seed, more seeds are the lever; if it is flat, the model or the budget is.

Resumable: every training run and evaluation is cached under ``--runs`` (see ``grasp_study.py``).

Run: python benchmarks/grasp_data_scaling.py --data datasets/grasp_unified_s0 datasets/grasp_unified_s1 [...]
       [--steps 3000] [-n 40] [--objects procedural:box:500 procedural:cylinder:500 @objects/ycb/PottedMeatCan]
  -> benchmarks/results/grasp_data_scaling.{json,md}
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import natural_sorted, run_script, script_parser, write_results  # noqa: E402
from grasp_study import ROOT, add_run_args, data_protocol, evaluated, protocol_note, trained  # noqa: E402

from ohra.data.recipe import Recipe  # noqa: E402

DEFAULT_OBJECTS = ["procedural:box:500", "procedural:cylinder:500", "@objects/ycb/PottedMeatCan"]


def objects(specs: list[str]) -> list:
    """Evaluation objects from specs (``@objects/`` = the shared object root), resolved as a recipe would."""
    return Recipe.from_dict({"hands": ["leap_3333"], "objects": specs}, ROOT / "recipes" / "scaling.yaml").resolve_objects()


def table(res: dict) -> str:
    hands = res["hands"]
    lines = [f"Unified grasp model vs training data: {res['steps']} steps each (same batch, seed), {res['n']} sampled grasps "
             f"per (hand, object) on {len(res['objects'])} unseen objects ({', '.join(res['objects'])}), protocol {res['protocol_note']}.",
             "", "| data folders | " + " | ".join(f"{h}: grasps / success" for h in hands) + " | all hands |",
             "|---|" + "---|" * (len(hands) + 1)]
    for row in res["rows"]:
        cells = [f"{row['counts'].get(h, 0)} / {100 * row['per_hand'][h]['success_rate']:.1f} %" for h in hands]
        tot = sum(row["per_hand"][h]["success_rate"] * row["per_hand"][h]["n"] for h in hands) / sum(row["per_hand"][h]["n"] for h in hands)
        lines.append(f"| {row['k']} ({sum(row['counts'].values())} grasps) | " + " | ".join(cells) + f" | {100 * tot:.1f} % |")
    return "\n".join(lines)


def main() -> None:
    ap = script_parser(__doc__, __file__)
    ap.add_argument("--data", nargs="+", required=True, help="dataset folders, in the order they are added")
    ap.add_argument("--hands", nargs="+", default=["allegro_hand_left", "barrett_hand", "shadow_hand_right"])
    ap.add_argument("--objects", nargs="+", default=DEFAULT_OBJECTS)
    ap.add_argument("--ks", type=int, nargs="+", default=None, help="only these prefix lengths (default 1..len(--data))")
    add_run_args(ap, steps=3000, n=40, runs="grasp_scaling", name="grasp_data_scaling")
    args = ap.parse_args()
    bad = [k for k in args.ks or () if k > len(args.data)]
    if bad:  # a model named unified-k5 trained on fewer folders would mislabel its row
        ap.error(f"--ks {' '.join(map(str, bad))}: more than the {len(args.data)} --data folder(s) given")
    objs = objects(args.objects)
    args.data = natural_sorted(args.data)  # s2 before s10, whatever the glob gave
    protocol = data_protocol(args.data)
    res = {"hands": args.hands, "steps": args.steps, "n": args.n, "objects": [o.name for o in objs], "data": args.data,
           "protocol_note": protocol_note(protocol), "rows": []}
    for k in args.ks or range(1, len(args.data) + 1):
        model = trained(f"unified-k{k}", args.data[:k], args.hands, args)
        ev = evaluated(model, f"unified-k{k}", args.hands, objs, False, protocol, args)
        counts = json.loads((Path(args.runs) / f"unified-k{k}" / "metrics.json").read_text())["data"]["per_hand"]
        res["rows"].append({"k": k, "data": args.data[:k], "counts": counts, "per_hand": ev["per_hand"]})
    write_results(args.name, res, table(res))
    print(table(res))


if __name__ == "__main__":
    run_script(main, __file__)
