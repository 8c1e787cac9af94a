"""The grasp-model study of issue 13 (paper Tables 4-6): unified vs hand-specific models, success on
unseen objects, canonical -> original replay. Resumable: every training run and every evaluation
is cached under ``--runs`` and reused when it was made with the same settings (``_study_cache.py``:
a run of other data, hands or steps stops the study with one line; an evaluation of other objects,
grasps per pair or protocol is redone); an interrupted study loses at most one unfinished step (a training run from
its last checkpoint, an evaluation from its last finished (hand, object) pair, kept under out/eval_pairs/).

Models, all with the same architecture, steps, batch size and seed (the same budget):
``unified`` (every hand of the data, VAE condition), ``specific-<hand>`` (one hand's grasps
only) and ``unified-params`` (every hand, the raw-parameter condition of the zero-shot study; the
VAE vs params table; ``--no-compare-condition`` skips it). Evaluation: ``-n`` grasps per (hand, object) with random wrist rotations on the objects of
``recipes/grasp_eval_objects.yaml`` (never trained on; the model refuses seen objects), six-direction
test with the protocol the data was filtered with (read from the first dataset's manifest);
the unified model's grasps are replayed on the original URDFs too, and evaluated once more on the
canonical geometry carrying the original URDFs' finger masses (``inertials="original"``): how much of
the canonical/original difference is finger mass (README, Table 4 analogue). Test-time refinement
(opening sunk fingers; ``touch``: also closing hovering ones) is evaluated on the same samples.

Table 6 with touch (stop 45, written before its run): the hand-specific models' samples refined with
``touch`` too, unified - specific per hand as in Table 6 (independent samples); a difference below minus
two standard errors reads as "specific ahead on that hand", above two as "unified ahead", else "no
difference detectable"; the issue's target (unified >= specific on every hand) holds when no hand reads
"specific ahead".

Run: python benchmarks/grasp_study.py --data out/grasp_unified [out/grasp_unified_s1 ...] [--steps 12000] [-n 100]
       [--runs runs/grasp_study] [--hands ...] [--objects-file recipes/grasp_eval_objects.yaml]
  -> benchmarks/results/grasp_study.{json,md}, grasp_study_sheet.png (contact sheet), grasp_study_scene.html (meshcat)
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, natural_sorted, run_script, script_parser, write_results  # noqa: E402
from _study_cache import cached, carried_over, claim_run, eval_key, run_key, store, train_key, when_free  # noqa: E402

import numpy as np  # noqa: E402
import yaml  # noqa: E402

from ohra.data.dataset import read_manifest  # noqa: E402
from ohra.data.recipe import Recipe  # noqa: E402
from ohra.learn.grasp import GraspModelConfig, GraspTrainConfig  # noqa: E402
from ohra.learn.grasp.evaluate import evaluate_model  # noqa: E402
from ohra.learn.grasp.model import load_grasp_model  # noqa: E402
from ohra.learn.grasp.refine import RefineSettings  # noqa: E402
from ohra.learn.grasp.train import train_grasp  # noqa: E402
from ohra.hands import get_hand  # noqa: E402
from ohra.sim import Protocol, SimHand  # noqa: E402
from ohra.sim.bullet import urdf_joint_damping  # noqa: E402
from ohra.sim.hands import ORIGINAL_SQUEEZE  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
PAPER = {"allegro_hand_left": 84.2, "barrett_hand": 88.1, "shadow_hand_right": 62.9}  # OHRA Table 5, Isaac Gym
PAPER_REPLAY = {"allegro_hand_left": -12.6, "barrett_hand": 0.6, "shadow_hand_right": -0.3}  # Table 4, points
# Baselines as reported by D(R,O) Grasp (Wei et al., arXiv 2410.01702, Table I; success %, Isaac Gym, its
# own object split), the numbers OHRA's Table 5 compares against. Check: D(R,O)'s mean over the three
# hands is 87.53 %, as its abstract states.
REPORTED = {
    "DFC": {"allegro_hand_left": 76.2, "barrett_hand": 86.3, "shadow_hand_right": 58.8},
    "GenDexGrasp": {"allegro_hand_left": 51.0, "barrett_hand": 67.0, "shadow_hand_right": 54.2},
    "D(R,O)": {"allegro_hand_left": 92.3, "barrett_hand": 87.3, "shadow_hand_right": 83.0},
    "OHRA": PAPER,
}


def data_protocol(data: list[str]) -> Protocol:
    """The six-direction protocol the first dataset was filtered with (its manifest's settings)."""
    man = read_manifest(Path(data[0]) / "manifest.json") or {}
    if "settings" not in man:  # a dataset written by other tools: the default protocol
        return Protocol()
    return Protocol(**man["settings"]["protocol"])


def eval_objects(path: Path) -> list:
    d = yaml.safe_load(path.read_text())
    return Recipe.from_dict({"hands": ["leap_3333"], "objects": d["objects"]}, path).resolve_objects()


def trained(name: str, data: list[str], hands: list[str], args, condition: str = "vae") -> object:
    """The model ``name`` trained on ``hands`` (resumed or reused when its run exists)."""
    run = Path(args.runs) / name

    def get():
        if claim_run(run, train_key(data, hands, args.steps, args.seed, condition)):
            return load_grasp_model(run)
        tcfg = GraspTrainConfig(steps=args.steps, seed=args.seed, threads=args.threads, hands=tuple(hands))
        return train_grasp(data, GraspModelConfig(condition=condition), tcfg, run,
                           resume=(run / "checkpoints" / "last.pt").exists(), progress=not args.quiet).model

    return when_free(get)


def evaluated(model, key: str, hands: list[str], objects: list, original: bool, protocol: Protocol, args,
              inertials: str = "capsule", refine: bool | RefineSettings = False, collisions: str = "own", seed: int = 0,
              tag: str = "", candidates: int = 1) -> dict:
    """One model's evaluation, cached in ``eval_<key><tag><suffix>.json`` under its settings' key (``tag``:
    tells apart evaluations of the same model on other hand subsets; ``refine``: True for the default
    refinement, or its settings)."""
    settings = refine if isinstance(refine, RefineSettings) else RefineSettings() if refine else None
    touch = settings is not None and settings.touch
    suffix = tag + (("_original" if original else "") + ("_hybrid" if collisions != "own" else "")
              + ("_origmass" if inertials != "capsule" else "") + ("_touched" if touch else "_refined" if settings else "")
              + (f"_seed{seed}" if seed else "") + (f"_k{candidates}" if candidates > 1 else ""))
    path = Path(args.runs) / f"eval_{key}{suffix}.json"
    extra = {"inertials": inertials} if inertials != "capsule" else {}  # the capsule evaluations keep their keys
    if settings is not None:
        extra["refine"] = settings
    if collisions != "own":  # the other evaluations keep their keys
        extra["collisions"] = collisions
    if candidates > 1:  # likewise
        extra["candidates"] = int(candidates)
    if original:  # the squeeze directions of an original hand (SimHand.squeeze_reference): older replays are not reused
        extra["squeeze"] = ORIGINAL_SQUEEZE
    ekey = eval_key(run_key(Path(args.runs) / key), hands=hands, objects=[o.name for o in objects], n=args.n, seed=seed,
                    original=original, protocol=protocol, **extra)
    if (hit := cached(path, ekey)) is not None:
        return hit
    # an original-URDF evaluation made before Protocol.urdf_joint_damping: hands whose URDFs carry no
    # damping ran exactly as they would now; only the others are evaluated again
    carry = (carried_over(path, ekey, lambda h: not urdf_joint_damping(SimHand.registered_original(h).urdf))
             if original and collisions == "own" else None)
    kept = carry["hands"] if carry else []
    todo = [h for h in hands if h not in kept]
    t0 = time.perf_counter()
    out = {"per_hand": {}, "pairs": [], "success": {}}
    if todo:
        # each finished (hand, object) pair is kept under out/ (keyed by the weights and every setting), so an
        # interrupted evaluation -- 25-45 min for an original-URDF replay -- resumes at its next pair
        rep = evaluate_model(model, todo, objects, n=args.n, seed=seed, original=original, protocol=protocol,
                             workers=args.workers, inertials=inertials, refine=settings or False, collisions=collisions,
                             candidates=candidates, resume_dir=ROOT / "out" / "eval_pairs" / Path(args.runs).name)
        out = {"per_hand": rep.per_hand(), "pairs": [{"hand": p.hand, "object": p.object, "successes": int(p.success.sum()),
                                                      "n": int(len(p.success))} for p in rep.pairs],
               "success": {p.hand + "/" + p.object: p.success.astype(int).tolist() for p in rep.pairs}}
    if carry:
        old = carry["result"]
        out = {"per_hand": {h: (old if h in kept else out)["per_hand"][h] for h in hands},
               "pairs": [p for h in hands for p in (old if h in kept else out)["pairs"] if p["hand"] == h],
               "success": {k: v for h in hands for k, v in (old if h in kept else out)["success"].items()
                           if k.split("/", 1)[0] == h},
               "carried_over": {"hands": kept, "seconds": old.get("seconds"),
                                "why": "evaluated before Protocol.urdf_joint_damping; these hands' URDFs carry no damping"}}
    out["seconds"] = time.perf_counter() - t0
    return store(path, ekey, out)


def paired_change(a: dict, b: dict, hand: str | list[str]) -> tuple[float, float]:
    """b - a success [points] over the same grasps of one hand (or of several, pooled), and its standard error."""
    prefixes = tuple(h + "/" for h in ([hand] if isinstance(hand, str) else hand))
    d = np.concatenate([np.asarray(b["success"][k]) - np.asarray(a["success"][k]) for k in a["success"] if k.startswith(prefixes)])
    return 100 * d.mean(), 100 * d.std(ddof=1) / np.sqrt(len(d)) if len(d) > 1 else float("nan")


def tables(res: dict) -> str:
    u, uo, ur = res["unified"], res["unified_original"], res.get("unified_refined")
    ut = res.get("unified_touched")
    lines = ["Table 5 analogue: success on unseen objects (unified model)", "",
             "| hand | training grasps | success (canonical) | ms / grasp | "
             + ("success, fingers refined | refinement ms / grasp | " if ur else "")
             + ("success, fingers onto the surface (touch) | refinement ms / grasp | " if ut else "")
             + " | ".join(f"{m} (reported)" for m in REPORTED) + " |",
             "|---|---|---|---|" + ("---|---|" if ur else "") + ("---|---|" if ut else "") + "---|" * len(REPORTED)]
    for h in res["hands"]:
        r = u["per_hand"][h]
        refined = ""
        for ev in (ur, ut):
            if ev:
                rr = ev["per_hand"][h]
                d, se = paired_change(u, ev, h)  # the same sampled grasps before and after refinement
                refined += f"{100 * rr['success_rate']:.1f} % ({d:+.1f} ± {se:.1f}) | {rr.get('refine_ms_per_grasp', float('nan')):.0f} | "
        lines.append(f"| {h} | {res['train_counts'].get(h, 0)} | {100 * r['success_rate']:.1f} % of {r['n']} | "
                     f"{r['sample_ms_per_grasp']:.2f} | " + refined
                     + " | ".join(f"{v[h]} %" if h in v else "-" for v in REPORTED.values()) + " |")
    if ur:
        lines += ["", "Fingers refined: the same sampled grasps with the fingers opened just enough to clear the object "
                  "(`refine=True`, `ohra.learn.grasp.refine`: joints only, 1 mm of penetration left alone); the change "
                  "is paired over the same grasps, in points."
                  + (" Touch: sunk fingers opened likewise and hovering ones closed until they touch "
                     "(`RefineSettings(touch=True)`, `--refine touch`; in the data every finger touches)." if ut else "")]
    lines += ["", "Reported columns: other protocol (Isaac Gym), other objects and hardware; DFC, GenDexGrasp and "
              "D(R,O) as reported by D(R,O) Grasp (arXiv 2410.01702, Table I), OHRA by its paper's Table 5.",
              "", "Table 6 analogue: unified vs hand-specific (same data, steps, batch, seed)", "",
              "| hand | unified | specific | unified - specific ± SE [points] |", "|---|---|---|---|"]
    for h in res["hands"]:
        ru, rs = u["per_hand"][h], res["specific"][h]["per_hand"][h]
        a, b = ru["success_rate"], rs["success_rate"]
        se = np.sqrt(a * (1 - a) / ru["n"] + b * (1 - b) / rs["n"])  # two independent samples of grasps
        lines.append(f"| {h} | {100 * a:.1f} % | {100 * b:.1f} % | {100 * (a - b):+.1f} ± {100 * se:.1f} |")
    if ut and res.get("specific_touched"):
        lines += ["", "Table 6 with touch: both models' samples refined with `touch` (rule in the script's docstring, "
                  "written before the run)", "", "| hand | unified, touch | specific, touch | unified - specific ± SE [points] | reading |",
                  "|---|---|---|---|---|"]
        for h in res["hands"]:
            ru, rs = ut["per_hand"][h], res["specific_touched"][h]["per_hand"][h]
            a, b = ru["success_rate"], rs["success_rate"]
            se = np.sqrt(a * (1 - a) / ru["n"] + b * (1 - b) / rs["n"])
            d = a - b
            reading = "specific ahead" if d < -2 * se else "unified ahead" if d > 2 * se else "no difference detectable"
            lines.append(f"| {h} | {100 * a:.1f} % | {100 * b:.1f} % | {100 * d:+.1f} ± {100 * se:.1f} | {reading} |")
    if "unified_params" in res:
        up = res["unified_params"]
        lines += ["", "Hand condition: the VAE's mean latent vs the raw normalised parameters (the zero-shot study's "
                  "condition; the VAE reads base-form hands only, so LEAP variants can only use `params`): unified "
                  "models with the same data, steps, batch and seed", "",
                  "| hand | VAE latent | raw parameters | params - VAE ± SE [points] |", "|---|---|---|---|"]
        for h in res["hands"]:
            a, b = u["per_hand"][h]["success_rate"], up["per_hand"][h]["success_rate"]
            se = np.sqrt(a * (1 - a) / u["per_hand"][h]["n"] + b * (1 - b) / up["per_hand"][h]["n"])
            lines.append(f"| {h} | {100 * a:.1f} % | {100 * b:.1f} % | {100 * (b - a):+.1f} ± {100 * se:.1f} |")
    um, rro, rto = res.get("unified_origmass"), res.get("unified_refined_original"), res.get("unified_touched_original")
    lines += ["", "Table 4 analogue: the unified model's grasps replayed on the original URDFs"
              + (" (and on the canonical hand carrying the original URDF's finger masses)" if um else ""), ""]
    if um:
        head = ["hand", "finger masses: canonical / original [kg]", "canonical", "canonical, original masses", "original",
                "original - canonical ± SE [points]", "original - canonical (original masses) ± SE"]
        head += ["fingers refined: canonical → original", "original - canonical, refined ± SE"] if rro else []
        head += ["touch: canonical → original", "original - canonical, touch ± SE"] if rto else []
    else:
        head = ["hand", "canonical", "original", "change ± SE [points]"]
    lines += ["| " + " | ".join(head + ["paper (reported)"]) + " |", "|" + "---|" * (len(head) + 1)]
    for h in res["hands"]:
        c, s = paired_change(u, uo, h)
        rate = {k: f"{100 * v['per_hand'][h]['success_rate']:.1f} %" for k, v in
                (("u", u), ("um", um), ("uo", uo), ("ur", ur), ("rro", rro), ("ut", ut), ("rto", rto)) if v}
        if um:
            cm, sm = paired_change(um, uo, h)
            fm = res["finger_masses"][h]
            cells = [h, f"{sum(fm['canonical']):.3f} / {sum(fm['original']):.3f}", rate["u"], rate["um"], rate["uo"],
                     f"{c:+.1f} ± {s:.1f}", f"{cm:+.1f} ± {sm:.1f}"]
            if rro:
                cr, sr = paired_change(ur, rro, h)
                cells += [f"{rate['ur']} → {rate['rro']}", f"{cr:+.1f} ± {sr:.1f}"]
            if rto:
                ct, st = paired_change(ut, rto, h)
                cells += [f"{rate['ut']} → {rate['rto']}", f"{ct:+.1f} ± {st:.1f}"]
        else:
            cells = [h, rate["u"], rate["uo"], f"{c:+.1f} ± {s:.1f}"]
        lines.append("| " + " | ".join(cells + [str(PAPER_REPLAY.get(h, "-"))]) + " |")
    if rro:
        lines += ["", "Fingers refined: the same grasps with their fingers opened out of the object first (`refine=True`), "
                  "then simulated on the canonical and the original URDF." + (" Touch: opened and the hovering ones closed onto "
                                                                             "the surface (`--refine touch`) first." if rto else "")]
    if um and (uh := res.get("unified_hybrid")):
        lines += ["", "Table 4 attribution: the same grasps on four hands, each one step from the canonical hand to the "
                  "original URDF (paired changes over the same grasps, points ± SE): the finger masses (canonical "
                  "geometry, original masses), then the rest of the URDF but its link shapes (the hybrid hand, "
                  "`ohra.sim.hybrid`: original kinematics, joint limits, masses and inertias carrying the canonical "
                  "capsules and palm disc; `ohra grasp eval --original --collisions canonical`), then the link shapes", "",
                  "| hand | canonical | + original masses | hybrid (original URDF, canonical shapes) | original | "
                  "masses | rest of the URDF | link shapes | total |", "|---|---|---|---|---|---|---|---|---|"]
        for h in res["hands"]:
            steps = [paired_change(a, b, h) for a, b in ((u, um), (um, uh), (uh, uo), (u, uo))]
            lines.append(f"| {h} | " + " | ".join(f"{100 * v['per_hand'][h]['success_rate']:.1f} %" for v in (u, um, uh, uo))
                         + " | " + " | ".join(f"{c:+.1f} ± {se:.1f}" for c, se in steps) + " |")
    if um:
        lines += ["", "Finger masses: the sum over fingers of the links' `<inertial>` masses; canonical = the template's "
                  "capsules at 1000 kg/m^3, original = the original URDF's links moved by each finger "
                  "(`SimHand.finger_masses`, `ohra grasp eval --inertials original`)."]
    lines += ["", f"Budget: {res['steps']} steps per model; evaluation {res['n']} grasps per (hand, object) on "
              f"{len(res['objects'])} unseen objects; protocol {res['protocol_note']}."]
    if "pictures" in res:
        lines += ["", f"Pictures: `{res['pictures']['sheet']}` (contact sheet), `{res['pictures']['scene']}` (meshcat; 2 MB of meshcat JavaScript, regenerated by the study in seconds, not committed)."]
    return "\n".join(lines)


def protocol_note(protocol: Protocol) -> str:
    """The preset a protocol is, for table captions."""
    if abs(protocol.position_gain - Protocol.isaac_drive().position_gain) < 1e-12:
        return "isaac-drive"
    return "reference" if protocol == Protocol() else "custom (see JSON)"


def add_run_args(ap: argparse.ArgumentParser, steps: int, n: int, runs: str, name: str) -> None:
    """The training / evaluation options every grasp-model study shares (same budget flags)."""
    ap.add_argument("--steps", type=int, default=steps, help="training steps per model (3,000 underfit 1,634 grasps: "
                    "benchmarks/results/grasp_data_scaling*.md)")
    ap.add_argument("-n", type=int, default=n, help="sampled grasps per (hand, object)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--workers", type=int, default=1, help="simulation processes")
    ap.add_argument("--runs", default=str(ROOT / "runs" / runs))
    ap.add_argument("--name", default=name, help="results name")
    ap.add_argument("--quiet", action="store_true")


def pictures(model, hands: list[str], objects: list, ev: dict, name: str, per_row: int = 8,
             title: str = "unified model: first passing grasp per (hand, unseen object); red: none passed",
             refine: "bool | RefineSettings" = False) -> dict:
    """Contact sheet (hands x objects, the first grasp of each pair that passed, else the first grasp;
    green / red frame = passed / failed) and a meshcat scene (each hand's first passing grasp on the
    first object, side by side). Grasps are re-sampled with the evaluation's pair seeds (sampling is
    deterministic), the verdicts are the evaluation's. ``model``: one model for every hand, or a
    dict hand -> model (the zero-shot gallery: each unseen variant drawn by a model that never saw it);
    ``ev``: ``{"success": {"<hand>/<object>": [0/1 per grasp]}}``; ``refine``: the evaluation refined the
    fingers (the pictures must show the grasps it simulated)."""
    from matplotlib.figure import Figure

    from ohra.canonical.kinematics import HandModel
    from ohra.hands import get_hand
    from ohra.learn.grasp.evaluate import pair_seed
    from ohra.rotations import grasp_to_pose
    from ohra.sim import SimHand
    from ohra.sim.render import contact_sheet, render_grasps
    from ohra.viz import add_hand, add_mesh, new_visualizer, save_html

    objs = objects[:per_row]
    fig = Figure(figsize=(2.0 * len(objs), 2.1 * len(hands)), dpi=80)
    vis = new_visualizer()
    for r, h in enumerate(hands):
        sim = SimHand.from_params(get_hand(h), name=h)
        for c, o in enumerate(objs):
            ok = np.asarray(ev["success"][f"{h}/{o.name}"], dtype=bool)
            m = model[h] if isinstance(model, dict) else model
            grasps = m.sample(h, o, len(ok), seed=pair_seed(0, h, o.mesh_hash), refine=refine)
            i = int(np.argmax(ok)) if ok.any() else 0
            tile = contact_sheet(render_grasps(sim, o, grasps[i:i + 1], size=160), ok[i:i + 1], columns=1)
            ax = fig.add_subplot(len(hands), len(objs), r * len(objs) + c + 1)
            ax.imshow(tile)
            ax.set_xticks([]), ax.set_yticks([])
            ax.set_title(f"{o.name}: {int(ok.sum())}/{len(ok)}", fontsize=8)
            if c == 0:
                ax.set_ylabel(h, fontsize=8)
                T, q = grasp_to_pose(grasps[i])
                off = np.eye(4)
                off[1, 3] = 0.35 * r
                add_mesh(vis, np.asarray(o.mesh.vertices), np.asarray(o.mesh.faces), T=off, path=f"{h}/object")
                add_hand(vis, HandModel.from_params(get_hand(h)), q, off @ T, path=f"{h}/hand")
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    RESULTS.mkdir(parents=True, exist_ok=True)
    sheet = RESULTS / f"{name}_sheet.png"
    fig.savefig(sheet)
    scene = save_html(vis, RESULTS / f"{name}_scene.html")
    return {"sheet": sheet.name, "scene": scene.name}


def main() -> None:
    ap = script_parser(__doc__, __file__)
    ap.add_argument("--data", nargs="+", required=True)
    ap.add_argument("--hands", nargs="+", default=list(PAPER))
    ap.add_argument("--objects-file", type=Path, default=ROOT / "recipes" / "grasp_eval_objects.yaml")
    add_run_args(ap, steps=12000, n=100, runs="grasp_study", name="grasp_study")
    ap.add_argument("--no-compare-condition", dest="compare_condition", action="store_false",
                    help="skip the unified model with the raw-parameter condition (VAE vs params table)")
    args = ap.parse_args()
    # natural order (s2 before s10) whatever the shell's glob gives: the data order is part of the runs' keys
    args.data = natural_sorted(args.data)
    objects = eval_objects(args.objects_file)
    protocol = data_protocol(args.data)
    unified = trained("unified", args.data, args.hands, args)
    res = {"hands": args.hands, "steps": args.steps, "n": args.n, "objects": [o.name for o in objects], "data": args.data,
           "train_counts": json.loads((Path(args.runs) / "unified" / "metrics.json").read_text())["data"]["per_hand"],
           "protocol": {k: getattr(protocol, k) for k in ("dt", "position_gain", "velocity_gain", "motor_force", "friction")},
           "protocol_note": protocol_note(protocol)}
    res["unified"] = evaluated(unified, "unified", args.hands, objects, False, protocol, args)
    res["unified_original"] = evaluated(unified, "unified", args.hands, objects, True, protocol, args)
    res["unified_origmass"] = evaluated(unified, "unified", args.hands, objects, False, protocol, args, inertials="original")
    res["unified_hybrid"] = evaluated(unified, "unified", args.hands, objects, True, protocol, args, collisions="canonical")
    res["unified_refined"] = evaluated(unified, "unified", args.hands, objects, False, protocol, args, refine=True)
    res["unified_refined_original"] = evaluated(unified, "unified", args.hands, objects, True, protocol, args, refine=True)
    touch = RefineSettings(touch=True)
    res["unified_touched"] = evaluated(unified, "unified", args.hands, objects, False, protocol, args, refine=touch)
    res["unified_touched_original"] = evaluated(unified, "unified", args.hands, objects, True, protocol, args, refine=touch)
    res["finger_masses"] = {h: {"canonical": SimHand.from_params(get_hand(h), name=h).finger_masses.tolist(),
                                "original": SimHand.registered_original(h).finger_masses.tolist()} for h in args.hands}
    res["specific"] = {}
    for h in args.hands:
        m = trained(f"specific-{h}", args.data, [h], args)
        res["specific"][h] = evaluated(m, f"specific-{h}", [h], objects, False, protocol, args)
        res.setdefault("specific_touched", {})[h] = evaluated(m, f"specific-{h}", [h], objects, False, protocol, args,
                                                              refine=touch)
    if args.compare_condition:  # the zero-shot study's condition on the hands the VAE can read too
        m = trained("unified-params", args.data, args.hands, args, condition="params")
        res["unified_params"] = evaluated(m, "unified-params", args.hands, objects, False, protocol, args)
    res["pictures"] = pictures(unified, args.hands, objects, res["unified"], args.name)
    write_results(args.name, res, tables(res))


if __name__ == "__main__":
    run_script(main, __file__)
