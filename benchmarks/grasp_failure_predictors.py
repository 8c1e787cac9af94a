"""What tells a passing touched grasp from a failing one, before simulation? (issue 13)

After ``--refine touch`` the committed unified model's fingers lie on the object's surface (median finger
distance within 1 mm on every hand), yet 40-51 % of its grasps on unseen objects still fail the six-direction
test. If a cheap geometric score predicted the outcome, ranking K draws by it at test time would be a lever
(``--candidates`` ranks by finger clearance, which added nothing on top of touch: ``grasp_touch.py``). This
script regenerates the study's touched grasps (the committed model, the same pair seeds and one torch thread
as the study, so the same grasps: sampling is deterministic) and relates each grasp's committed verdict
(``runs/grasp_study/eval_unified_touched.json``, reused only under its key) to:

* ``palm``: the palm cylinder's clearance from the object [m] (points on its two faces and mid-plane);
* ``contacts``: capsules whose nearest core sample lies within 3 mm of the surface;
* ``q1``, ``q1_mu1``: the Ferrari-Canny epsilon (``ohra.synth.quality``) of those contacts, projected onto the
  surface, with friction 0.5 and 1.0 (0 without force closure);
* ``spread``: mean distance of those contacts from their centroid [m].

For scale, the same contact features are taken on the robust grasps the model was trained on (the first
``--data-folders`` folders, at most ``--data-per-pair`` grasps per (hand, training object)).

Read by the area under the ROC curve (0.5: no information), pooled per hand and averaged within objects (what a
ranking among one pair's draws can use). Exploratory: written after a first look at the same numbers (stop 53),
so it reads no rule; it reports.

Run: python benchmarks/grasp_failure_predictors.py --data datasets/grasp_unified_s{0..22}
  -> benchmarks/results/grasp_failure_predictors.{json,md}  (~10 min on one core)
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import natural_sorted, run_script, script_parser, write_results  # noqa: E402
from grasp_scale_up import require_data_of  # noqa: E402
from _study_cache import cached, eval_key, run_key  # noqa: E402
from grasp_study import PAPER, ROOT, data_protocol, eval_objects  # noqa: E402

from ohra.learn.grasp.refine import RefineSettings  # noqa: E402

TOUCH = RefineSettings(touch=True)
CONTACT_M = 0.003
SAMPLES = 9  # points along each capsule core
FEATURES = ("palm", "contacts", "q1", "q1_mu1", "spread")
PALM_BINS = ((-np.inf, 0.0), (0.0, 0.005), (0.005, 0.02), (0.02, np.inf))  # [m]


def auc(score: np.ndarray, ok: np.ndarray) -> float | None:
    """P(score of a passing grasp > score of a failing one), ties counted half; None without both outcomes."""
    pos, neg = score[ok == 1], score[ok == 0]
    if not len(pos) or not len(neg):
        return None
    greater = (pos[:, None] > neg[None, :]).sum() + 0.5 * (pos[:, None] == neg[None, :]).sum()
    return float(greater / (len(pos) * len(neg)))


def palm_points(radius: float, depth: float) -> np.ndarray:
    """Points on the canonical palm cylinder (axis +x, centre (0, 0, radius) in the palm frame) [m]."""
    th = np.linspace(0.0, 2.0 * np.pi, 24, endpoint=False)
    out = []
    for x in (-0.5 * depth, 0.0, 0.5 * depth):
        out.append([x, 0.0, radius])
        for a in (0.5, 1.0):
            out += [[x, a * radius * np.cos(t), radius + a * radius * np.sin(t)] for t in th]
    return np.array(out)


def features(hm, obj, grasps: np.ndarray) -> dict[str, np.ndarray]:
    """Per-grasp features (see the module docstring) of grasps (N, 31) of hand model ``hm`` on ``obj``."""
    from ohra.rotations import grasp_to_pose
    from ohra.synth.quality import contact_normals, ferrari_canny

    T, q = grasp_to_pose(grasps.astype(float))
    pp = palm_points(hm.palm["radius"], hm.palm["depth"])
    W = np.einsum("nij,pj->npi", T[:, :3, :3], pp) + T[:, None, :3, 3]
    palm = obj.signed_distance(W.reshape(-1, 3)).reshape(len(grasps), -1).min(axis=1)
    caps = hm.capsules(q)
    u = np.linspace(0.0, 1.0, SAMPLES)[:, None, None]
    pts = caps.p0[:, None] + u * (caps.p1 - caps.p0)[:, None]  # (N, S, K, 3) palm frame
    Wc = np.einsum("nij,nskj->nski", T[:, :3, :3], pts) + T[:, None, None, :3, 3]
    sd = obj.signed_distance(Wc.reshape(-1, 3)).reshape(Wc.shape[:3])
    d = sd - caps.radius
    out = {k: np.zeros(len(grasps)) for k in FEATURES}
    out["palm"] = palm
    cols = np.arange(d.shape[2])
    for i in range(len(grasps)):
        best = d[i].argmin(axis=0)  # each capsule's nearest core sample
        near = d[i][best, cols] < CONTACT_M
        out["contacts"][i] = near.sum()
        if near.sum() < 2:
            continue
        p, s = Wc[i][best, cols][near], sd[i][best, cols][near]
        n = contact_normals(p, obj)
        surf = p - s[:, None] * n
        out["q1"][i] = ferrari_canny(surf, obj, mu=0.5, normals=n)
        out["q1_mu1"][i] = ferrari_canny(surf, obj, mu=1.0, normals=n)
        out["spread"][i] = float(np.linalg.norm(surf - surf.mean(axis=0), axis=1).mean())
    return out


def training_data_features(folders: list[str], hands: list[str], per_pair: int) -> dict:
    """Contact features of the first ``per_pair`` robust grasps per (hand, object) of ``folders``."""
    import json

    from ohra.canonical.kinematics import HandModel
    from ohra.data.dataset import GraspDataset
    from ohra.learn.grasp.data import load_dataset_object
    from ohra.learn.grasp.evaluate import resolve_hand

    out, total = {}, 0
    for hand in hands:
        hm = HandModel.from_params(resolve_hand(hand))
        q1, contacts = [], []
        for folder in folders:
            objects = json.loads((Path(folder) / "manifest.json").read_text())["objects"]
            for _, name, g in GraspDataset(folder, hands=[hand]):
                g = np.asarray(g)[:per_pair]
                if not len(g):
                    continue
                f = features(hm, load_dataset_object(Path(folder), name, objects[name], {}), g)
                q1.append(f["q1"])
                contacts.append(f["contacts"])
        q1, contacts = np.concatenate(q1), np.concatenate(contacts)
        total += len(q1)
        out[hand] = {"grasps": len(q1), "fc_share": float((q1 > 0).mean()), "median_contacts": float(np.median(contacts))}
    return {"folders": len(folders), "per_pair": per_pair, "grasps": total, "per_hand": out}


def within(w: dict) -> str:
    return "-" if w["mean_difference"] is None else f"{100 * w['mean_difference']:+.1f} ({w['objects']} objects with >= 5 of each)"


def table(res: dict) -> str:
    lines = [f"The committed unified model's touched grasps (`--refine touch`) on {len(res['objects'])} unseen objects, "
             f"{res['n']} per (hand, object), the study's seeds; verdicts from `eval_unified_touched.json`. Area under the "
             "ROC curve of each feature for pass vs fail (0.5: no information): pooled over the hand's grasps / mean within "
             "objects (what ranking one pair's draws could use). Exploratory (no rule written before).", "",
             "| feature | " + " | ".join(res["hands"]) + " |", "|---|" + "---|" * len(res["hands"])]
    for f in FEATURES:
        cells = []
        for h in res["hands"]:
            a = res["per_hand"][h]["auc"][f]
            cells.append(f"{a['pooled']:.2f} / {a['within']:.2f}")
        lines.append(f"| {f} | " + " | ".join(cells) + " |")
    lines += ["", "Success by palm clearance (share of grasps, success):", "",
              "| palm clearance | " + " | ".join(res["hands"]) + " |", "|---|" + "---|" * len(res["hands"])]
    for b, (lo, hi) in enumerate(PALM_BINS):
        name = f"{'< 0' if lo == -np.inf else f'{1e3 * lo:.0f}'}{'' if lo == -np.inf else ' mm+' if hi == np.inf else f'-{1e3 * hi:.0f} mm'}"
        cells = []
        for h in res["hands"]:
            r = res["per_hand"][h]["palm_bins"][b]
            rate = "-" if r["success"] is None else f"{100 * r['success']:.0f} %"
            cells.append(f"{100 * r['share']:.1f} %, {rate}")
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    d = res["data"]
    lines += ["", f"Force closure of the sampled grasps and of the training data ({d['grasps']} robust grasps from {d['folders']} "
              f"folder(s), at most {d['per_pair']} per pair): contacts within {1e3 * CONTACT_M:.0f} mm, Q1 with friction 0.5.", "",
              "| hand | success | median finger distance [mm] | sampled: Q1 > 0 | success if Q1 > 0 / if not | same, within objects "
              "[points] | training data: Q1 > 0 | median contacts sampled / data |", "|---|---|---|---|---|---|---|---|"]
    for h in res["hands"]:
        r, t = res["per_hand"][h], d["per_hand"][h]
        lines.append(f"| {h} | {100 * r['success']:.1f} % | {r['median_finger_mm']:+.1f} | {100 * r['fc_share']:.0f} % | "
                     f"{100 * r['success_fc']:.0f} % / {100 * r['success_no_fc']:.0f} % | {within(r['fc_within_objects'])} | "
                     f"{100 * t['fc_share']:.0f} % | "
                     f"{r['median_contacts']:.0f} / {t['median_contacts']:.0f} |")
    return "\n".join(lines)


def main() -> None:
    ap = script_parser(__doc__, __file__)
    ap.add_argument("--data", nargs="+", required=True, help="the folders the committed unified model was trained on")
    ap.add_argument("--hands", nargs="+", default=list(PAPER))
    ap.add_argument("--objects-file", type=Path, default=ROOT / "recipes" / "grasp_eval_objects.yaml")
    ap.add_argument("-n", type=int, default=100, help="grasps per (hand, object), as evaluated")
    ap.add_argument("--runs", type=Path, default=ROOT / "runs" / "grasp_study", help="the committed study's runs")
    ap.add_argument("--data-folders", type=int, default=3, help="training folders whose grasps are scored for scale")
    ap.add_argument("--data-per-pair", type=int, default=20, help="at most this many training grasps per (hand, object)")
    args = ap.parse_args()
    import torch

    from ohra.canonical.kinematics import HandModel
    from ohra.learn.grasp.evaluate import pair_seed, resolve_hand, seed_label
    from ohra.learn.grasp.model import load_grasp_model
    from ohra.learn.grasp.refine import finger_distances

    torch.set_num_threads(1)  # the study's sampling threads: the same grasps as were evaluated
    args.data = natural_sorted(args.data)
    require_data_of(args.runs / "unified", args.data)
    objects = eval_objects(args.objects_file)
    protocol = data_protocol(args.data)
    model = load_grasp_model(args.runs / "unified")
    # the committed verdicts, reused only under their key (grasp_touch.py's evaluation; never simulated here)
    path = args.runs / "eval_unified_touched.json"
    ev = cached(path, eval_key(run_key(args.runs / "unified"), hands=args.hands, objects=[o.name for o in objects], n=args.n,
                               seed=0, original=False, protocol=protocol, refine=TOUCH)) if path.exists() else None
    if ev is None:
        raise SystemExit(f"{path}: missing or made with other settings than these; run grasp_touch.py first")
    res = {"hands": args.hands, "n": args.n, "objects": [o.name for o in objects], "per_hand": {}}
    for hand in args.hands:
        params = resolve_hand(hand)
        hm = HandModel.from_params(params)
        feats = {k: [] for k in FEATURES}
        oks, objs, fmed = [], [], []
        for obj in objects:
            g = model.sample(params, obj, args.n, seed=pair_seed(0, seed_label(hand, params), obj.mesh_hash), refine=TOUCH)
            f = features(hm, obj, g)
            for k in FEATURES:
                feats[k].append(f[k])
            oks.append(np.asarray(ev["success"][f"{hand}/{obj.name}"], dtype=int))
            objs += [obj.name] * len(g)
            fmed.append(finger_distances(hm, obj, g).ravel())
            print(hand, obj.name, flush=True)
        ok, objs = np.concatenate(oks), np.array(objs)
        F = {k: np.concatenate(v) for k, v in feats.items()}
        aucs = {}
        for k, v in F.items():
            within = [a for o in dict.fromkeys(objs) if (a := auc(v[objs == o], ok[objs == o])) is not None]
            aucs[k] = {"pooled": auc(v, ok), "within": float(np.mean(within))}
        bins = []
        for lo, hi in PALM_BINS:
            m = (F["palm"] >= lo) & (F["palm"] < hi)
            bins.append({"lo_m": lo if np.isfinite(lo) else None, "hi_m": hi if np.isfinite(hi) else None,
                         "share": float(m.mean()), "success": float(ok[m].mean()) if m.any() else None})
        fc = F["q1"] > 0
        # within objects: the pooled split mixes objects that are easy to hold in force closure with hard ones
        split = [ok[(objs == o) & fc].mean() - ok[(objs == o) & ~fc].mean() for o in dict.fromkeys(objs)
                 if ((objs == o) & fc).sum() >= 5 and ((objs == o) & ~fc).sum() >= 5]
        res["per_hand"][hand] = {"success": float(ok.mean()), "auc": aucs, "palm_bins": bins,
                                 "median_finger_mm": 1e3 * float(np.median(np.concatenate(fmed))),
                                 "fc_share": float(fc.mean()), "success_fc": float(ok[fc].mean()),
                                 "success_no_fc": float(ok[~fc].mean()), "median_contacts": float(np.median(F["contacts"])),
                                 "fc_within_objects": {"mean_difference": float(np.mean(split)) if split else None,
                                                       "objects": len(split)}}
    res["data"] = training_data_features(args.data[:args.data_folders], args.hands, args.data_per_pair)
    write_results("grasp_failure_predictors", res, table(res))


if __name__ == "__main__":
    run_script(main, __file__)
