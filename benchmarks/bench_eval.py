"""Six-direction evaluator throughput: grasps/s on one core and with 2 workers, pass rates, early exit.

Grasps: ``ohra.sim.heuristic.heuristic_grasps`` (seeded): the palm faces the object from a random
direction and each finger takes, among 256 random configurations, the one whose distal segment
just touches the object. They are plausible, not optimised: some hold, many do not, which is the
mix a filter sees. Every (hand, object) pair is evaluated three times on the same grasps: 1 worker
with early exit, 1 worker without (outcomes must be identical: early exit never changes one), and
2 workers with early exit (outcomes must be identical again).

    python benchmarks/bench_eval.py [--grasps 24] [--hands leap_3333 shadow_hand_right]
"""

from __future__ import annotations

import resource
import sys
import time
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import peak_rss_mib, run_script, script_parser, write_results  # noqa: E402

import numpy as np  # noqa: E402

from ohra import HandModel, get_hand  # noqa: E402
from ohra.objects.model import ObjectModel  # noqa: E402
from ohra.paths import objects_root  # noqa: E402
from ohra.sim import GraspEvaluator, Protocol  # noqa: E402
from ohra.sim.heuristic import heuristic_grasps  # noqa: E402

OBJECTS = ("TomatoSoupCan", "MustardBottle", "PottedMeatCan")


def main(argv: list[str] | None = None) -> int:
    ap = script_parser(__doc__, __file__)
    ap.add_argument("--grasps", type=int, default=24, help="grasps per (hand, object)")
    ap.add_argument("--hands", nargs="+", default=["leap_3333", "shadow_hand_right"],
                    help="hands, space- (as in the other scripts) or comma-separated (default leap_3333 shadow_hand_right)")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    rows, notes = [], []
    objs = []
    for name in OBJECTS:
        path = objects_root() / "ycb" / name / "model.urdf"
        if path.is_file():
            objs.append(ObjectModel.load(path))
        else:
            notes.append(f"{name}: not found under {objects_root()}")
    hands = {h: get_hand(h) for h in ",".join(args.hands).split(",") if h}  # a misspelt hand: one line, before any result is written
    for hand_name, params in hands.items():
        hm = HandModel.from_params(params)
        for obj in objs:
            G = heuristic_grasps(hm, obj, args.grasps, seed=args.seed)
            runs = {}
            for label, protocol, workers in (("early", Protocol(), 1), ("full", replace(Protocol(), early_exit=False), 1),
                                             ("early_2w", Protocol(), 2)):
                ev = GraspEvaluator(params, obj, protocol)
                _ = ev.world  # world construction is a one-off per (hand, object): timed separately
                t = time.perf_counter()
                rep = ev.evaluate(G, workers=workers)
                runs[label] = (time.perf_counter() - t, rep)
                ev.close()
            same_early = bool(np.array_equal(runs["early"][1].success, runs["full"][1].success))
            same_workers = all(a.success == b.success and np.array_equal(a.post_grasp, b.post_grasp)
                               for a, b in zip(runs["early"][1].results, runs["early_2w"][1].results))
            n = len(G)
            rep = runs["early"][1]
            rows.append({
                "hand": hand_name, "object": obj.name, "grasps": n, "pass_rate": rep.success_rate,
                "pass_rate_no_early_exit": runs["full"][1].success_rate,
                "early_exit_identical": same_early, "workers_identical": same_workers,
                "early_exits": int(sum(r.early_exit for r in rep.results)),
                "grasps_per_s_1core": n / runs["early"][0], "grasps_per_s_1core_no_early_exit": n / runs["full"][0],
                "grasps_per_s_2workers": n / runs["early_2w"][0],
                "mean_steps": float(np.mean([r.steps for r in rep.results])),
                "mean_penetration_mm": 1000 * float(rep.penetration.mean()),
            })
            print(rows[-1], flush=True)
    peak_self = peak_rss_mib()
    peak_children = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0
    lines = [
        "| hand | object | grasps | pass rate | pass rate, no early exit | early exit changes outcomes | grasps/s 1 core | grasps/s 1 core, no early exit | grasps/s 2 workers |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(f"| {r['hand']} | {r['object']} | {r['grasps']} | {100 * r['pass_rate']:.0f} % | "
                     f"{100 * r['pass_rate_no_early_exit']:.0f} % | {'no' if r['early_exit_identical'] else 'YES'} | "
                     f"{r['grasps_per_s_1core']:.1f} | {r['grasps_per_s_1core_no_early_exit']:.1f} | {r['grasps_per_s_2workers']:.1f} |")
    if rows:
        tot = sum(r["grasps"] for r in rows)
        t1 = sum(r["grasps"] / r["grasps_per_s_1core"] for r in rows)
        t2 = sum(r["grasps"] / r["grasps_per_s_2workers"] for r in rows)
        lines.append(f"| **all** | | {tot} | {100 * np.mean([r['pass_rate'] for r in rows]):.0f} % | | "
                     f"{'no' if all(r['early_exit_identical'] for r in rows) else 'YES'} | **{tot / t1:.1f}** | | **{tot / t2:.1f}** |")
    lines.append("")
    prot = Protocol()
    lines.append(f"Default protocol (dt 1/{1 / prot.dt:.0f} s, {prot.substeps} substep(s), {prot.solver_iterations} solver iterations, "
                 f"{prot.squeeze_time + 6 * prot.direction_time:.0f} s). Peak memory {peak_self:.0f} MiB (main), "
                 f"{peak_children:.0f} MiB (largest worker). Grasps: seeded heuristic closures (bench_eval.py docstring).")
    lines += [f"Note: {n}" for n in notes]
    write_results("eval", {"rows": rows, "grasps_per_pair": args.grasps, "seed": args.seed, "peak_rss_mib": peak_self,
                           "peak_rss_worker_mib": peak_children, "notes": notes}, "\n".join(lines))
    return 0


if __name__ == "__main__":
    run_script(main, __file__)
