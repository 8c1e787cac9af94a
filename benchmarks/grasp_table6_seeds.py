"""Table 6 of the grasp study (unified vs hand-specific) over more sampling seeds, pooled.

The study samples 100 grasps per (hand, unseen object) with sampling seed 0; a difference of two such
1,300-grasp rates has a standard error of ~2 points, the size of the differences Table 6 reads. This
script evaluates the study's committed models (``runs/grasp_study``: ``unified`` and ``specific-<hand>``,
no training) again with further sampling seeds (other wrist rotations and diffusion noise, same
objects and protocol), caches each evaluation beside the study's (``eval_unified_<hand>_seed<S>.json``, ``eval_specific-<hand>_seed<S>.json``:
one per model and hand, so an interrupted run keeps the hands it finished), and
writes per hand each seed's unified and specific success and the pooled difference with its standard
error (two independent samples of grasps per model).

    python benchmarks/grasp_table6_seeds.py --data datasets/grasp_unified_s{0..22} [--seeds 0 1] [--workers 2]
    -> benchmarks/results/grasp_table6_seeds.{json,md}
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import natural_sorted, run_script, script_parser, write_results  # noqa: E402

import numpy as np  # noqa: E402

from grasp_study import PAPER, ROOT, data_protocol, eval_objects, evaluated  # noqa: E402
from ohra.learn.grasp.model import load_grasp_model  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    ap = script_parser(__doc__, __file__)
    ap.add_argument("--data", nargs="+", required=True, help="the study's datasets (for its protocol)")
    ap.add_argument("--hands", nargs="+", default=list(PAPER))
    ap.add_argument("--seeds", nargs="+", type=int, default=[0, 1])
    ap.add_argument("--objects-file", type=Path, default=ROOT / "recipes" / "grasp_eval_objects.yaml")
    ap.add_argument("-n", type=int, default=100)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--runs", default=str(ROOT / "runs" / "grasp_study"))
    ap.add_argument("--name", default="grasp_table6_seeds")
    args = ap.parse_args(argv)
    args.data = natural_sorted(args.data)
    objects, protocol = eval_objects(args.objects_file), data_protocol(args.data)
    res: dict = {"hands": args.hands, "seeds": args.seeds, "n": args.n, "objects": [o.name for o in objects], "per_seed": {}}
    unified = load_grasp_model(Path(args.runs) / "unified")
    for s in args.seeds:
        res["per_seed"][s] = {}
        for h in args.hands:  # one cached evaluation per model and hand: an interrupted run keeps whole hands
            if s == 0:  # the study's own evaluation (all hands at once)
                u = evaluated(unified, "unified", args.hands, objects, False, protocol, args)
            else:
                u = evaluated(unified, "unified", [h], objects, False, protocol, args, seed=s, tag=f"_{h}")
            res["per_seed"][s].setdefault("unified", {"per_hand": {}})["per_hand"][h] = u["per_hand"][h]
            m = load_grasp_model(Path(args.runs) / f"specific-{h}")
            res["per_seed"][s][h] = evaluated(m, f"specific-{h}", [h], objects, False, protocol, args, seed=s)
    lines = [f"Table 6 analogue over sampling seeds {', '.join(map(str, args.seeds))}: the study's unified and hand-specific "
             f"models (`runs/grasp_study`, not retrained), {args.n} grasps per (hand, unseen object) per seed on "
             f"{len(objects)} objects; pooled = all seeds' grasps together; SE of the difference of two independent rates.", "",
             "| hand | " + " | ".join(f"seed {s}: unified / specific" for s in args.seeds)
             + " | pooled unified | pooled specific | unified - specific ± SE [points] |",
             "|---|" + "---|" * len(args.seeds) + "---|---|---|"]
    res["pooled"] = {}
    for h in args.hands:
        cells, k = [], {"u": [0, 0], "s": [0, 0]}
        for s in args.seeds:
            u, sp = res["per_seed"][s]["unified"]["per_hand"][h], res["per_seed"][s][h]["per_hand"][h]
            cells.append(f"{100 * u['success_rate']:.1f} / {100 * sp['success_rate']:.1f} %")
            for key, r in (("u", u), ("s", sp)):
                k[key][0] += round(r["success_rate"] * r["n"])
                k[key][1] += r["n"]
        a, b = k["u"][0] / k["u"][1], k["s"][0] / k["s"][1]
        se = np.sqrt(a * (1 - a) / k["u"][1] + b * (1 - b) / k["s"][1])
        res["pooled"][h] = {"unified": a, "specific": b, "difference": a - b, "se": se, "n": k["u"][1]}
        lines.append(f"| {h} | " + " | ".join(cells) + f" | {100 * a:.1f} % | {100 * b:.1f} % | {100 * (a - b):+.1f} ± {100 * se:.1f} |")
    write_results(args.name, res, "\n".join(lines))
    return 0


if __name__ == "__main__":
    run_script(main, __file__)
