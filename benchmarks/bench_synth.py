"""Synthesis benchmark: solves/s, solver success, filter pass rate, sim-verified grasps/s per core,
wall time and peak memory with 1 and 2 workers, and grasp diversity, on the shared YCB objects.

Run: python benchmarks/bench_synth.py [--grasps-per-object 8] [--hands ...]
 -> benchmarks/results/synth.{json,md}
"""

from __future__ import annotations

import argparse
import resource
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import peak_rss_mib, write_results  # noqa: E402

import numpy as np  # noqa: E402

from ohra.data.dataset import GraspDataset  # noqa: E402
from ohra.errors import OhraError  # noqa: E402
from ohra.hands import get_hand  # noqa: E402
from ohra.objects.model import resolve_objects  # noqa: E402
from ohra.paths import objects_root  # noqa: E402
from ohra.rotations import grasp_to_pose  # noqa: E402
from ohra.synth.pipeline import SynthSettings, synthesize  # noqa: E402

HANDS = ["leap_3333", "leap_3303", "leap_2203", "shadow_hand_right", "barrett_hand"]


def diversity(grasps: np.ndarray) -> dict[str, float]:
    """Spread of approach (palm normal) directions, 1 - mean resultant length (0 = one direction),
    and the mean per-joint standard deviation of the movable joints [rad]."""
    if len(grasps) < 2:
        return {"approach_spread": float("nan"), "joint_std_rad": float("nan")}
    T, q = grasp_to_pose(grasps.astype(float))
    normals = T[:, :3, 0]
    spread = 1.0 - float(np.linalg.norm(normals.mean(axis=0)))
    moving = q.std(axis=0) > 0
    return {"approach_spread": spread, "joint_std_rad": float(q[:, moving].std(axis=0).mean()) if moving.any() else 0.0}


def run(hand: str, objects, n: int, workers: int, object_set: str = "ycb") -> dict:
    params = get_hand(hand)
    with tempfile.TemporaryDirectory() as tmp:
        t = time.perf_counter()
        man = synthesize([(hand, params)], objects, tmp, SynthSettings(grasps_per_object=n, seed=0), workers=workers, progress=False)
        wall = time.perf_counter() - t
        grasps = GraspDataset(tmp).grasps()
    c = man["hands"][hand]["counts"]
    solve_s = sum(s["timing"]["solve_s"] for s in man["hands"][hand]["shards"].values())
    sim_s = sum(s["timing"]["sim_s"] for s in man["hands"][hand]["shards"].values())
    return {
        "hand": hand, "workers": workers, "object_set": object_set, "objects": len(objects), "solves": c["candidates"], "solved": c["solved"],
        "kept": c["grasps"], "wall_s": wall, "solve_time_s": solve_s, "sim_time_s": sim_s,
        "solves_per_s_per_core": c["candidates"] / wall / workers,
        "solver_success": c["solved"] / max(c["candidates"], 1), "filter_pass": c["grasps"] / max(c["solved"], 1),
        "verified_per_s_per_core": c["grasps"] / wall / workers, **diversity(grasps),
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--grasps-per-object", type=int, default=8)
    ap.add_argument("--hands", nargs="+", default=HANDS)
    ap.add_argument("--workers", nargs="+", type=int, default=[1, 2])
    ap.add_argument("--builtin-hands", nargs="*", default=["leap_3333", "leap_3303"],
                    help="hands also measured on the built-in primitives (objects outside ../shared/objects), 1 worker")
    args = ap.parse_args()
    objects = resolve_objects([str(objects_root() / "ycb")])
    builtin = resolve_objects("builtin")
    rows, skipped = [], {}
    for hand in args.hands:
        try:
            get_hand(hand)
        except OhraError as exc:
            skipped[hand] = str(exc)
            continue
        for w in args.workers:
            r = run(hand, objects, args.grasps_per_object, w)
            rows.append(r)
            print(r, flush=True)
    for hand in args.builtin_hands:
        r = run(hand, builtin, args.grasps_per_object, 1, "builtin")
        rows.append(r)
        print(r, flush=True)
    mem = max(peak_rss_mib(), resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0)
    lines = [
        f"Objects: the {len(objects)} YCB meshes in `../shared/objects` (ycb) and the {len(builtin)} built-in primitives (builtin); "
        f"{args.grasps_per_object} solver restarts per object; filter = six-direction PyBullet test (default protocol).",
        "",
        "| hand | objects | workers | solves | solver success | filter pass | verified grasps | wall [s] | solves/s/core | **verified grasps/s/core** | approach spread | joint std [rad] |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['hand']} | {r['object_set']} | {r['workers']} | {r['solves']} | {r['solver_success']:.0%} | {r['filter_pass']:.0%} | {r['kept']} | "
            f"{r['wall_s']:.0f} | {r['solves_per_s_per_core']:.2f} | **{r['verified_per_s_per_core']:.2f}** | "
            f"{r['approach_spread']:.2f} | {r['joint_std_rad']:.2f} |"
        )
    for h, why in skipped.items():
        lines.append(f"| {h} | – | – | skipped: {why} | | | | | | | | |")
    best = max((r["verified_per_s_per_core"] for r in rows if r["object_set"] == "ycb"), default=0.0)
    lines += [
        "",
        f"Best YCB rate {best:.2f} verified grasps/s/core: {16 * best:.1f}/s on 16 cores vs BODex's 30–50/s on one GPU.",
        f"Peak memory (largest process): {mem:.0f} MiB. Target: ≥ 3 verified grasps/s per core. Anchors (DESIGN.md): "
        "DexGraspNet ≪ 3/s, BODex 30–50/s, Lightning Grasp 300–1000/s on one datacentre GPU; CasADi prototype 2–4 solves/s/core.",
    ]
    write_results("synth", {"rows": rows, "skipped": skipped, "peak_rss_mib": mem, "grasps_per_object": args.grasps_per_object}, "\n".join(lines))


if __name__ == "__main__":
    main()
