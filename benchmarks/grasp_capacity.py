"""Does network capacity close the grasp model's precision gap (issue 13)? The paper's encoder on a GPU.

The committed study (``grasp_study.py``) trained a PointNet-encoder model (256-D object feature) because
the paper's DGCNN encoder trains at ~3 clouds/s on this machine's CPU (days per run). The study's models
do no better on their training objects than on unseen ones (``grasp_seen_objects.py``), so the gap to
the paper's success is precision, and more data or more steps did not close it (``grasp_scale_up.py``).
Capacity is the lever left untested. This script trains, on the study's data (the 23 committed folders),
hands, VAE condition, seed, batch (128), learning rate and steps (12,000), three larger models:

- ``dgcnn512``: the paper's encoder family: DGCNN edge convolutions (64, 64, 128, 256), k = 20, 512-D
  object feature; denoiser and joint network as the study's;
- ``wide``: the study's PointNet, wider and deeper everywhere: point MLP (64, 128, 256, 512), 512-D
  feature, denoiser (1024, 512, 256), joint network 512 wide with 3 blocks;
- ``dgcnn512-wide``: both.

Stop 52 adds two arms for the other candidate cause of imprecise fingers: the paper's joint network
regresses the joints given the sampled translation, i.e. it predicts their conditional mean, which for
a multimodal set of finger placements is none of them (half the sampled fingers are sunk, a third hover):

- ``diffq``: the 22 joints diffused together with the translation (``GraspModelConfig.diffuse_joints``;
  per-joint standardisation; no joint network), the study's widths;
- ``diffq-wide``: the same with the ``wide`` arm's denoiser (1024, 512, 256), since the denoiser now
  carries the joints too.

The script trains each arm and evaluates it exactly as the study evaluated its unified model (100 grasps per (hand, unseen
object) of ``recipes/grasp_eval_objects.yaml``, sampling seed 0, the data's protocol, canonical URDFs),
paired over the same wrist rotations with the committed evaluation ``runs/grasp_study/eval_unified.json``.

How it is read, written before any of these models was trained (stop 51):
pooled over the three hands (3,900 paired grasps), an arm whose success exceeds the committed unified
model's by more than two standard errors reads as "capacity helped", below minus two as "capacity hurt",
otherwise "no change detectable"; per-hand differences are shown, not read. The same rule, written in
stop 52 before either was trained, reads the two ``diffq`` arms ("diffused joints helped/hurt"). One training seed, one
sampling seed. ``--touch`` adds the same comparison with test-time finger refinement (``--refine touch``)
against ``runs/grasp_study/eval_unified_touched.json``. The shipped model and Tables 4-6 stay the committed
study's whatever this shows (an arm that wins is the candidate for the next full study).

Two phases, so that training can run where a GPU is (the evaluation needs PyBullet, the CPU machine):

    python benchmarks/grasp_capacity.py train --device cuda --parallel [--torch-only]
    python benchmarks/grasp_capacity.py eval [--touch] [--workers 2]
      -> benchmarks/results/grasp_capacity.{json,md}

``--torch-only`` stands in for Pinocchio, Coal, CasADi and PyBullet when they are not installed
(``_torch_only.py``; training calls none of them). Runs are cached and resumable under ``--runs``
(``_study_cache.py``; a run made on another device is reused: its key records the device).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
from _common import run_script, script_parser  # noqa: E402

HANDS = ["allegro_hand_left", "barrett_hand", "shadow_hand_right"]
STUDY_DATA = [f"datasets/grasp_unified_s{i}" for i in range(23)]

# each arm's GraspModelConfig fields that differ from the default (the study's model)
ARMS: dict[str, dict] = {
    "dgcnn512": {"encoder": "dgcnn", "encoder_channels": (64, 64, 128, 256), "object_dim": 512, "dgcnn_k": 20},
    "wide": {"encoder_channels": (64, 128, 256, 512), "object_dim": 512, "denoiser_hidden": (1024, 512, 256),
             "joint_hidden": 512, "joint_blocks": 3},
    "dgcnn512-wide": {"encoder": "dgcnn", "encoder_channels": (64, 64, 128, 256), "object_dim": 512, "dgcnn_k": 20,
                      "denoiser_hidden": (1024, 512, 256), "joint_hidden": 512, "joint_blocks": 3},
    # stop 52: the joints diffused with the translation (no joint network), at the study's widths and wider
    "diffq": {"diffuse_joints": True},
    "diffq-wide": {"diffuse_joints": True, "denoiser_hidden": (1024, 512, 256)},
}
# how a pooled change is read, per arm (the rule itself is the docstring's)
VERDICTS = {arm: ("diffused joints helped", "diffused joints hurt") if ARMS[arm].get("diffuse_joints")
            else ("capacity helped", "capacity hurt") for arm in ARMS}


def _key(arm: str, args: argparse.Namespace) -> dict:
    from _study_cache import _jsonable, train_key

    return train_key(args.data, HANDS, args.steps, args.seed, "vae") | _jsonable(
        {"model": ARMS[arm], "batch_size": args.batch_size, "device": args.device})


def train_arm(arm: str, args: argparse.Namespace) -> None:
    """Train (or resume, or reuse) one arm's run under ``args.runs``."""
    from _study_cache import claim_run

    from ohra.learn.grasp.config import GraspModelConfig, GraspTrainConfig
    from ohra.learn.grasp.train import torch_device, train_grasp

    mcfg = GraspModelConfig(**ARMS[arm])
    tcfg = GraspTrainConfig(steps=args.steps, batch_size=args.batch_size, seed=args.seed, threads=args.threads,
                            hands=tuple(HANDS), device=args.device, checkpoint_every=500)
    torch_device(args.device)  # a missing device stops here, before the run folder is claimed under its key
    run = Path(args.runs) / arm
    if claim_run(run, _key(arm, args)):
        print(f"{arm}: trained already ({run})", flush=True)
        return
    t0 = time.perf_counter()
    res = train_grasp(args.data, mcfg, tcfg, run, resume=(run / "checkpoints" / "last.pt").exists(), progress=not args.quiet)
    n_params = sum(p.numel() for p in res.model.net.parameters())
    print(f"{arm}: {args.steps} steps in {time.perf_counter() - t0:.0f} s on {args.device} ({n_params / 1e6:.2f} M "
          f"parameters); final losses {res.metrics['final_losses']}", flush=True)


def cmd_train(args: argparse.Namespace) -> None:
    if args.parallel and len(args.arms) > 1:  # one process per arm, all at once
        from _torch_only import train_in_parallel

        train_in_parallel(__file__, args, "--arms", args.arms)
        return
    for arm in args.arms:
        train_arm(arm, args)


def cmd_eval(args: argparse.Namespace) -> None:
    from _common import write_results
    from grasp_scale_up import baseline, comparison_lines, paired_comparison, rates
    from grasp_study import PAPER, data_protocol, eval_objects, evaluated, protocol_note

    from _study_cache import cached, eval_key, run_key
    from ohra.learn.grasp import load_grasp_model
    from ohra.learn.grasp.refine import RefineSettings

    objects = eval_objects(args.objects_file)
    protocol = data_protocol(args.data)
    base_dir = args.baseline
    base = {"raw": baseline(base_dir, objects, args.n, protocol)}
    modes = ["raw"] + (["touch"] if args.touch else [])
    if args.touch:
        path = base_dir / "eval_unified_touched.json"
        want = eval_key(run_key(base_dir / "unified"), hands=HANDS, objects=[o.name for o in objects], n=args.n, seed=0,
                        original=False, protocol=protocol, refine=RefineSettings(touch=True))
        if (hit := cached(path, want)) is None:
            raise SystemExit(f"{path}: made with other evaluation settings than this run's")
        base["touch"] = hit
    a = argparse.Namespace(**{**vars(args), "runs": args.runs})
    rows, comps = [], {m: [] for m in modes}
    from ohra.learn.grasp.config import GraspModelConfig
    from ohra.learn.grasp.model import GraspNet

    committed = load_grasp_model(base_dir / "unified").net
    hand_dim = committed.hand_dim
    study_metrics = json.loads((base_dir / "unified" / "metrics.json").read_text())
    rows.append({"name": "committed unified (PointNet 256-D)", "device": "cpu",
                 "train_min": study_metrics["train_seconds_total"] / 60,
                 "params_m": sum(p.numel() for p in committed.parameters()) / 1e6, **{m: rates(base[m], HANDS) for m in modes}})
    for arm in args.arms:
        run = Path(args.runs) / arm
        if not (run / "metrics.json").exists():
            print(f"{arm}: not trained ({run}); skipped", file=sys.stderr)
            continue
        made, want = run_key(run), _key(arm, args)
        made.pop("device", None), want.pop("device", None)  # a run trained on a GPU is evaluated here
        if made != want:
            raise SystemExit(f"{run}: trained with other settings than this call's (data, steps, seed, batch or model)")
        m = json.loads((run / "metrics.json").read_text())
        row = {"name": arm, "device": m.get("device", "cpu"), "train_min": m["train_seconds_total"] / 60, "model": ARMS[arm],
               "params_m": sum(p.numel() for p in GraspNet(GraspModelConfig(**ARMS[arm]), hand_dim).parameters()) / 1e6}
        for mode in modes:
            refine = RefineSettings(touch=True) if mode == "touch" else False
            # the weights of arms that did not help are not committed: their cached verdicts stand without them
            key = eval_key(run_key(run), hands=HANDS, objects=[o.name for o in objects], n=args.n, seed=0, original=False,
                           protocol=protocol, **({"refine": refine} if refine else {}))
            path = Path(args.runs) / f"eval_{arm}{'_touched' if refine else ''}.json"
            if (ev := cached(path, key)) is None:
                if not (run / "model.pt").exists():
                    raise SystemExit(f"{run}: no model.pt to evaluate ({mode}); train it again (phase train, same settings)")
                ev = evaluated(load_grasp_model(run), arm, HANDS, objects, False, protocol, a, refine=refine)
            row[mode] = rates(ev, HANDS)
            comps[mode].append(paired_comparison(base[mode], ev, HANDS, f"{arm} - committed ({mode})",
                                                 VERDICTS[arm]))
        rows.append(row)
    res = {"hands": HANDS, "n": args.n, "objects": [o.name for o in objects], "data": args.data, "steps": args.steps,
           "protocol_note": protocol_note(protocol), "rows": rows, "comparisons": comps, "paper": PAPER}
    write_results(args.name, res, table(res))


def table(res: dict) -> str:
    hands, modes = res["hands"], list(res["comparisons"])
    lines = [f"Unified grasp model vs other networks: more capacity, diffused joints (same data, hands, VAE condition, seed, batch, {res['steps']} steps): "
             f"{res['n']} grasps per (hand, object) on {len(res['objects'])} unseen objects, protocol {res['protocol_note']}, "
             "canonical URDFs. Rule written before training (script docstring): pooled paired difference > 2 SE reads as a change.",
             "", "| model | trained on | train min | parameters [M] | " + " | ".join(
                 f"{h} ({m})" for m in modes for h in [*hands, "pooled"]) + " |",
             "|---|---|---|---|" + "---|" * ((len(hands) + 1) * len(modes))]
    for r in res["rows"]:
        lines.append(f"| {r['name']} | {r['device']} | {r['train_min']:.1f} | "
                     + f"{r['params_m']:.2f} | "
                     + " | ".join(f"{100 * r[m]['per_hand'][h]:.1f} %" if h in hands else f"{100 * r[m]['pooled']:.1f} %"
                                  for m in modes for h in [*hands, "pooled"]) + " |")
    lines.append("| paper (reported, Isaac Gym, DGCNN 512-D) | GPU | - | - | "
                 + " | ".join(f"{res['paper'][h]} %" if h in hands else "-" for m in modes for h in [*hands, "pooled"]) + " |")
    from grasp_scale_up import comparison_lines

    for m in modes:
        lines += ["", *comparison_lines(res["comparisons"][m], hands, f"paired change vs committed ({m})")]
    return "\n".join(lines)


def main() -> None:
    ap = script_parser(__doc__, __file__)
    ap.add_argument("phase", choices=("train", "eval"))
    ap.add_argument("--data", nargs="+", default=STUDY_DATA,
                    help="dataset folders (default: the study's 23 committed folders; run from the repository root)")
    ap.add_argument("--arms", nargs="+", default=list(ARMS), choices=list(ARMS))
    ap.add_argument("--steps", type=int, default=12000)
    ap.add_argument("--batch-size", type=int, default=128)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--device", default="cpu", help="torch device of the training (the run key records it)")
    ap.add_argument("--parallel", action="store_true", help="train the arms in one process each, at once")
    ap.add_argument("--torch-only", action="store_true", help="stand in for missing Pinocchio/Coal/CasADi/PyBullet")
    ap.add_argument("--objects-file", type=Path, default=ROOT / "recipes" / "grasp_eval_objects.yaml")
    ap.add_argument("-n", type=int, default=100)
    ap.add_argument("--workers", type=int, default=1, help="simulation processes (eval)")
    ap.add_argument("--touch", action="store_true", help="also evaluate with --refine touch (eval)")
    ap.add_argument("--runs", default=str(ROOT / "runs" / "grasp_capacity"))
    ap.add_argument("--baseline", type=Path, default=ROOT / "runs" / "grasp_study")
    ap.add_argument("--name", default="grasp_capacity")
    ap.add_argument("--quiet", action="store_true")
    args = ap.parse_args()
    from _torch_only import run_phase

    run_phase(args, cmd_train, cmd_eval, "grasp_capacity")


if __name__ == "__main__":
    run_script(main, __file__)
