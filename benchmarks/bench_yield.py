"""Yield of the data engine per CPU-second: what the NLP's finger-pair rows cost and what they save.

A fixed sample decided before running: the recipe's (``recipes/grasp_unified.yaml``) hands, 8 of its
objects evenly spaced through its object list, the recipe's 16 starts per pair, seed 0, its protocol
(isaac-drive) and robustness trials. Each variant of ``NLPSettings.finger_pairs`` synthesises every
(hand, object) shard in this process (:func:`ohra.synth.pipeline.synthesize_shard`) and the table
reports per hand: share of starts that converge, that converge but self-collide (exact Coal check,
status ``Self_Collision``), that pass the simulated test (verified) and the robustness trials
(robust), mean IPOPT iterations, CPU seconds (``time.process_time``, what an idle core would take) and
verified / robust grasps per CPU-second.

Run: python benchmarks/bench_yield.py [--hands ...] [--variants spheres capsules] [--cache DIR]
Each (hand, variant) is cached as JSON in ``--cache`` so runs can be split across processes;
``--report`` writes benchmarks/results/yield.{json,md} from the cache.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import write_results  # noqa: E402

import numpy as np  # noqa: E402

from ohra.data.recipe import Recipe  # noqa: E402
from ohra.synth.pipeline import STATUS_CODES, synthesize_shard  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
RECIPE = ROOT / "recipes" / "grasp_unified.yaml"
N_OBJECTS = 8


def sample_objects(objects: list, n: int = N_OBJECTS) -> list:
    """``n`` objects evenly spaced through the recipe's list (procedural families and YCB alike)."""
    idx = np.unique(np.linspace(0, len(objects) - 1, n).round().astype(int))
    return [objects[i] for i in idx]


def run(hand: str, variant: str, starts: int, seed: int) -> dict:
    """Synthesise the sample for one hand and one ``finger_pairs`` variant; counts and CPU time."""
    r = Recipe.load(RECIPE)
    params = dict(r.resolve_hands())[hand]
    base = r.synth_settings()
    settings = replace(base, grasps_per_object=starts, seed=seed, nlp=replace(base.nlp, finger_pairs=variant))
    per_obj, tot = [], {"starts": 0, "converged": 0, "self_collision": 0, "prefiltered": 0, "verified": 0, "robust": 0,
                        "iterations": 0, "cpu_s": 0.0, "solve_s": 0.0, "sim_s": 0.0}
    for obj in sample_objects(r.resolve_objects()):
        cpu0 = time.process_time()
        a = synthesize_shard(hand, params, obj, settings)
        cpu = time.process_time() - cpu0  # includes the solver build, as a shard does
        row = {"object": obj.name, "starts": int(len(a["raw"])), "converged": int(a["solver_success"].sum()),
               "self_collision": int((a["solver_status"] == STATUS_CODES["Self_Collision"]).sum()),
               "prefiltered": int(a["prefiltered"].sum()), "verified": int(a["sim_success"].sum()),
               "robust": int(a["robust_success"].sum()), "iterations": int(a["iterations"].sum()), "cpu_s": cpu,
               "solve_s": a["_timing"]["solve_s"], "sim_s": a["_timing"]["sim_s"]}
        per_obj.append(row)
        for k in tot:
            tot[k] += row[k]
        print(f"{hand} {variant} {obj.name}: {row}", flush=True)
    return {"hand": hand, "variant": variant, "starts_per_pair": starts, "seed": seed, "total": tot, "objects": per_obj}


def table(runs: list[dict]) -> str:
    lines = ["# Yield per CPU-second: finger-pair rows of the grasp NLP", "",
             f"Recipe `{RECIPE.relative_to(ROOT)}` (protocol isaac-drive, 2 robustness trials), {N_OBJECTS} of its objects evenly "
             "spaced through its list, 16 starts per pair, seed 0, one process (`benchmarks/bench_yield.py`). "
             "Shares are of all starts; CPU is `time.process_time` of the whole shard (build, solves, simulation).", "",
             "| hand | finger pairs | starts | converged | self-collision | verified | robust | iterations/start | CPU s | verified/CPU-s | robust/CPU-s |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in sorted(runs, key=lambda r: (r["hand"], r["variant"] != "spheres")):
        t = t_ = r["total"]
        n = max(t["starts"], 1)
        lines.append(f"| {r['hand']} | {r['variant']} | {n} | {t['converged'] / n:.0%} | {t['self_collision'] / n:.0%} | "
                     f"{t['verified'] / n:.0%} | {t['robust'] / n:.0%} | {t['iterations'] / n:.0f} | {t_['cpu_s']:.0f} | "
                     f"{t['verified'] / t['cpu_s']:.3f} | {t['robust'] / t['cpu_s']:.3f} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hands", nargs="+", default=["allegro_hand_left", "barrett_hand", "shadow_hand_right"])
    ap.add_argument("--variants", nargs="+", default=["spheres", "capsules"])
    ap.add_argument("--starts", type=int, default=16)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--cache", type=Path, default=Path("/tmp/ohra_bench_yield"))
    ap.add_argument("--report", action="store_true", help="only write results/yield.{json,md} from the cache")
    a = ap.parse_args(argv)
    a.cache.mkdir(parents=True, exist_ok=True)
    if not a.report:
        for hand in a.hands:
            for variant in a.variants:
                res = run(hand, variant, a.starts, a.seed)
                (a.cache / f"{hand}-{variant}.json").write_text(json.dumps(res, indent=1))
    runs = [json.loads(p.read_text()) for p in sorted(a.cache.glob("*.json"))]
    write_results("yield", {"runs": runs}, table(runs))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
