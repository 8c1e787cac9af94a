"""What a dataset build delivered, per hand: candidates, converged, simulation passes, robust
grasps kept, CPU time, verified grasps per CPU-second, converged -> verified, and how its stored
grasps replay (exactly as stored, and under one fresh perturbation of the robustness trials' size
with another seed), all under the protocol the dataset was filtered with (its manifest).

Run: python benchmarks/bench_dataset.py --data out/grasp_unified [--name dataset_grasp_unified] [--no-replay] [--replay-max N]
  -> benchmarks/results/<name>.{json,md}
"""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import run_script, script_parser, write_results  # noqa: E402

import numpy as np  # noqa: E402

from ohra.canonical.kinematics import HandModel  # noqa: E402
from ohra.canonical.params import load_params  # noqa: E402
from ohra.data.dataset import GraspDataset, read_manifest  # noqa: E402
from ohra.learn.grasp.data import load_dataset_object  # noqa: E402
from ohra.sim import GraspEvaluator, Protocol, SimHand  # noqa: E402
from ohra.synth.robust import RobustnessSettings, perturb  # noqa: E402


def main() -> None:
    ap = script_parser(__doc__, __file__)
    ap.add_argument("--data", required=True, type=Path)
    ap.add_argument("--name", default=None)
    ap.add_argument("--no-replay", action="store_true")
    ap.add_argument("--replay-max", type=int, default=None,
                    help="replay at most N stored grasps per hand (a seeded random subset; default: all)")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    man = read_manifest(args.data / "manifest.json")
    if man is None:
        from ohra.errors import DatasetError

        raise DatasetError(f"--data {args.data} holds no dataset (no manifest.json)")
    st = man["settings"]
    protocol = Protocol(**st["protocol"])
    rob = RobustnessSettings(**{**st["robustness"], "trials": 1})
    rows, lines = {}, []
    for hand, e in man["hands"].items():
        sh = e["shards"]
        c = {k: sum(s.get(f"n_{k}", 0) for s in sh.values()) for k in ("candidates", "solved", "sim_passed", "grasps")}
        cpu = sum(s["timing"]["cpu_s"] for s in sh.values())
        r = {"pairs": len(sh), **c, "cpu_s": cpu, "verified_per_cpu_s": c["grasps"] / cpu if cpu else 0.0,
             "converged_to_verified": c["grasps"] / max(c["solved"], 1)}
        if not args.no_replay and c["grasps"]:
            params = load_params(e["params"])
            hm = HandModel.from_params(params)
            exact = fresh = replayed = 0
            counts = {k: s.get("n_grasps", 0) for k, s in sh.items()}
            keep = np.arange(sum(counts.values()))
            if args.replay_max is not None and len(keep) > args.replay_max:
                keep = np.sort(np.random.default_rng(0).choice(len(keep), args.replay_max, replace=False))
            start = 0
            for key, info in sh.items():
                sel = keep[(keep >= start) & (keep < start + counts[key])] - start
                start += counts[key]
                if not len(sel):
                    continue
                g = GraspDataset(args.data, hands=[hand], objects=[key]).grasps().astype(float)[sel]
                replayed += len(g)
                obj = load_dataset_object(args.data, key, info["object"], {})
                with GraspEvaluator(SimHand.from_params(params, hand), obj, protocol) as ev:
                    exact += int(ev.evaluate(g, mode="filter").success.sum())
                    rng = np.random.default_rng(12345)
                    moved = np.vstack([perturb(x, rob, rng, hm.lower, hm.upper, hm.movable_joints) for x in g])
                    fresh += int(ev.evaluate(moved, mode="filter").success.sum())
            r.update(replay_exact=exact / replayed, replay_fresh_perturbation=fresh / replayed, replayed=replayed)
        rows[hand] = r
        rep = (f"{100 * r['replay_exact']:.0f} % | {100 * r['replay_fresh_perturbation']:.0f} %" if "replay_exact" in r else "- | -")
        lines.append(f"| {hand} | {r['pairs']} | {c['candidates']} | {c['solved']} | {c['sim_passed']} | {c['grasps']} | "
                     f"{100 * r['converged_to_verified']:.0f} % | {cpu:.0f} | **{r['verified_per_cpu_s']:.2f}** | {rep} |")
        print(lines[-1], flush=True)
    tot_c = sum(r["grasps"] for r in rows.values())
    tot_cpu = sum(r["cpu_s"] for r in rows.values())
    if len(rows) > 1:  # pooled over hands (the replay rates weighted by the grasps replayed)
        tot = {k: sum(r[k] for r in rows.values()) for k in ("pairs", "candidates", "solved", "sim_passed")}
        rep = [r for r in rows.values() if "replay_exact" in r]
        n_rep = sum(r["replayed"] for r in rep)
        pooled = (f"{100 * sum(r['replay_exact'] * r['replayed'] for r in rep) / n_rep:.0f} % | "
                  f"{100 * sum(r['replay_fresh_perturbation'] * r['replayed'] for r in rep) / n_rep:.0f} % (of {n_rep})"
                  if n_rep else "- | -")
        lines.append(f"| **all {len(rows)} hands** | {tot['pairs']} | {tot['candidates']} | {tot['solved']} | {tot['sim_passed']} | "
                     f"{tot_c} | {100 * tot_c / max(tot['solved'], 1):.0f} % | {tot_cpu:.0f} | **{tot_c / max(tot_cpu, 1e-9):.2f}** | {pooled} |")
    table = (f"Dataset `{args.data.name}` (recipe {man.get('recipe', {}).get('name', '-')}, protocol position gain "
             f"{protocol.position_gain:.4f}, robustness trials {st['robustness']['trials']}): {tot_c} grasps, "
             f"{tot_cpu / 3600:.2f} core-hours, {tot_c / max(tot_cpu, 1e-9):.2f} verified grasps per CPU-s.\n\n"
             "| hand | pairs | candidates | converged | sim pass | kept (robust) | converged→verified | CPU-s | verified per CPU-s | "
             "replay exact | replay fresh perturbation |\n|---|---|---|---|---|---|---|---|---|---|---|\n" + "\n".join(lines))
    write_results(args.name or f"dataset_{args.data.name}", {"data": str(args.data), "hands": rows}, table)


if __name__ == "__main__":
    run_script(main, __file__)
