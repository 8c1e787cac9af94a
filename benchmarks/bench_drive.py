"""Joint-drive speed of the six-direction test: the default PyBullet gain vs Isaac's drive rate.

For each hand: the solver's converged candidates (``SynthSettings`` defaults, no filter, penetration
pre-filter applied) on objects no recipe trains on (procedural seeds 1000+, two YCB objects), each
run under ``Protocol()`` (position gain 0.3: fingers close at 72 rad/s per rad of error) and
``Protocol.isaac_drive()`` (gain dt*k/d: 5 rad/s per rad, Isaac's k = 1000, d = 200). Reported per
protocol: nominal pass rate, the share that also passes ``--trials`` seeded perturbed re-tests (the
data engine's robustness check, here with more trials: palm 1 mm / 10 mrad, joints 10 mrad), and
simulation CPU seconds per robust grasp.

Run: python benchmarks/bench_drive.py [--hands ...] [--starts 8] [--trials 4] -> benchmarks/results/drive.{json,md}
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import run_script, script_parser, write_results  # noqa: E402

import numpy as np  # noqa: E402

from ohra.canonical.kinematics import HandModel  # noqa: E402
from ohra.hands import get_hand  # noqa: E402
from ohra.objects.model import resolve_objects  # noqa: E402
from ohra.paths import objects_root  # noqa: E402
from ohra.sim import GraspEvaluator, Protocol, SimHand  # noqa: E402
from ohra.synth.pipeline import SynthSettings, synthesize_shard  # noqa: E402
from ohra.synth.robust import RobustnessSettings, perturb  # noqa: E402

HANDS = ("leap_3333", "allegro_hand_left", "barrett_hand", "shadow_hand_right")
OBJECTS = ("procedural:superquadric:1000", "procedural:box:1000", "procedural:cylinder:1000", "procedural:capsule:1000",
           "procedural:ellipsoid:1000")
YCB = ("MustardBottle", "PottedMeatCan")


def candidates(name: str, obj, starts: int) -> np.ndarray:
    params = get_hand(name)
    s = synthesize_shard(name, params, obj, SynthSettings(grasps_per_object=starts, filter=False, seed=0))
    return s["raw"][s["solver_success"] & ~s["prefiltered"]].astype(np.float64)


def run(name: str, objects, starts: int, trials: int) -> dict:
    hm = HandModel.from_params(get_hand(name))
    rows = {k: {"n": 0, "nominal": 0, "robust": 0, "sim_cpu_s": 0.0} for k in ("reference", "isaac-drive")}
    for obj in objects:
        G = candidates(name, obj, starts)
        if not len(G):
            continue
        rng = np.random.default_rng(0)
        P = np.stack([perturb(g, RobustnessSettings(trials=trials), rng, hm.lower, hm.upper, hm.movable_joints) for g in G])
        for key, prot in (("reference", Protocol()), ("isaac-drive", Protocol.isaac_drive())):
            ev = GraspEvaluator(SimHand.from_params(get_hand(name), name), obj, prot)
            c0 = time.process_time()
            nom = ev.evaluate(G, mode="filter").success
            per = ev.evaluate(P.reshape(-1, 31), mode="filter").success.reshape(len(G), trials)
            r = rows[key]
            r["sim_cpu_s"] += time.process_time() - c0
            r["n"] += len(G)
            r["nominal"] += int(nom.sum())
            r["robust"] += int((nom & per.all(axis=1)).sum())
            ev.close()
    return rows


def main() -> None:
    ap = script_parser(__doc__, __file__)
    ap.add_argument("--hands", nargs="+", default=list(HANDS))
    ap.add_argument("--starts", type=int, default=8)
    ap.add_argument("--trials", type=int, default=4)
    a = ap.parse_args()
    objects = resolve_objects(list(OBJECTS) + [str(objects_root() / "ycb" / y) for y in YCB])
    res, lines = {}, []
    for h in a.hands:
        res[h] = run(h, objects, a.starts, a.trials)
        for key, r in res[h].items():
            n = max(r["n"], 1)
            lines.append(f"| {h} | {key} | {r['n']} | {r['nominal']} ({100 * r['nominal'] / n:.0f} %) | "
                         f"{r['robust']} ({100 * r['robust'] / n:.0f} %) | "
                         f"{r['sim_cpu_s'] / max(r['robust'], 1):.1f} |")
        print("\n".join(lines[-2:]), flush=True)
    table = ("| hand | drive | converged candidates | nominal pass | robust (all "
             f"{a.trials} trials) | sim CPU-s per robust grasp |\n|---|---|---|---|---|---|\n" + "\n".join(lines))
    write_results("drive", {"hands": res, "objects": [o.name for o in objects], "starts": a.starts, "trials": a.trials}, table)


if __name__ == "__main__":
    run_script(main, __file__)
