"""``ohra grasp sample|eval`` and ``ohra train grasp``: the cross-embodiment grasp model from the shell.

    ohra train grasp --data DIR [DIR ...] [--hands H ...] [--test-objects O ...] --condition vae|params
                     [--encoder pointnet|dgcnn] [--diffuse-joints] [--steps N] [--batch-size B] [--seed S] [--threads T]
                     -o RUN [--resume]
    ohra grasp sample --hand H --object O [-n 100] [--seed S] [--refine [open|touch]] [--centre] [--candidates K] [--mirror auto|on|off] [--condition-hand H] [--model RUN] -o grasps.npz
    ohra grasp eval --hands H ... --objects O ... [-n 100] [--seed S] [--original [--collisions canonical] | --inertials original] [--condition-hand H] [--refine [open|touch]] [--centre] [--candidates K] [--mirror auto|on|off] [--model RUN] [-o report.json]

Plugged into :mod:`ohra.cli.main` by ``register(subparsers)`` (adds the ``grasp`` group and
``grasp`` under the ``train`` group, creating ``train`` if no other plugin did). torch is imported
only when a command runs.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Sequence

import numpy as np

from ohra.cli.main import BODY_CHOICES, BODY_HELP, subcommand_group, wrote
from ohra.errors import OhraError

if TYPE_CHECKING:
    from ohra.hands import Params


CENTRE_HELP = ("sample on the object centred on its bounding box, grasps moved back into its mesh frame (for a mesh "
               "whose frame origin lies away from the object, e.g. exported in scene coordinates)")
CANDIDATES_HELP = ("draw K grasps per wrist rotation and keep the one whose fingers lie nearest the object's surface "
                   "(default 1: the first draw)")
MIRROR_HELP = ("sample the hand as its mirror image on the mirrored object and mirror the grasps back: 'auto' (default) "
               "when the mirror image lies nearer the model's training hands (a left twin of a right training hand), 'on', 'off'")
REFINE_HELP = ("refine the fingers after sampling (ohra.learn.grasp.refine; tens of ms per grasp): 'open' (the flag "
               "alone) opens sunk fingers just enough to clear the object; 'touch' also closes hovering fingers onto "
               "its surface (+7.8 points over 'open' for the shipped model on unseen objects)")


def _mirror(choice: str) -> bool | str:
    """The ``mirror=`` argument of ``--mirror auto|on|off``."""
    return {"on": True, "off": False}.get(choice, choice)


def _refine(choice: str | None) -> Any:
    """The ``refine=`` argument of ``--refine [open|touch]``."""
    if choice is None:
        return False
    from ohra.learn.grasp.refine import RefineSettings

    return RefineSettings(touch=choice == "touch")


def register(sub: Any) -> None:
    """Add ``ohra grasp sample|eval`` and ``ohra train grasp``."""
    register_train(subcommand_group(sub, "train", "train learned models", "train_command"))
    g = subcommand_group(sub, "grasp", "the cross-embodiment grasp model: sample and evaluate grasps", "grasp_command")
    model_help = ("run or model directory, .pt file, or a shipped model: 'default' (VAE condition; base-form hands such "
                  "as Allegro, Barrett, Shadow) or 'leap' (raw-parameter condition, trained on 66 LEAP variants); "
                  "default: 'default', or 'leap' when no hand has a base form")
    p = g.add_parser("sample", help="sample grasps of a hand on an object -> .npz (key 'grasps', (N, 31))")
    p.add_argument("--hand", required=True, help="registered hand, leap_XXXX, hand spec YAML, or params JSON file")
    p.add_argument("--object", required=True, help="mesh (.obj/.stl/.ply/.off/.glb), object URDF or folder, builtin:NAME "
                   "or procedural:FAMILY:SEED")
    p.add_argument("--scale", type=float, default=None, help="multiply the coordinates of object files (0.001 for "
                   "millimetre meshes; built-in and procedural shapes keep their size)")
    p.add_argument("--body", choices=BODY_CHOICES, default="auto", help=BODY_HELP)
    p.add_argument("-n", type=int, default=100, help="number of grasps (default 100)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--model", help=model_help)
    p.add_argument("--refine", nargs="?", const="open", choices=("open", "touch"), help=REFINE_HELP)
    p.add_argument("--centre", action="store_true", help=CENTRE_HELP)
    p.add_argument("--candidates", type=int, default=1, help=CANDIDATES_HELP)
    p.add_argument("--mirror", choices=("auto", "on", "off"), default="auto", help=MIRROR_HELP)
    p.add_argument("--condition-hand", help="condition the model on this hand instead (paper Table 9); the joints stay "
                   "within --hand's limits")
    p.add_argument("-o", "--output", "--out", dest="output", required=True, help="output .npz")
    p.set_defaults(func=_cmd_sample)

    p = g.add_parser("eval", help="sample N grasps per (hand, unseen object) and run the six-direction test")
    p.add_argument("--hands", nargs="+", required=True,
                   help="hands to evaluate: registered hands, leap_XXXX, hand spec YAMLs or params JSON files")
    p.add_argument("--objects", nargs="+", required=True, help="builtin:NAME, procedural:FAMILY:SEED, mesh files "
                   "(.obj/.stl/.ply/.off/.glb), object URDFs or folders")
    p.add_argument("--scale", type=float, default=None, help="multiply the coordinates of object files (0.001 for "
                   "millimetre meshes; built-in and procedural shapes keep their size)")
    p.add_argument("--body", choices=BODY_CHOICES, default="auto", help=BODY_HELP)
    p.add_argument("-n", type=int, default=100, help="grasps per (hand, object) (default 100)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--model", help=model_help)
    p.add_argument("--original", action="store_true", help="replay on the hands' original URDFs through the action map")
    p.add_argument("--inertials", choices=("capsule", "original"), default="capsule",
                   help="finger masses of the canonical hand: the template's 1000 kg/m^3 capsules (default) or the "
                        "original URDF's (a registered hand, spec YAML or params JSON beside its spec; geometry stays canonical)")
    p.add_argument("--collisions", choices=("own", "canonical"), default="own",
                   help="with --original: the original URDF's collision shapes (default) or the canonical capsules on "
                        "its links (the hybrid hand: tells the link shapes' effect from the rest of the URDF's)")
    p.add_argument("--refine", nargs="?", const="open", choices=("open", "touch"), help=REFINE_HELP)
    p.add_argument("--centre", action="store_true", help=CENTRE_HELP)
    p.add_argument("--candidates", type=int, default=1, help=CANDIDATES_HELP)
    p.add_argument("--mirror", choices=("auto", "on", "off"), default="auto", help=MIRROR_HELP)
    p.add_argument("--condition-hand", help="condition the model on this hand instead (paper Table 9); the grasps run on "
                   "the true hand, within its joint limits")
    p.add_argument("--workers", type=int, default=1, help="simulation processes (default 1)")
    p.add_argument("--protocol", default="reference", choices=("reference", "strict", "isaac-step", "isaac-drive"),
                   help="six-direction test preset (default reference; use the one the training data was filtered with)")
    p.add_argument("--object-point", choices=("frame", "com"), default="frame",
                   help="the point the fingers close toward and whose displacement is measured: the mesh frame's origin "
                        "(default, the reference's) or the object's centre of mass")
    p.add_argument("--allow-seen", action="store_true", help="also evaluate objects the model was trained on")
    p.add_argument("-o", "--output", "--out", dest="output", help="write the JSON report here")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_eval)


def register_train(train_sub: Any) -> None:
    """Add ``grasp`` to the subparsers of ``ohra train``."""
    from ohra.learn.grasp.config import CONDITIONS, ENCODERS, GraspModelConfig, GraspTrainConfig

    m, t = GraspModelConfig(), GraspTrainConfig()
    p = train_sub.add_parser("grasp", help="train the cross-embodiment grasp model on grasp datasets")
    p.add_argument("--data", nargs="+", required=True, help="dataset directories (written by the synthesiser)")
    p.add_argument("--hands", nargs="*", default=[], help="hands to train on (default: every hand in the data)")
    p.add_argument("--test-objects", nargs="*", default=[], help="objects held out of training (evaluate on them)")
    p.add_argument("--test-hands", nargs="*", default=[],
                   help="hands held out of training, by name and by parameters (zero-shot models)")
    p.add_argument("--condition", choices=CONDITIONS, default=m.condition, help="hand condition (default vae)")
    p.add_argument("--encoder", choices=ENCODERS, default=m.encoder, help="object encoder (default pointnet)")
    p.add_argument("--object-dim", type=int, default=m.object_dim,
                   help=f"object feature size (default {m.object_dim}; the paper's DGCNN: 512)")
    p.add_argument("--diffuse-joints", action="store_true",
                   help="diffuse the 22 joints with the wrist translation (no joint network; default: the paper's joint "
                        "network given the sampled translation)")
    p.add_argument("--steps", type=int, default=t.steps, help=f"training steps (default {t.steps})")
    p.add_argument("--batch-size", type=int, default=t.batch_size, help=f"grasps per step (default {t.batch_size})")
    p.add_argument("--lr", type=float, default=t.lr, help=f"Adam learning rate at step 0, cosine-annealed (default {t.lr:g})")
    p.add_argument("--seed", type=int, default=t.seed)
    p.add_argument("--threads", type=int, default=t.threads, help=f"torch CPU threads (default {t.threads}; results depend on it)")
    p.add_argument("--device", default=t.device,
                   help="torch device: cpu (default), cuda, cuda:N, mps; batches are drawn on the CPU either way")
    p.add_argument("--rotated-copies", type=int, default=t.rotated_copies, help=f"rotated copies per object and batch (default {t.rotated_copies}; 0: none)")
    p.add_argument("--objects-per-step", type=int, default=t.objects_per_step, help="cap on distinct objects per batch (0: none)")
    p.add_argument("--max-per-pair", type=int, default=t.max_per_pair, help="cap on grasps per (hand, object) (0: all)")
    p.add_argument("--condition-noise", type=float, default=t.condition_noise,
                   help="std of Gaussian noise on each training row's hand condition (standardised units for params; 0: none)")
    p.add_argument("--penetration-weight", type=float, default=t.penetration_weight,
                   help="weight of the finger-object penetration term on the joints (base-form hands; 0: off)")
    p.add_argument("--penetration-shift", type=float, default=t.penetration_shift,
                   help="std [m] of the palm shift the penetration term is evaluated at (0: the data's palm)")
    p.add_argument("--contact-weight", type=float, default=t.contact_weight,
                   help="weight of the two-sided finger-contact term: each finger link's distance to the object pulled "
                        "to the data's (base-form hands; 0: off)")
    p.add_argument("--contact-form", choices=("capped", "target"), default=t.contact_form,
                   help="'capped': both distances capped at 1 cm; 'target': a link the data has on the surface is pulled "
                        f"there from any distance (default {t.contact_form})")
    p.add_argument("--checkpoint-every", type=int, default=t.checkpoint_every,
                   help=f"steps between checkpoints (default {t.checkpoint_every}; Ctrl-C also saves one)")
    p.add_argument("--vae", help="VAE for the 'vae' condition (default: the shipped one)")
    p.add_argument("-o", "--output", "--out", dest="output", required=True, help="run directory")
    p.add_argument("--resume", action="store_true", help="continue from OUTPUT/checkpoints/last.pt")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_train)


def run(args: argparse.Namespace) -> int:
    return int(args.func(args) or 0)


def _torch() -> None:
    from ohra.learn import require_torch

    require_torch()


def _cmd_train(args: argparse.Namespace) -> int:
    _torch()
    from ohra.learn.grasp.config import GraspModelConfig, GraspTrainConfig
    from ohra.learn.grasp.train import train_grasp

    out = Path(args.output)
    if not args.resume and (out / "checkpoints" / "last.pt").exists():
        raise OhraError(f"{out} already holds a training run; pass --resume to continue it or choose another -o")
    mcfg = GraspModelConfig(encoder=args.encoder, condition=args.condition, object_dim=args.object_dim,
                            diffuse_joints=args.diffuse_joints)
    tcfg = GraspTrainConfig(steps=args.steps, batch_size=args.batch_size, lr=args.lr, seed=args.seed, threads=args.threads, device=args.device,
                            rotated_copies=args.rotated_copies, objects_per_step=args.objects_per_step,
                            max_per_pair=args.max_per_pair, checkpoint_every=args.checkpoint_every,
                            condition_noise=args.condition_noise, penetration_weight=args.penetration_weight,
                            penetration_shift=args.penetration_shift, contact_weight=args.contact_weight, contact_form=args.contact_form, hands=tuple(args.hands), test_objects=tuple(args.test_objects),
                            test_hands=tuple(args.test_hands))
    if args.vae and args.condition != "vae":  # it would be ignored without a word
        raise OhraError(f"--vae {args.vae} gives the VAE of --condition vae; this run is --condition {args.condition}")
    res = train_grasp(args.data, mcfg, tcfg, out, resume=args.resume, progress=not args.quiet, vae_path=args.vae)
    m = res.metrics
    f = m["final_losses"]
    earlier = m["steps"] - m["steps_this_run"]
    done = (f"trained {m['steps']} steps in {m['train_seconds_total']:.1f} s" if not earlier else
            f"trained steps {earlier}-{m['steps']} in {m['train_seconds_this_run']:.1f} s ({m['steps']} steps in "
            f"{m['train_seconds_total']:.1f} s over all sessions)")
    print(f"{done} on {m['data']['grasps']} grasps "
          f"({', '.join(f'{h} {c}' for h, c in m['data']['per_hand'].items())}); "
          f"final loss diffusion {f.get('diffusion', float('nan')):.4f}, joints {f.get('joints', float('nan')):.4f}")
    from ohra.learn.grasp.data import recorded_test_objects

    recorded = sorted(recorded_test_objects([Path(d) for d in args.data]) - set(args.test_objects))
    if recorded:
        print(f"ohra: note: held out the test object(s) the dataset's recipe split off: {', '.join(recorded)}",
              file=sys.stderr)
    if args.test_hands:
        from ohra.data import GraspDataset

        in_data = {h for _, h, _, _ in GraspDataset([Path(d) for d in args.data]).entries}
        unheld = [h for h in args.test_hands if h not in in_data]
        if unheld:  # held out by name (and parameters) but no dataset has them by that name
            print(f"ohra: note: test hand(s) {', '.join(unheld)} are in none of the datasets by name (held out by their "
                  "parameters too; check the spelling if they should be there)", file=sys.stderr)
    # a test object in no dataset is warned about by the library when the data load (ohra.learn.grasp.data)
    wrote(f"{out / 'model.pt'} and {out / 'metrics.json'}")
    return 0


def _load(model: str | None, hands: Sequence[str] = (), resolved: Mapping[str, Params] | None = None):
    """(model, note): the model ``--model`` names; without one, the shipped ``default`` model, or the
    shipped ``leap`` model when none of ``hands`` has a base form (the default model's VAE condition reads
    base-form hands only: LEAP variants and extended-only hands), with a note for stderr, which the command
    prints once its work is done (an error stays the one line on stderr). ``resolved``: params the caller
    already read, by hand spec (a params JSON is then not read again)."""
    _torch()
    from ohra.errors import ParamsError
    from ohra.learn.grasp.condition import resolve_hand
    from ohra.learn.grasp.model import default_model_dir, load_grasp_model

    chosen = load_grasp_model(model)
    if model is not None or not hands:
        return chosen, None
    unusable = []
    for h in hands:
        # an unknown or malformed hand is its own error, not a reason to switch models
        params = resolved[h] if resolved and h in resolved else resolve_hand(h)
        try:
            chosen.condition.vector(params)
        except ParamsError:
            unusable.append(h)
    if unusable and len(unusable) == len(hands):
        note = (f"ohra: note: the default grasp model (VAE condition) reads base-form hands only, and "
                f"{', '.join(unusable)} {'has' if len(unusable) == 1 else 'have'} none: used the shipped 'leap' model "
                "(raw-parameter condition, trained on 66 LEAP variants; --model leap)")
        # by its folder: a folder named 'leap' where the user runs ohra must not stand in for the shipped model
        return load_grasp_model(default_model_dir("leap")), note
    return chosen, None  # a mix: evaluate_model names the hands the default model cannot condition on


def _output(path: str, suffix: str) -> Path:
    """``-o`` checked before any work: the file type it must have, not a folder."""
    from ohra.io import check_output, check_suffix

    return check_output(check_suffix(path, suffix))  # not a folder, no parent that is a file


def _cmd_sample(args: argparse.Namespace) -> int:
    from ohra.hands import get_hand

    out = _output(args.output, ".npz")
    params = get_hand(args.hand)  # a misspelt hand is named before seconds of torch imports; read once, here
    from ohra.data.dataset import atomic_write_npz

    from ohra.learn.grasp.model import resolve_object
    from ohra.synth import MIN_GRASP_FINGERS

    # the model must read the hand it is conditioned on
    model, note = _load(args.model, [args.condition_hand or args.hand], resolved={args.hand: params})
    obj = resolve_object(args.object, scale=args.scale, body=args.body)  # sampling warns about its size (GraspModel.object_warnings)
    timing: dict = {}
    mirrored = model.mirrors(args.condition_hand or params, _mirror(args.mirror))
    g = model.sample(params, obj, args.n, seed=args.seed, timing=timing, refine=_refine(args.refine), centre=args.centre,
                     condition_hand=args.condition_hand, candidates=args.candidates, mirror=mirrored, name=args.hand)
    from ohra.hands import get_couplings

    couplings = get_couplings(args.hand)
    if couplings:  # the network does not know them: coupled joints follow their drivers, as simulation runs them
        from ohra.canonical.couplings import project

        g[:, 9:] = project(couplings, g[:, 9:])
        print(f"ohra: note: {len(couplings)} coupled joint(s) of {args.hand} set from their drivers "
              "(ohra.canonical.couplings.project), as simulation drives them", file=sys.stderr)
    from ohra.canonical.params import ExtendedParams

    # what the grasps were made for: ohra eval takes the form from here (the base and extended canonical hands of
    # one registered hand differ, and so do their outcomes)
    atomic_write_npz(out, {"grasps": g.astype(np.float64), "hand": np.array(str(args.hand)),
                           "form": np.array("extended" if isinstance(params, ExtendedParams) else "base"),
                           "model": np.array(str(args.model or ("leap" if note else "default"))),
                           "mirrored": np.array(bool(mirrored)),
                           # and how, so that the file can be made again: object (as given, its name and mesh hash),
                           # seed and the sampling options
                           "object": np.array(str(args.object)), "object_name": np.array(obj.name),
                           "scale": np.array(float(obj.file_scale)),  # ohra eval reads the object at it again
                           "body": np.array(str(obj.body_choice)),  # and simulates it as this body (refinement used it)
                           "object_hash": np.array(obj.mesh_hash), "seed": np.array(int(args.seed)),
                           "refine": np.array(str(args.refine or "none")), "candidates": np.array(int(args.candidates)),
                           "centre": np.array(bool(args.centre)),
                           "condition_hand": np.array(str(args.condition_hand or ""))})
    if note:
        print(note, file=sys.stderr)
    fingers = params.num_fingers
    if fingers < MIN_GRASP_FINGERS:  # sampling is defined for any hand; their grasps hold nothing
        print(f"ohra: note: {args.hand} has {fingers} finger(s): its grasps cannot hold an object "
              "(grasp synthesis refuses such hands)", file=sys.stderr)
    extra = f", refinement {1e3 * timing['refine_seconds'] / len(g):.1f} ms per grasp" if args.refine else ""
    how = " (sampled as its mirror image)" if mirrored else ""
    print(f"{len(g)} grasps of {args.hand}{how} on {args.object} ({1e3 * timing['seconds'] / len(g):.2f} ms per grasp{extra})")
    wrote(out)
    return 0


def _cmd_eval(args: argparse.Namespace) -> int:
    from ohra.learn.grasp.evaluate import evaluate_model

    if args.workers < 1:
        raise OhraError(f"--workers must be >= 1, got {args.workers}")
    if args.output:
        _output(args.output, ".json")
    model, note = _load(args.model, [args.condition_hand] if args.condition_hand else args.hands)
    from ohra.sim import Protocol

    from ohra.objects.model import resolve_objects

    objs = resolve_objects(args.objects, scale=args.scale, body=args.body)
    # with a report file, finished pairs are kept beside it until the report is written: a rerun of an
    # interrupted evaluation continues where it stopped
    pairs_dir = Path(args.output).with_suffix(".pairs") if args.output else None
    rep = evaluate_model(model, args.hands, objs, n=args.n, seed=args.seed, original=args.original, resume_dir=pairs_dir,
                         workers=args.workers, progress=not args.quiet, allow_seen=args.allow_seen,
                         protocol=replace(Protocol.preset(args.protocol), object_point=args.object_point), inertials=args.inertials,
                         condition_hand=args.condition_hand, refine=_refine(args.refine), collisions=args.collisions, centre=args.centre,
                         candidates=args.candidates, mirror=_mirror(args.mirror))
    if args.output:
        from ohra.data.dataset import atomic_write_json

        atomic_write_json(args.output, rep.to_dict())
        import shutil

        shutil.rmtree(pairs_dir, ignore_errors=True)
        if rep.meta.get("resumed_pairs"):
            print(f"ohra: note: {rep.meta['resumed_pairs']} of {len(rep.pairs)} pairs came from the interrupted run's "
                  f"{pairs_dir}", file=sys.stderr)
    wh = max([20] + [len(p.hand) for p in rep.pairs])  # a file hand's label (its path) can be long
    wo = max([16] + [len(p.object) for p in rep.pairs])
    for p in rep.pairs:
        d = p.diversity_all or {}
        print(f"{p.hand:{wh}s} {p.object:{wo}s} {int(p.success.sum()):4d}/{len(p.success):<4d} "
              f"({100 * p.success_rate:5.1f} %)  {1e3 * p.sample_seconds / len(p.success):6.2f} ms/grasp  "
              f"approach spread {d.get('approach_spread', float('nan')):.2f}")
    mirrored = set(rep.meta.get("mirrored_hands", []))
    for h, r in rep.per_hand().items():
        print(f"{h}: {100 * r['success_rate']:.1f} % of {r['n']} grasps{' (sampled as its mirror image)' if h in mirrored else ''}{(' (original URDF, canonical collision shapes)' if args.collisions == 'canonical' else ' (original URDF)') if args.original else ''}"
              f"{' (canonical, original finger masses)' if args.inertials == 'original' and not args.original else ''}"
              f"{f' (model told {args.condition_hand})' if args.condition_hand else ''}")
    if note:
        print(note, file=sys.stderr)
    if args.output:
        wrote(args.output)
    return 0
