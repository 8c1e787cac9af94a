"""The ceiling on verified grasps per CPU-second that the physics test allows (issue 12's speed targets).

A kept (robust) grasp runs the six-direction test to its end three times: the nominal test and the
two robustness trials of the learning recipes (a passing grasp never exits early). Its solve costs
one IPOPT start. So even if every start converged and every candidate passed, one core keeps at most
``1 / (3 * sim + solve)`` robust grasps per CPU-second, and at most ``1 / (3 * sim)`` with a free
solver. This script measures both costs in CPU time (``time.process_time``: what an idle core would
take, also on a loaded machine) on committed data: ``sim`` over stored robust grasps of the first
shards that have them (they pass, so they run the full protocol), ``solve`` over IPOPT starts on the
same objects with the recipe's NLP settings.

Run: python benchmarks/bench_ceiling.py [--grasps 12] [--starts 2]  -> benchmarks/results/synth_ceiling.{json,md}
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import run_script, script_parser, write_results  # noqa: E402

import numpy as np  # noqa: E402

from ohra.canonical.kinematics import HandModel  # noqa: E402
from ohra.data.dataset import GraspDataset, read_manifest  # noqa: E402
from ohra.data.recipe import Recipe  # noqa: E402
from ohra.hands import get_hand  # noqa: E402
from ohra.learn.grasp.data import load_dataset_object  # noqa: E402
from ohra.sim import GraspEvaluator, SimHand  # noqa: E402
from ohra.synth.init import initial_poses  # noqa: E402
from ohra.synth.nlp import GraspNLP  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
# hand -> committed dataset holding its robust grasps (the speed targets' four hands)
HANDS = {"leap_3333": "datasets/leap_zeroshot_s0", "allegro_hand_left": "datasets/grasp_unified_s3",
         "barrett_hand": "datasets/grasp_unified_s3", "shadow_hand_right": "datasets/grasp_unified_s3"}
TARGETS = {"leap_3333": 1.5, "allegro_hand_left": 1.0, "barrett_hand": 1.0, "shadow_hand_right": 0.5}


def measure(hand: str, root: Path, n_grasps: int, n_starts: int) -> dict:
    man = read_manifest(root / "manifest.json")
    settings = Recipe.from_dict(man["recipe"]).synth_settings() if "recipe" in man else None
    if settings is None:
        raise SystemExit(f"{root}: no recipe in the manifest")
    ds = GraspDataset(root, hands=[hand])
    model = HandModel.from_params(get_hand(hand))
    sim_t = solve_t = 0.0
    n_sim = n_solve = n_ok = 0
    objects = []
    # shards in the dataset's (object-major) order, each object simulated in its own world, until
    # n_grasps stored robust grasps have run; n_starts IPOPT starts on each of those objects
    for (r, _, _, sh), (_, _, g) in zip(ds.entries, ds):
        if n_sim >= n_grasps:
            break
        if not len(g):
            continue
        obj = load_dataset_object(Path(r), sh["_name"], sh["object"], {})
        objects.append(obj.name)
        grasps = np.asarray(g[: n_grasps - n_sim], dtype=np.float64)
        with GraspEvaluator(SimHand.from_params(get_hand(hand), hand, couplings=settings.nlp.couplings), obj, settings.protocol) as ev:
            ev.evaluate(grasps[:1], mode="filter")  # the first call builds the world
            t = time.process_time()
            n_ok += sum(ev.evaluate(x[None], mode="filter").results[0].success for x in grasps)
            sim_t += time.process_time() - t
        n_sim += len(grasps)
        nlp = GraspNLP(model, obj, settings.nlp)
        starts = initial_poses(model, obj, n_starts, np.random.default_rng(0), settings.nlp.couplings)
        t = time.process_time()
        for st in starts:
            nlp.solve(st["R0"], st["t0"], st["q0"], st["q_pref"])
        solve_t += time.process_time() - t
        n_solve += len(starts)
    sim, solve = sim_t / n_sim, solve_t / n_solve
    trials = settings.robustness.trials if settings.robustness else 0
    runs = 1 + trials
    return {"objects": objects, "grasps": n_sim, "passed_again": int(n_ok), "starts": n_solve, "sim_cpu_s": sim,
            "solve_cpu_s": solve, "tests_per_kept": runs, "ceiling": 1.0 / (runs * sim + solve),
            "ceiling_free_solver": 1.0 / (runs * sim), "target": TARGETS.get(hand)}


def main() -> None:
    ap = script_parser(__doc__, __file__)
    ap.add_argument("--grasps", type=int, default=12, help="stored robust grasps simulated per hand")
    ap.add_argument("--starts", type=int, default=2, help="IPOPT starts solved per object")
    args = ap.parse_args()
    res = {h: measure(h, ROOT / d, args.grasps, args.starts) for h, d in HANDS.items()}
    lines = ["| hand | data (object) | full six-direction test [CPU-s] | IPOPT start [CPU-s] | tests per kept grasp | "
             "ceiling [robust / CPU-s] | with a free solver | target |", "|---|---|---|---|---|---|---|---|"]
    for h, r in res.items():
        lines.append(f"| {h} | `{Path(HANDS[h]).name}` ({len(r['objects'])} objects, {r['passed_again']}/{r['grasps']} passed again) | "
                     f"{r['sim_cpu_s']:.2f} | {r['solve_cpu_s']:.2f} | {r['tests_per_kept']} | **{r['ceiling']:.2f}** | "
                     f"{r['ceiling_free_solver']:.2f} | {r['target']} |")
    write_results("synth_ceiling", {"grasps": args.grasps, "starts": args.starts, "hands": res}, "\n".join(lines))


if __name__ == "__main__":
    run_script(main, __file__)
