"""Table 7 of the zero-shot study over several training seeds: each seed's ratio and the pooled one.

Reads the results of ``zeroshot_study.py`` runs that differ only in ``--seed`` (their JSON under
``benchmarks/results/``; no training, no simulation) and writes, per test variant, each seed's all-data and
zero-shot success with its ratio, and the pooled ratio (all seeds' zero-shot successes over all seeds'
all-data successes) with a 95 % interval from the object-cluster bootstrap over the pooled verdicts
(``_stats.pool``, ``_stats.ratio_interval``).

    python benchmarks/zeroshot_seeds.py zeroshot_long zeroshot_long_s1 [--name zeroshot_long_seeds]
    -> benchmarks/results/zeroshot_long_seeds.{json,md}
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import read_results, run_script, script_parser, write_results  # noqa: E402
from _stats import pool, ratio_interval  # noqa: E402

TARGET = 0.95  # issue 14: zero-shot / all-data ratio on each test variant


def rate(success: dict) -> float:
    n = sum(len(v) for v in success.values())
    return sum(map(sum, success.values())) / n if n else float("nan")


def main(argv: list[str] | None = None) -> int:
    ap = script_parser(__doc__, __file__)
    ap.add_argument("results", nargs="+", help="results names of zeroshot_study.py runs (benchmarks/results/NAME.json)")
    ap.add_argument("--name", default="zeroshot_long_seeds")
    args = ap.parse_args(argv)
    runs = read_results(args.results, "zeroshot_seeds")
    settings = {k: (r["steps"], r["n"], r["condition_noise"], r.get("refine", False), tuple(r["objects"])) for k, r in runs.items()}
    if len(set(settings.values())) != 1:
        shown = {k: f"steps {s[0]}, n {s[1]}, condition noise {s[2]}, refine {s[3]}, {len(s[4])} objects" for k, s in settings.items()}
        raise SystemExit(f"zeroshot_seeds: the runs differ in more than the seed: {shown}")
    variants = sorted(set.intersection(*(set(r["table7"]) for r in runs.values())))
    lines = [f"Table 7 over {len(runs)} training seeds ({', '.join(runs)}): zero-shot / all-data success per seed and pooled", "",
             "| variant | " + " | ".join(f"{k}: all-data / zero-shot / ratio" for k in runs)
             + f" | pooled all-data | pooled zero-shot | pooled ratio | 95 % interval | >= {TARGET} |",
             "|---|" + "---|" * len(runs) + "---|---|---|---|---|"]
    out = {}
    for v in variants:
        cells, alls, zss = [], [], []
        for r in runs.values():
            t = r["table7"][v]
            alls.append(t["all"]["success"])
            zss.append(t["zero_shot"]["success"])
            cells.append(f"{100 * t['all']['success_rate']:.1f} / {100 * t['zero_shot']['success_rate']:.1f} / {t['ratio']:.2f}")
        a, z = pool(*alls), pool(*zss)
        ratio = rate(z) / rate(a)
        lo, hi = ratio_interval(z, a)
        out[v] = {"per_seed": {k: r["table7"][v]["ratio"] for k, r in runs.items()}, "all": rate(a), "zero_shot": rate(z),
                  "ratio": ratio, "ratio_interval": [lo, hi], "grasps_per_side": sum(len(x) for x in a.values())}
        lines.append(f"| {v} | " + " | ".join(cells) + f" | {100 * rate(a):.1f} % | {100 * rate(z):.1f} % | {ratio:.2f} | "
                     f"{lo:.2f}-{hi:.2f} | {'yes' if ratio >= TARGET else 'no'} |")
    lines += ["", "Pooled: each side's verdicts of all seeds concatenated per (variant, object); the interval resamples the "
              "13 evaluation objects (shared by both sides) and the grasps within each (`benchmarks/_stats.py`); the "
              "spread between seeds is shown per seed, not bootstrapped (too few seeds)."]
    write_results(args.name, {"runs": list(runs), "target": TARGET, "table7": out}, "\n".join(lines))
    return 0


if __name__ == "__main__":
    run_script(main, __file__)
