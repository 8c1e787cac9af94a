"""Test-time finger refinement (``--refine``, ``--refine touch``): milliseconds per grasp.

The shipped grasp model samples ``--grasps`` grasps per (hand, object) (seeded); each batch is refined with
opening only and with ``touch`` (``ohra.learn.grasp.refine.refine_grasps``), timed on one thread, best of
``--repeat``. Objects: two procedural ones (a superquadric, whose body is a convex mesh, and a cylinder, whose
signed distance is closed-form) and three YCB objects under the objects root (unions of V-HACD pieces,
where each signed distance is a KD-tree query plus point-in-piece tests). The shares of grasps that the
refinement changes and the gradient steps it takes are reported beside the time.

    python benchmarks/bench_refine.py [--grasps 30] [--repeat 2]

To time another version of the refinement, run this script with that version's
``ohra/learn/grasp/refine.py`` checked out (its API is unchanged since stop 45).
"""

from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import run_script, script_parser, write_results  # noqa: E402

import numpy as np  # noqa: E402

HANDS = ("allegro_hand_left", "barrett_hand", "shadow_hand_right")
OBJECTS = ("procedural:superquadric:900", "procedural:cylinder:77", "ycb/MustardBottle", "ycb/PowerDrill", "ycb/Scissors")


def main(argv: list[str] | None = None) -> None:
    ap = script_parser(__doc__, __file__)
    ap.add_argument("--grasps", type=int, default=30, help="grasps per (hand, object)")
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)

    from ohra.canonical.kinematics import HandModel
    from ohra.hands import get_hand
    from ohra.learn.grasp.model import load_grasp_model, resolve_object
    from ohra.learn.grasp.refine import RefineSettings, refine_grasps
    from ohra.paths import objects_root

    model = load_grasp_model()
    rows, missing = [], []
    for spec in OBJECTS:
        if spec.startswith("ycb/"):
            path = objects_root() / spec
            if not path.is_dir():
                missing.append(spec)
                continue
            spec = str(path)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the YCB bodies' fidelity notes
            obj = resolve_object(spec)
            kind = "exact" if obj.body._exact is not None else f"{len(obj.body.pieces)} convex piece(s)"
        for hand in HANDS:
            hm = HandModel.from_params(get_hand(hand))
            g = model.sample(hand, obj, args.grasps, seed=args.seed)
            row = {"hand": hand, "object": obj.name, "body": kind, "grasps": len(g)}
            for label, settings in (("open", RefineSettings()), ("touch", RefineSettings(touch=True))):
                best, r = float("inf"), None
                for _ in range(args.repeat):
                    t = time.perf_counter()
                    r = refine_grasps(hm, obj, g, settings)
                    best = min(best, time.perf_counter() - t)
                row[f"{label}_ms_per_grasp"] = 1e3 * best / len(g)
                row[f"{label}_changed"] = float(np.mean(r.steps > 0))
                row[f"{label}_mean_steps"] = float(r.steps.mean())
            rows.append(row)
            print(f"{hand:18s} {obj.name:16s} open {row['open_ms_per_grasp']:6.1f} ms  touch {row['touch_ms_per_grasp']:6.1f} ms",
                  flush=True)
    lines = ["| hand | object | body | open: ms per grasp | touch: ms per grasp | changed (open / touch) | mean steps (open / touch) |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['hand']} | {r['object']} | {r['body']} | {r['open_ms_per_grasp']:.0f} | {r['touch_ms_per_grasp']:.0f} | "
                     f"{100 * r['open_changed']:.0f} / {100 * r['touch_changed']:.0f} % | {r['open_mean_steps']:.1f} / {r['touch_mean_steps']:.1f} |")
    if missing:
        lines.append(f"\nNot found under the objects root ({objects_root()}): {', '.join(missing)}.")
    lines.append(f"\n{args.grasps} sampled grasps per (hand, object), seed {args.seed}, refined as one batch on one thread, "
                 f"best of {args.repeat}.")
    write_results("bench_refine", {"grasps": args.grasps, "repeat": args.repeat, "seed": args.seed, "rows": rows,
                                   "missing": missing}, "\n".join(lines))


if __name__ == "__main__":
    run_script(main, __file__)
