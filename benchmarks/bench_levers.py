"""Speed levers of the synthesis filter, measured on the datasets ``bench_synth.py --keep DIR`` left:

1. PyBullet solver settings: the converged candidates of each hand (YCB, 1 worker) re-simulated with
   fewer solver iterations / a looser residual threshold; agreement with the reference verdicts
   (100 iterations, 1e-7) and the time ratio. A setting is usable when agreement >= 98 %.
2. A cheap pre-filter: how many simulations a threshold on the candidates' penetration
   (``min_distance``) or Ferrari-Canny ``q1`` would skip, and how many verified grasps it would lose.
3. Stopping a pair early once a cap is met: the share of starts a cap would not try.

Run: python benchmarks/bench_levers.py --data DIR [--per-hand 40] -> benchmarks/results/levers.{json,md}
"""

from __future__ import annotations

import sys
import time
import warnings
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import run_script, script_parser, write_results  # noqa: E402

import numpy as np  # noqa: E402

from ohra.data.dataset import GraspDataset, read_manifest  # noqa: E402
from ohra.hands import get_hand  # noqa: E402
from ohra.objects.resolve import resolve_objects  # noqa: E402
from ohra.paths import objects_root  # noqa: E402
from ohra.sim import GraspEvaluator, Protocol  # noqa: E402

VARIANTS = {"iterations 50": {"solver_iterations": 50}, "iterations 30": {"solver_iterations": 30},
            "residual 1e-4": {"solver_residual_threshold": 1e-4}}


def candidates(root: Path, per_hand: int, seed: int = 0) -> list[tuple[str, str, np.ndarray, np.ndarray]]:
    """(hand, object, raw converged grasps, reference verdicts) per shard, at most ``per_hand`` in all."""
    ds = GraspDataset(root)
    out = []
    for hand, key in ds.pairs:
        sh = ds.load_shard(hand, key)
        idx = np.flatnonzero(sh["solver_success"])
        out.append((hand, key, sh["raw"][idx], sh["sim_success"][idx]))
    n = sum(len(g) for *_, g, _ in out)
    keep = set(np.random.default_rng(seed).permutation(n)[:per_hand].tolist())
    res, k = [], 0
    for hand, key, g, v in out:
        m = np.array([(k + i) in keep for i in range(len(g))], dtype=bool)
        k += len(g)
        if m.any():
            res.append((hand, key, g[m], v[m]))
    return res


def solver_settings(data: Path, per_hand: int) -> list[dict]:
    objs = {o.name: o for o in resolve_objects([str(objects_root() / "ycb")])}
    rows = []
    for d in sorted(data.glob("*-ycb-process-1")):
        hand = d.name.split("-ycb-")[0]
        cands = candidates(d, per_hand)
        times = {}
        verdicts = {name: [] for name in ["reference", *VARIANTS]}
        ref = []
        for name, over in [("reference", {}), *VARIANTS.items()]:
            prot = replace(Protocol(), **over)
            t = time.process_time()
            for h, key, g, v in cands:
                with GraspEvaluator(get_hand(h), objs[key], prot) as ev:
                    verdicts[name].append(ev.evaluate(g, mode="filter").success)
                if name == "reference":
                    ref.append(v)
            times[name] = time.process_time() - t
        stored = np.concatenate(ref)
        base = np.concatenate(verdicts["reference"])
        row = {"hand": hand, "grasps": int(len(base)), "reference_reproduces_stored": float((base == stored).mean()),
               "reference_pass": float(base.mean()), "reference_cpu_s": times["reference"]}
        for name in VARIANTS:
            v = np.concatenate(verdicts[name])
            row[name] = {"agreement": float((v == base).mean()), "pass": float(v.mean()), "time_ratio": times[name] / times["reference"]}
        rows.append(row)
        print(row, flush=True)
    return rows


def prefilter_and_cap(data: Path) -> list[dict]:
    rows = []
    for d in sorted(data.glob("*-ycb-process-1")):
        hand = d.name.split("-ycb-")[0]
        man = read_manifest(d / "manifest.json")
        ds = GraspDataset(d)
        md, q1, sim, kept, starts_cap = [], [], [], [], []
        for h, key in ds.pairs:
            sh = ds.load_shard(h, key)
            m = sh["solver_success"]
            md += sh["min_distance"][m].tolist()
            q1 += sh["q1"][m].tolist()
            sim += sh["sim_success"][m].tolist()
            kept += sh["robust_success"][m].tolist()
            cum = np.cumsum(sh["robust_success"])
            cap = 2
            starts_cap.append((int(np.searchsorted(cum, cap) + 1) if cum[-1] >= cap else len(cum), len(cum)))
        md, q1, sim, kept = map(np.asarray, (md, q1, sim, kept))
        row = {"hand": hand, "converged": int(len(md)), "grasps_per_object": man["settings"]["grasps_per_object"]}
        for thr in (-0.001, -0.0005):
            skip = md < thr
            row[f"min_distance<{1e3 * thr:g}mm"] = {"skipped": float(skip.mean()), "sim_failures_skipped": float((skip & ~sim).sum() / max((~sim).sum(), 1)),
                                                    "kept_lost": float((skip & kept).sum() / max(kept.sum(), 1))}
        lo = np.quantile(q1, 0.25) if len(q1) else 0.0
        skip = q1 < lo
        row["q1<lower quartile"] = {"skipped": float(skip.mean()), "sim_failures_skipped": float((skip & ~sim).sum() / max((~sim).sum(), 1)),
                                    "kept_lost": float((skip & kept).sum() / max(kept.sum(), 1))}
        tried = sum(a for a, _ in starts_cap)
        row["cap 2: starts tried"] = tried / max(sum(b for _, b in starts_cap), 1)
        rows.append(row)
        print(row, flush=True)
    return rows


def main() -> None:
    ap = script_parser(__doc__, __file__)
    ap.add_argument("--data", type=Path, required=True)
    ap.add_argument("--per-hand", type=int, default=40)
    args = ap.parse_args()
    if not sorted(args.data.glob("*-ycb-process-1")):  # nothing to measure: the results file is left as it is
        ap.error(f"--data {args.data} holds no bench_synth.py runs (*-ycb-process-1 folders; bench_synth.py --keep)")
    warnings.simplefilter("ignore")
    pre = prefilter_and_cap(args.data)
    sol = solver_settings(args.data, args.per_hand)
    lines = ["PyBullet solver settings on converged candidates (YCB; reference = 100 iterations, residual 1e-7; CPU time):", "",
             "| hand | grasps | reference pass | reference reproduces stored | " + " | ".join(f"{v}: agreement / time" for v in VARIANTS) + " |",
             "|---|---|---|---|" + "---|" * len(VARIANTS)]
    for r in sol:
        lines.append(f"| {r['hand']} | {r['grasps']} | {r['reference_pass']:.0%} | {r['reference_reproduces_stored']:.0%} | "
                     + " | ".join(f"{r[v]['agreement']:.0%} / {r[v]['time_ratio']:.2f}x" for v in VARIANTS) + " |")
    lines += ["", "Cheap pre-filters (share of converged candidates skipped, of simulation failures skipped, of verified grasps lost) "
              "and a cap of 2 kept grasps per pair (share of starts still tried):", "",
              "| hand | converged | min_distance < -1 mm | min_distance < -0.5 mm | q1 < lower quartile | cap 2: starts tried |", "|---|---|---|---|---|---|"]
    fmt = lambda d: f"{d['skipped']:.0%} / {d['sim_failures_skipped']:.0%} / {d['kept_lost']:.0%}"  # noqa: E731
    for r in pre:
        lines.append(f"| {r['hand']} | {r['converged']} | {fmt(r['min_distance<-1mm'])} | {fmt(r['min_distance<-0.5mm'])} | "
                     f"{fmt(r['q1<lower quartile'])} | {r['cap 2: starts tried']:.0%} |")
    write_results("levers", {"solver_settings": sol, "prefilter_and_cap": pre}, "\n".join(lines))


if __name__ == "__main__":
    run_script(main, __file__)
