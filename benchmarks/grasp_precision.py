"""How far the unified grasp model's palm and joints lie from its own training grasps, for their rotations (issue 13).

Descriptive (no verdict): per (hand, training object) of ``recipes/grasp_seen_objects.yaml``, up to ``-n``
stored robust grasps (seeded choice); the committed model samples one grasp for each stored grasp's
wrist rotation, and eight more draws give its spread for that rotation. Reported per hand: the median
distance between the model's palm position and the stored one [mm], the median RMS difference of the
movable joints [rad], the median spread of the eight draws' palm positions about their mean [mm], and
the median deepest finger penetration of the model's grasps and of the stored ones [mm]
(``finger_clearance``). No simulation; a minute on one core.

Run: python benchmarks/grasp_precision.py --data datasets/grasp_unified_s{0..22} [-n 100]
  -> benchmarks/results/grasp_precision.{json,md}
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import natural_sorted, run_script, script_parser, write_results  # noqa: E402
from grasp_study import PAPER, ROOT, eval_objects  # noqa: E402

import numpy as np  # noqa: E402

from ohra.data.dataset import GraspDataset  # noqa: E402
from ohra.hands import get_hand  # noqa: E402
from ohra.learn.grasp.evaluate import pair_seed  # noqa: E402
from ohra.learn.grasp.model import load_grasp_model  # noqa: E402
from ohra.learn.grasp.refine import finger_clearance  # noqa: E402
from ohra.rotations import grasp_to_pose  # noqa: E402


def main() -> None:
    ap = script_parser(__doc__, __file__)
    ap.add_argument("--data", nargs="+", required=True, help="the data the model was trained on")
    ap.add_argument("--hands", nargs="+", default=list(PAPER))
    ap.add_argument("--seen-file", type=Path, default=ROOT / "recipes" / "grasp_seen_objects.yaml")
    ap.add_argument("--model", type=Path, default=ROOT / "runs" / "grasp_study" / "unified")
    ap.add_argument("-n", type=int, default=100)
    ap.add_argument("--draws", type=int, default=8)
    ap.add_argument("--name", default="grasp_precision")
    args = ap.parse_args()
    args.data = natural_sorted(args.data)
    model = load_grasp_model(args.model)
    objs = eval_objects(args.seen_file)
    res = {"hands": args.hands, "n": args.n, "draws": args.draws, "per_hand": {}}
    for h in args.hands:
        p = get_hand(h)
        movable = np.asarray(p.movable_joints)
        pos, jrms, spread, depth_model, depth_data = [], [], [], [], []
        for o in objs:
            stored = GraspDataset(args.data, hands=[h], objects=[o.name]).grasps().astype(float)
            if not len(stored):
                continue
            s = pair_seed(0, h, o.mesh_hash)
            idx = np.random.default_rng(s).choice(len(stored), min(args.n, len(stored)), replace=False)
            ref = stored[idx]
            R = grasp_to_pose(ref)[0][:, :3, :3]
            g = model.sample(h, o, len(ref), rotations=R, seed=s)
            pos.append(np.linalg.norm(g[:, :3] - ref[:, :3], axis=1))
            jrms.append(np.sqrt(np.mean((g[:, 9:][:, movable] - ref[:, 9:][:, movable]) ** 2, axis=1)))
            many = model.sample(h, o, len(ref) * args.draws, rotations=np.repeat(R, args.draws, axis=0), seed=s + 1)
            t = many[:, :3].reshape(len(ref), args.draws, 3)
            spread.append(np.linalg.norm(t - t.mean(axis=1, keepdims=True), axis=-1).mean(axis=1))
            depth_model.append(-finger_clearance(p, o, g))
            depth_data.append(-finger_clearance(p, o, ref))
        cat = lambda xs: np.concatenate(xs)  # noqa: E731
        res["per_hand"][h] = {"grasps": int(len(cat(pos))), "palm_error_mm": 1e3 * float(np.median(cat(pos))),
                              "joint_rms_rad": float(np.median(cat(jrms))), "draw_spread_mm": 1e3 * float(np.median(cat(spread))),
                              "depth_model_mm": 1e3 * float(np.median(cat(depth_model))),
                              "depth_data_mm": 1e3 * float(np.median(cat(depth_data)))}
    lines = [f"The committed unified model vs its own training grasps, for their wrist rotations: up to {args.n} stored robust "
             f"grasps per (hand, training object) of `recipes/grasp_seen_objects.yaml`; medians. Descriptive, no simulation.", "",
             "| hand | grasps | palm position error [mm] | joint RMS error [rad] | spread of 8 draws for one rotation [mm] | "
             "deepest finger penetration, model / data [mm] |", "|---|---|---|---|---|---|"]
    for h in args.hands:
        r = res["per_hand"][h]
        lines.append(f"| {h} | {r['grasps']} | {r['palm_error_mm']:.1f} | {r['joint_rms_rad']:.3f} | {r['draw_spread_mm']:.1f} | "
                     f"{r['depth_model_mm']:.1f} / {r['depth_data_mm']:.1f} |")
    write_results(args.name, res, "\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    run_script(main, __file__)
