"""The zero-shot study of issue 14 (paper Tables 7-9, Fig. 8) on the LEAP variants. Resumable like
``grasp_study.py``: training runs and evaluations are cached under ``--runs``, keyed by their
settings (``_study_cache.py``).

Models (``params`` condition, same architecture, steps, batch and seed):
* ``all``: every variant of the data with digit sum >= 8;
* ``zs-<variant>`` for each test variant: the same data without any grasp of that variant (held out
  by name and by parameters, ``GraspTrainConfig.test_hands``);
* ``only-<variant>`` for each low-sum variant (Table 8): that variant's grasps alone.

Tables: 7, success of ``all`` and ``zs-<v>`` on each test variant and the zero-shot / all-data ratio;
8, low-sum variants, ``all`` vs ``only-<v>`` with training counts (the ``all`` model here is
trained on the >= 8 variants, so low-sum variants are unseen by it, as in the paper); 9, ``leap_3033``
sampled with the conditions of other variants. Gallery: each unseen variant drawn by a model that never saw it
-> benchmarks/results/zeroshot_study_sheet.png and _scene.html. Fig. 8: condition saliency per parameter group for
``leap_3333`` and ``leap_3033`` (``all`` model) -> benchmarks/results/zeroshot_study_saliency.png.

Table 7 with touch (stop 46, written and committed before its run): the committed 20,000-step condition-noise
models of both training seeds (``runs/zeroshot_long``, ``runs/zeroshot_long_s1``), the same sampled grasps (sampling
seed 0) refined with ``--refine touch`` (sunk fingers opened, hovering ones closed onto the surface, as in the unified
study's Table 5) before the six-direction test; ``--tables 7``, results ``zeroshot_long_touch`` and
``zeroshot_long_touch_s1``, pooled by ``zeroshot_seeds.py`` into ``zeroshot_long_touch_seeds``. Reading: as the raw one,
the two-seed pooled ratio per test variant against 0.95, with its object-cluster interval; it is reported next to the
raw-sample reading (``zeroshot_long_seeds``), which stays. Expected if touch adds the same points to both sides (it
added ~12 to the unified model): ``leap_3330`` rises only to ~0.88. No other refinement, seed or setting is tried
after seeing it.

Run: python benchmarks/zeroshot_study.py --data out/leap_zeroshot [...] [--steps 12000] [-n 100] [--runs runs/zeroshot_study] [--tables 7 8 9]
  -> benchmarks/results/zeroshot_study.{json,md}
Two cores: train the nine models in two processes first (``--train-only all zs-leap_3033 ...`` in one,
the other runs in the other), then run the study without the flag (``--workers 2`` for the simulations).
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import asdict
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, natural_sorted, run_script, script_parser, write_results  # noqa: E402
from _stats import ratio_interval  # noqa: E402
from _study_cache import cached, claim_run, eval_key, run_key, store, train_key, when_free  # noqa: E402

import numpy as np  # noqa: E402

from grasp_study import add_run_args, data_protocol, eval_objects, pictures  # noqa: E402
from ohra.data.dataset import require_manifest  # noqa: E402
from ohra.learn.grasp import GraspModelConfig, GraspTrainConfig  # noqa: E402
from ohra.learn.grasp.evaluate import evaluate_model  # noqa: E402
from ohra.learn.grasp.model import load_grasp_model  # noqa: E402
from ohra.learn.grasp.refine import RefineSettings  # noqa: E402
from ohra.learn.grasp.saliency import mean_condition_saliency, saliency_figure  # noqa: E402
from ohra.learn.grasp.train import train_grasp  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
TEST = ("leap_3033", "leap_3303", "leap_3330")
LOW = ("leap_0303", "leap_0312", "leap_2203", "leap_3030", "leap_3103")
WRONG = ("leap_3303", "leap_3330", "leap_3333")  # Table 9: conditions given to leap_3033
PAPER_ZS = {"leap_3303": 81.9}  # the abstract's zero-shot number; the others: paper Table 7
# core-seconds of every training run and simulation the study used (cached ones included), for its stated cost
COMPUTE: dict[str, dict[str, float]] = {"training": {}, "simulation": {}}


def digit_sum(h: str) -> int:
    return sum(int(c) for c in h[-4:])


def data_hands(data: list[str]) -> list[str]:
    out: dict[str, None] = {}
    for d in data:
        for h, e in require_manifest(d)["hands"].items():
            if sum(s.get("n_grasps", 0) for s in e["shards"].values()):
                out[h] = None
    return list(out)


def trained(name: str, data: list[str], hands: list[str], test_hands: tuple, args):
    run = Path(args.runs) / name

    def get():
        if claim_run(run, train_key(data, hands, args.steps, args.seed, "params", test_hands, args.condition_noise)):
            return load_grasp_model(run), json.loads((run / "metrics.json").read_text())
        tcfg = GraspTrainConfig(steps=args.steps, seed=args.seed, threads=args.threads, hands=tuple(hands), test_hands=test_hands,
                                condition_noise=args.condition_noise)
        res = train_grasp(data, GraspModelConfig(condition="params"), tcfg, run,
                          resume=(run / "checkpoints" / "last.pt").exists(), progress=not args.quiet)
        return res.model, res.metrics

    model, metrics = when_free(get)
    # core-seconds = wall seconds x threads: what the run occupied, whether or not it was cached now
    COMPUTE["training"][name] = metrics["train_seconds_total"] * metrics.get("threads", 1)
    return model, metrics["data"]["per_hand"]


def success(model, key: str, hand: str, objects: list, protocol, args, condition_hand: str | None = None) -> dict:
    """Success of ``hand`` sampled by ``model`` (conditioned on ``condition_hand`` if given: Table 9;
    the grasps run on the true hand), with the per-grasp verdicts per object (for the gallery), cached.
    Pair seeds are the evaluator's, so the true and the wrong conditions sample from the same noise."""
    settings = refine_settings(args)
    suffix = "" if settings is None else "_touched" if settings.touch else "_refined"
    path = Path(args.runs) / f"eval_{key}_{hand}{'_as_' + condition_hand if condition_hand else ''}{suffix}.json"
    extra = {"refine": asdict(settings)} if settings is not None else {}
    ekey = eval_key(run_key(Path(args.runs) / key), hand=hand, condition_hand=condition_hand,
                    objects=[o.name for o in objects], n=args.n, seed=0, protocol=protocol, **extra)
    if (hit := cached(path, ekey)) is None:
        hit = _simulate(model, hand, objects, protocol, args, condition_hand, path, ekey)
    COMPUTE["simulation"][path.stem] = hit.get("seconds", float("nan")) * hit.get("workers", 1)
    return hit


def _simulate(model, hand: str, objects: list, protocol, args, condition_hand: str | None, path: Path, ekey: dict) -> dict:
    t0 = time.perf_counter()
    rep = evaluate_model(model, [hand], objects, n=args.n, seed=0, protocol=protocol, workers=args.workers,
                         condition_hand=condition_hand, refine=refine_settings(args) or False)
    ok = np.concatenate([p.success for p in rep.pairs])
    out = {"n": int(len(ok)), "successes": int(ok.sum()), "success_rate": float(ok.mean()),
           "success": {f"{p.hand}/{p.object}": p.success.astype(int).tolist() for p in rep.pairs},
           "seconds": time.perf_counter() - t0, "workers": args.workers}
    return store(path, ekey, out)


def refine_settings(args) -> RefineSettings | None:
    """The test-time refinement ``--refine`` asks for: None (raw samples), ``open`` or ``touch``."""
    if not args.refine:
        return None
    return RefineSettings(touch=args.refine == "touch")


def pct(r: dict) -> str:
    return f"{100 * r['success_rate']:.1f} %"


def main() -> None:
    ap = script_parser(__doc__, __file__)
    ap.add_argument("--data", nargs="+", required=True)
    ap.add_argument("--objects-file", type=Path, default=ROOT / "recipes" / "grasp_eval_objects.yaml")
    add_run_args(ap, steps=12000, n=100, runs="zeroshot_study", name="zeroshot_study")
    ap.add_argument("--refine", nargs="?", const="open", choices=("open", "touch"),
                    help="evaluate the sampled grasps with their fingers refined (ohra.learn.grasp.refine): 'open' (the "
                         "default of a bare --refine) opens sunk fingers, 'touch' also closes hovering ones onto the surface; "
                         "cached apart from the plain evaluations")
    ap.add_argument("--condition-noise", type=float, default=0.0,
                    help="GraspTrainConfig.condition_noise of every model (std in standardised condition units; 0: none); "
                         "use another --runs and --name")
    ap.add_argument("--train-only", nargs="+", metavar="RUN",
                    help="train these runs (all, zs-<variant>, only-<variant>) and stop: several study processes with "
                         "different runs use one core each; a last run without the flag reuses them")
    ap.add_argument("--tables", nargs="+", choices=("7", "8", "9"), default=["7", "8", "9"],
                    help="tables to compute (default all); a partial study trains and simulates only what those need "
                         "and says in its outputs which tables it left out")
    args = ap.parse_args()
    args.data = natural_sorted(args.data)  # s2 before s10, whatever the glob gave
    hands = data_hands(args.data)
    high = [h for h in hands if digit_sum(h) >= 8]
    # every run of the study: name -> (training hands, held-out hands)
    specs = {"all": (high, ())}
    specs.update({f"zs-{v}": ([h for h in high if h != v], (v,)) for v in TEST if v in high})
    specs.update({f"only-{v}": ([v], ()) for v in LOW if v in hands})
    if args.train_only:
        unknown = [r for r in args.train_only if r not in specs]
        if unknown:
            print(f"zeroshot_study: --train-only: unknown run(s) {unknown}; this data has {list(specs)}", file=sys.stderr)
            raise SystemExit(2)
        for r in args.train_only:
            trained(r, args.data, *specs[r], args)
        return
    objects = eval_objects(args.objects_file)
    protocol = data_protocol(args.data)
    res: dict = {"steps": args.steps, "n": args.n, "refine": args.refine or False, "condition_noise": args.condition_noise, "objects": [o.name for o in objects],
                 "variants_with_grasps": len(high), "tables": sorted(args.tables)}
    all_model, counts = trained("all", args.data, *specs["all"], args)
    res["train_counts"] = counts
    lines = ["Table 7 analogue: all-data vs zero-shot models on the test variants (unseen objects)", "",
             "| variant | all-data | zero-shot | ratio | ratio, 95 % interval | grasps of the variant in all-data training |",
             "|---|---|---|---|---|---|"]
    skipped = "| (not computed in this run: `--tables` " + " ".join(sorted(args.tables)) + ") |"
    if "7" not in args.tables:
        lines.append(skipped + " |" * 5)
    # the zero-shot models the chosen tables use: every test variant's for Table 7, zs-leap_3033 for Table 9
    zs_needed = [v for v in TEST if v in high and ("7" in args.tables or (v == "leap_3033" and "9" in args.tables))]
    res["table7"], zs_models = {}, {}
    for v in zs_needed:
        zs, _ = trained(f"zs-{v}", args.data, *specs[f"zs-{v}"], args)
        zs_models[v] = zs
        if "7" not in args.tables:
            continue
        a, z = success(all_model, "all", v, objects, protocol, args), success(zs, f"zs-{v}", v, objects, protocol, args)
        ratio = z["success_rate"] / a["success_rate"] if a["success_rate"] else float("nan")
        lo, hi = ratio_interval(z["success"], a["success"])
        res["table7"][v] = {"all": a, "zero_shot": z, "ratio": ratio, "ratio_interval": [lo, hi]}
        lines.append(f"| {v} | {pct(a)} | {pct(z)} | {ratio:.2f} | {lo:.2f}-{hi:.2f} | {counts.get(v, 0)} |")
    lines += ["", "Table 8 analogue: low-sum variants, all-data (never trained on them) vs variant-specific", "",
              "| variant | all-data | variant-specific | specific training grasps |", "|---|---|---|---|"]
    res["table8"] = {}
    if "8" not in args.tables:
        lines.append(skipped + " |" * 3)
    for v in LOW:
        if v not in hands or "8" not in args.tables:
            continue
        only, c = trained(f"only-{v}", args.data, *specs[f"only-{v}"], args)
        a, s = success(all_model, "all", v, objects, protocol, args), success(only, f"only-{v}", v, objects, protocol, args)
        res["table8"][v] = {"all": a, "specific": s, "specific_grasps": c.get(v, 0)}
        lines.append(f"| {v} | {pct(a)} | {pct(s)} | {c.get(v, 0)} |")
    lines += ["", "Table 9 analogue: leap_3033 sampled with other variants' conditions", "",
              "| condition | all-data | zero-shot (zs-leap_3033) |", "|---|---|---|"]
    res["table9"] = {}
    if "9" not in args.tables:
        lines.append(skipped + " |" * 2)
    elif "leap_3033" in high:
        zs3033 = zs_models["leap_3033"]
        for c in ("leap_3033",) + WRONG:
            a = success(all_model, "all", "leap_3033", objects, protocol, args, None if c == "leap_3033" else c)
            z = success(zs3033, "zs-leap_3033", "leap_3033", objects, protocol, args, None if c == "leap_3033" else c)
            res["table9"][c] = {"all": a, "zero_shot": z}
            lines.append(f"| {c}{' (true)' if c == 'leap_3033' else ''} | {pct(a)} | {pct(z)} |")
    # gallery: every variant drawn by a model that never saw a grasp of it (zs-<v> for the test
    # variants; the all-data model for the low-sum ones, which it was not trained on)
    gallery_models, gallery_ev = {}, {"success": {}}
    for v, r in res["table7"].items():
        gallery_models[v] = zs_models[v]
        gallery_ev["success"].update(r["zero_shot"]["success"])
    for v, r in res["table8"].items():
        gallery_models[v] = all_model
        gallery_ev["success"].update(r["all"]["success"])
    if gallery_models:
        res["pictures"] = pictures(gallery_models, list(gallery_models), objects, gallery_ev, args.name,
                                   title="unseen LEAP variants (rows; each drawn by a model never trained on it): "
                                         "first passing grasp per unseen object; red: none passed",
                                   refine=refine_settings(args) or False)
    sal = {h: mean_condition_saliency(all_model, h, objects, n=64, seed=0) for h in ("leap_3333", "leap_3033")}
    res["saliency"] = {h: r["groups"] for h, r in sal.items()}
    RESULTS.mkdir(parents=True, exist_ok=True)
    saliency_figure(sal, str(RESULTS / f"{args.name}_saliency.png"), title=f"condition saliency, all-data model, mean over {len(objects)} objects")
    lines += ["", f"Fig. 8 analogue (condition saliency, mean gradient norm per group, averaged over the {len(objects)} "
              "evaluation objects, 64 wrist rotations each):", "",
              "| hand | " + " | ".join(next(iter(res["saliency"].values()))) + " |",
              "|---|" + "---|" * len(next(iter(res["saliency"].values())))]
    for h, g in res["saliency"].items():
        lines.append(f"| {h} | " + " | ".join(f"{v:.3g}" for v in g.values()) + " |")
    if res["table7"]:
        lines += ["", "Ratio intervals: a bootstrap over the evaluation objects (the same objects drawn for both models) "
                  "and over each drawn object's grasps (`benchmarks/_stats.py`, 4,000 replicates, seed 0)."]
    lines += ["", f"Budget: {args.steps} steps per model; {args.n} grasps per (variant, object) on {len(objects)} unseen objects"
              + (f"; condition noise {args.condition_noise:g} (std, standardised units) in training" if args.condition_noise else "")
              + ({"open": "; fingers refined before simulation (`--refine`: sunk fingers opened).",
                  "touch": "; fingers refined before simulation (`--refine touch`: sunk fingers opened, hovering ones "
                           "closed onto the surface)."}.get(args.refine, "."))]
    train_h = sum(COMPUTE["training"].values()) / 3600
    sim_h = sum(COMPUTE["simulation"].values()) / 3600
    res["compute"] = {**COMPUTE, "training_core_hours": train_h, "simulation_core_hours": sim_h}
    lines += ["", f"Compute (core-hours = wall time x threads or simulation processes, cached runs included): training "
              f"{train_h:.2f} ({len(COMPUTE['training'])} models, "
              + ", ".join(f"{k} {v / 60:.0f} core-min" for k, v in COMPUTE["training"].items())
              + f"); simulation {sim_h:.2f} ({len(COMPUTE['simulation'])} evaluations)."]
    if "pictures" in res:
        lines += ["", f"Gallery of unseen variants: `{res['pictures']['sheet']}` (contact sheet), `{res['pictures']['scene']}` "
                  "(meshcat; regenerated by the study, not committed)."]
    write_results(args.name, res, "\n".join(lines))


if __name__ == "__main__":
    run_script(main, __file__)
