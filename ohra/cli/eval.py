"""``ohra eval``: run the six-direction test on a grasp file and report the success rate.

    ohra eval GRASPS.npz --hand NAME --object MESH|builtin:NAME [--workers K] [--mode eval|filter]
              [--strict] [--isaac-step] [--isaac-drive] [--original | --inertials original] [--form base|extended] [--render SHEET.png] [--meshcat SCENE.html] [-o report.json]

``GRASPS`` is an ``.npz`` (key ``grasps``, or its only array) or ``.npy`` of shape (N, 31):
``[t, rot6d, q22]``, the canonical palm pose in the object's mesh frame and canonical joints. Bad
input (shape, NaN, non-rotations, missing or empty meshes, unknown hands) is one line on stderr and
exit code 2; outputs are written atomically only after the evaluation succeeded. Joints outside
the limits are clamped, warned about and counted in the report.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np

from ohra.cli.main import BODY_CHOICES, BODY_HELP, wrote
from ohra.errors import GraspError, ObjectError

EPILOG = "Exit codes: 0 ok, 2 bad input. The report is JSON (success, displacements per phase, contacts, penetration)."


def register(subparsers) -> None:
    p = subparsers.add_parser("eval", help="evaluate grasps with the six-direction PyBullet test",
                              description=__doc__.split("\n\n")[0], epilog=EPILOG)
    p.add_argument("grasps", help="grasp file: .npz (key 'grasps' or its only array) or .npy, shape (N, 31)")
    p.add_argument("--hand", required=True, help="registered hand, leap_XXXX, hand spec YAML, or a params JSON file")
    p.add_argument("--object", required=True, help="mesh (.obj/.stl/.ply/.off/.glb), object URDF or folder, builtin:NAME "
                   "or procedural:FAMILY:SEED")
    p.add_argument("--scale", type=float, default=None, help="multiply the coordinates of object files (0.001 for millimetre meshes)")
    p.add_argument("--body", choices=BODY_CHOICES, default=None, help=BODY_HELP.replace(
        "auto (default: ", "auto (default, unless the grasp file records another: ", 1))
    p.add_argument("--key", default=None, help="array name inside the .npz (default: 'grasps' or the only array)")
    p.add_argument("--workers", type=int, default=1, help="processes (default 1)")
    p.add_argument("--backend", choices=("process", "ray"), default="process", help="process pool (default) or Ray")
    p.add_argument("--address", default=None, help="Ray cluster address (with --backend ray; default: a local cluster)")
    p.add_argument("--mode", choices=("eval", "filter"), default="eval", help="eval (default) or filter, which also needs the object within 5 cm of the origin")
    p.add_argument("--protocol", default="reference", choices=("reference", "strict", "isaac-step", "isaac-drive"),
                   help="six-direction test preset, as in ohra grasp eval (default reference); the three flags below "
                        "are the same presets and combine (--strict --isaac-step)")
    p.add_argument("--strict", action="store_true", help="strict preset: friction 1.0, gravity during the perturbations")
    p.add_argument("--isaac-step", action="store_true", help="Isaac's literal time step (100 Hz x 2 substeps) instead of 240 Hz")
    p.add_argument("--isaac-drive", action="store_true",
                   help="fingers close at Isaac's drive speed (position gain dt*1000/200) instead of gain 0.3")
    p.add_argument("--original", action="store_true", help="replay on the hand's original URDF (needs the hand assets)")
    p.add_argument("--inertials", choices=("capsule", "original"), default="capsule",
                   help="finger masses of the canonical hand: the template's 1000 kg/m^3 capsules (default) or the "
                        "original URDF's (needs the hand assets; geometry stays canonical)")
    p.add_argument("--form", choices=("base", "extended"), default=None,
                   help="canonical form the grasps were made for (default: the hand's natural form); with --original it "
                        "picks the action map that carries them to the original joints")
    p.add_argument("--no-early-exit", action="store_true", help="simulate every grasp to the end")
    p.add_argument("--object-point", choices=("frame", "com"), default="frame",
                   help="the point the fingers close toward and whose displacement is measured: the mesh frame's origin "
                        "(default, the reference's) or the object's centre of mass (outcomes then do not depend on "
                        "where the mesh's origin lies)")
    p.add_argument("--limit", type=int, default=None, help="evaluate only the first N grasps")
    p.add_argument("--render", metavar="PNG", default=None, help="write a contact sheet of the grasps (first 16)")
    p.add_argument("--meshcat", metavar="HTML", default=None, help="write a meshcat scene of the first grasp as static HTML")
    p.add_argument("-o", "--output", "--out", dest="output", metavar="JSON", default=None,
                   help="write the JSON report here; until it is written, finished grasps are kept in OUTPUT's "
                        ".partial.npz beside it, and a rerun after an interruption simulates only the rest")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def eval_hand(name: str, original: bool = False, form: str | None = None, inertials: str = "capsule"):
    """The simulated hand ``ohra eval`` runs: the canonical hand of ``form`` (with its couplings), or
    the original URDF driven through that form's action map; ``inertials="original"`` gives the
    canonical hand the original URDF's finger masses."""
    from ohra.hands import get_couplings, get_hand
    from ohra.sim import SimHand
    from ohra.sim.hands import original_finger_masses

    if original:
        return SimHand.original_of(name, form)  # a registered name, a spec YAML or a params JSON with its spec
    hand = SimHand.from_params(get_hand(name, form), name=name, couplings=get_couplings(name, form))
    if inertials == "original":
        hand = hand.with_finger_masses(original_finger_masses(name, form))
    return hand


def partial_path(output: str | Path) -> Path:
    """Where ``ohra eval -o OUTPUT`` keeps finished grasps until the report is written (``OUTPUT`` with
    ``.partial.npz`` for its suffix)."""
    out = Path(output)
    return out.with_name(out.stem + ".partial.npz")


def load_grasp_file(path: str | Path, key: str | None = None) -> tuple[np.ndarray, dict[str, str]]:
    """The (N, 31) array of a grasp file and the ``hand``, ``form`` and ``model`` it records beside it (``ohra
    grasp sample`` writes them; empty for other files); :class:`GraspError` naming the file when unusable."""
    path = Path(path)
    if path.is_dir():
        shards = sorted(str(p.relative_to(path)) for p in path.glob("*/*.npz"))[:3]
        hint = f" (e.g. {path / shards[0]})" if shards else ""
        raise GraspError(f"{path} is a folder: pass one grasp file, such as a dataset shard HAND/OBJECT-HASH.npz{hint}, "
                         "or export a dataset's grasps with GraspDataset(DIR).grasps()")
    if not path.is_file():
        raise GraspError(f"grasp file not found: {path}")
    try:
        data = np.load(path, allow_pickle=False)
    except Exception as exc:  # numpy raises several types for bad files
        # numpy reads any file that is not .npy/.npz as a pickle, which it refuses: say what the file is not
        why = "not a NumPy .npz/.npy file" if "pickled" in str(exc) else str(exc)
        raise GraspError(f"{path}: cannot read grasps: {why} (expected an (N, 31) array, e.g. a shard or "
                         "`ohra grasp sample` output)") from None
    if isinstance(data, np.ndarray):
        return data, {}
    with data:
        names = list(data.keys())
        if any(n.endswith(".rows") for n in names):  # ohra.data.pack's per-hand file: every object's grasps in a row
            raise GraspError(f"{path} is a packed dataset file (every object's grasps of a hand, one after another): "
                             "evaluate one (hand, object) pair, e.g. `ohra data pack --unpack DIR` to restore the "
                             "shards, or GraspDataset(DIR, objects=[...]).grasps()")
        if key is None:
            key = "grasps" if "grasps" in names else (names[0] if len(names) == 1 else None)
        if key is None or key not in names:
            raise GraspError(f"{path}: no array {key or 'grasps'!r} (arrays: {', '.join(names) or 'none'}); use --key")
        info = {k: str(data[k]) for k in ("hand", "form", "model", "object", "object_name", "object_hash", "scale", "body")
                if k in names and data[k].ndim == 0}
        return np.asarray(data[key]), info or _shard_info(path)


def _shard_info(path: Path) -> dict[str, str]:
    """What a dataset shard (``DIR/HAND/OBJECT-HASH.npz``) was made for, from ``DIR/manifest.json``: hand name
    and form, object name and mesh hash; empty for any other file."""
    import json

    manifest = path.parent.parent / "manifest.json"
    if not manifest.is_file():
        return {}
    try:
        man = json.loads(manifest.read_text())
        entry = man["hands"][path.parent.name]
        shard = next(sh for sh in entry["shards"].values() if Path(sh["file"]).name == path.name)
        obj = man["objects"][shard["object"]]
    except (ValueError, KeyError, TypeError, StopIteration, OSError):
        return {}  # not a shard this manifest lists: nothing to compare
    form = "extended" if "finger_radii" in entry.get("params", {}) else "base"
    out = {"hand": path.parent.name, "form": form, "object_name": str(obj["name"]), "object_hash": str(obj["mesh_hash"]),
           "body_hash": str(obj.get("body_hash", "")), "body_kind": str(obj.get("body", {}).get("kind", "")),
           "made": "synthesised"}
    # how the object's file was read (a centimetre mesh's --scale, a chosen --body): applied again when --object
    # names that file, as for a grasp file from ohra grasp sample
    if obj.get("source") and obj["source"] != "builtin":
        out["object"] = str(obj["source"])
        if obj.get("scale") is not None:
            out["scale"] = float(obj["scale"])
        if obj.get("body_choice"):
            out["body"] = str(obj["body_choice"])
    return out


def _same_object(recorded: str | None, given: str) -> bool:
    """Whether ``--object`` names the object a grasp file recorded: the same spec, or the same file or folder by
    another path (relative against absolute: the recorded scale was left out and a 9 m box simulated)."""
    if not recorded:
        return False
    if recorded == str(given):
        return True
    a, b = Path(str(recorded)).expanduser(), Path(str(given)).expanduser()
    return a.exists() and b.exists() and a.resolve() == b.resolve()


COUPLING_NOTE_RAD = 1e-3
"""[rad] ``ohra eval`` notes grasps whose coupled joints lie farther than this from their drivers' values."""


def run(args: argparse.Namespace) -> int:
    from ohra.hands import get_hand
    from ohra.objects.model import resolve_objects
    from ohra.sim import GraspEvaluator

    if args.workers < 1:
        raise GraspError(f"--workers must be >= 1, got {args.workers}")
    if args.limit is not None and args.limit < 1:
        raise GraspError(f"--limit must be >= 1, got {args.limit}")
    if args.original and args.inertials != "capsule":
        raise GraspError("--inertials original gives the canonical hand the original finger masses; --original "
                         "already simulates the original URDF with its own: give one of them")
    if args.meshcat and args.original:
        raise GraspError("--meshcat draws canonical hands only; drop --original")
    from ohra.io import check_output, check_suffix

    for out, suffix, flag in ((args.output, ".json", "-o"), (args.render, ".png", "--render"), (args.meshcat, ".html", "--meshcat")):
        if out:  # all checked before anything is simulated or written: a PNG written into r.txt, a report into sheet.png
            check_suffix(check_output(out), suffix, flag)
    grasps, made = load_grasp_file(args.grasps, args.key)  # made: what `ohra grasp sample` recorded, if anything
    if made.get("hand") and made["hand"] != str(args.hand):
        from ohra.hands.resolve import resolve_hand

        told = resolve_hand(args.hand, args.form)  # a file may hold the same hand under another reference
        if told.name != made["hand"]:
            made_for, given = made["hand"], f"--hand {args.hand}"
            if made.get("form") and told.form != made["form"]:  # another hand, and another form too
                made_for, given = f"the {made['form']} form of {made_for}", f"{given} ({told.form} form)"
            print(f"ohra: note: {args.grasps} was {made.get('made', 'sampled')} for {made_for}; evaluating it on {given}",
                  file=sys.stderr)
        elif made.get("form") and told.form != made["form"]:
            from ohra.hands import list_hands

            # the registered name when there is one (a params file may hold only the other form), else the hand as given
            # (a spec path: its name is unknown unless its folder is registered)
            again = made["hand"] if made["hand"] in list_hands() else args.hand
            print(f"ohra: note: {args.grasps} was {made.get('made', 'sampled')} for the {made['form']} form of {made['hand']}; --hand "
                  f"{args.hand} gives its {told.form} form, evaluated as given (--hand {again} --form "
                  f"{made['form']} evaluates the hand the grasps were made for)", file=sys.stderr)
    if made.get("hand") == str(args.hand) and made.get("form"):
        if args.form is None:
            args.form = made["form"]  # the canonical hand the grasps were sampled for
        elif args.form != made["form"]:
            print(f"ohra: note: {args.grasps} was {made.get('made', 'sampled')} for the {made['form']} form of {args.hand}; evaluating on the "
                  f"{args.form} form as --form asks", file=sys.stderr)
    if args.limit is not None:
        grasps = grasps[: args.limit]
    same_object = _same_object(made.get("object"), args.object)
    if args.scale is None and made.get("scale") and float(made["scale"]) != 1.0 and same_object:
        # the grasps were sampled on this file read at another scale (a millimetre mesh): read it the same way
        args.scale = float(made["scale"])
        print(f"ohra: note: --scale {args.scale:g} from {args.grasps} (the scale its grasps were {made.get('made', 'sampled')} at)", file=sys.stderr)
    if args.body is None:
        args.body = "auto"
        if made.get("body", "auto") != "auto" and same_object:
            args.body = made["body"]  # the body refined grasps were made against; the test runs on it too
            print(f"ohra: note: --body {args.body} from {args.grasps} (the body its grasps were {made.get('made', 'sampled')} on)", file=sys.stderr)
    objs = resolve_objects(args.object, scale=args.scale, body=args.body)
    if len(objs) != 1:
        raise ObjectError(f"--object must name one object, {args.object!r} names {len(objs)}")
    obj = objs[0]
    if made.get("object_hash") and made["object_hash"] != obj.mesh_hash:
        print(f"ohra: note: {args.grasps} holds grasps of {made.get('object_name', 'another object')} (mesh {made['object_hash']}); "
              f"evaluating them on --object {args.object} (mesh {obj.mesh_hash})", file=sys.stderr)
    elif made.get("body_hash") and made["body_hash"] != obj.body_hash:
        kind = made.get("body_kind") or "another body"
        print(f"ohra: note: {args.grasps} was synthesised on the body {kind} of this mesh; --body {args.body} gives "
              f"{obj.body.kind} (--body {kind.split(':', 1)[0]} evaluates on the body they were made on)", file=sys.stderr)
    protocol = protocol_of(args)
    if args.no_early_exit:
        protocol = replace(protocol, early_exit=False)
    protocol = replace(protocol, object_point=args.object_point)
    hand = eval_hand(args.hand, args.original, args.form, args.inertials)
    ev = GraspEvaluator(hand, obj, protocol)
    g, out_of_limits = ev.check(grasps)  # validates before any simulation or output
    if out_of_limits.any():
        print(f"ohra: warning: {int(out_of_limits.sum())} grasp(s) have joints outside the limits; clamped", file=sys.stderr)
    if hand.coupled and len(g):
        from ohra.canonical.couplings import residual

        off = np.abs(residual(hand.couplings, g[:, 9:])).max(axis=1)
        if np.any(off > COUPLING_NOTE_RAD):
            print(f"ohra: note: {int(np.sum(off > COUPLING_NOTE_RAD))} of {len(g)} grasp(s) hold coupled joints of {args.hand} "
                  f"off their drivers' values (up to {off.max():.3f} rad); the simulation sets them from their drivers "
                  "(ohra.canonical.couplings.project), as the hand moves", file=sys.stderr)
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # already reported above
        # with a report file, finished grasps are kept beside it until the report is written: a rerun of an
        # interrupted evaluation (same grasps and settings) simulates only the rest
        partial = partial_path(args.output) if args.output else None
        rep = ev.evaluate(g, mode=args.mode, workers=args.workers, progress=not args.quiet, backend=args.backend,
                          address=args.address, resume=partial)
    wall = time.perf_counter() - t0
    ev.close()
    from ohra.canonical.params import ExtendedParams

    form = "extended" if isinstance(get_hand(args.hand, args.form), ExtendedParams) else "base"  # the form simulated
    made_for = {k: v for k, v in made.items() if k in ("hand", "form", "object_name", "object_hash", "made")}
    rep.meta.update({"grasp_file": str(args.grasps), "hand": str(args.hand), "form": form, "original_hand": bool(args.original),
                     "inertials": args.inertials, "wall_s": wall, "object_info": obj.describe(),
                     **({"grasps_made_for": made_for} if made_for else {})})
    if args.output:
        from ohra.io import write_json

        write_json(args.output, rep.to_dict())
        partial.unlink(missing_ok=True)
        wrote(args.output)
        if rep.meta.get("resumed"):
            print(f"ohra: note: {rep.meta['resumed']} of {len(rep.results)} grasps came from the interrupted run's "
                  f"{partial}", file=sys.stderr)
    if args.render:
        from ohra.sim.render import contact_sheet, render_grasps, write_png

        k = min(16, len(g))
        write_png(contact_sheet(render_grasps(hand, obj, g[:k]), rep.success[:k]), args.render)
        wrote(f"a contact sheet of {k} grasp(s) to {args.render}")
    if args.meshcat and len(g):
        first = g[0].copy()
        if hand.coupled:  # drawn as simulated
            from ohra.canonical.couplings import project

            first[9:] = project(hand.couplings, first[9:])
        _meshcat(args, hand, obj, first)
        wrote(f"the first grasp's meshcat page to {args.meshcat}")
    n = len(rep.results)
    if n == 0:
        print(f"{args.hand} on {obj.name}: {args.grasps} holds no grasps; nothing was simulated")
        return 0
    simulated = n - int(rep.meta.get("resumed", 0))  # the rate of this run's own simulations
    which = " (original URDF)" if args.original else (" (original finger masses)" if args.inertials == "original" else "")
    print(f"{args.hand}{which} on {obj.name}: {int(rep.success.sum())}/{n} succeeded ({100 * rep.success_rate:.1f} %), "
          f"{rep.clamped_count} clamped, {wall:.1f} s ({simulated / wall if wall > 0 else 0:.1f} grasps/s"
          f"{f' over the {simulated} simulated now' if simulated < n else ''})")
    return 0


def protocol_of(args: argparse.Namespace):
    """The six-direction protocol ``--protocol`` and the preset flags ask for (``--protocol X`` is the flag of X)."""
    from ohra.sim import Protocol
    from ohra.sim.protocol import ISAAC_DRIVE, ISAAC_STEP

    strict, step, drive = (args.strict or args.protocol == "strict", args.isaac_step or args.protocol == "isaac-step",
                           args.isaac_drive or args.protocol == "isaac-drive")
    protocol = Protocol.strict() if strict else Protocol()
    if step:
        protocol = replace(protocol, **ISAAC_STEP)
    if drive:
        protocol = replace(protocol, position_gain=protocol.dt * ISAAC_DRIVE["stiffness"] / ISAAC_DRIVE["damping"], velocity_gain=1.0)
    return protocol


def _meshcat(args: argparse.Namespace, hand, obj, grasp: np.ndarray) -> None:
    if not hand.canonical:
        raise GraspError("--meshcat draws canonical hands only; drop --original")
    from ohra.hands import get_hand
    from ohra.canonical.kinematics import HandModel
    from ohra.viz import add_grasp, new_visualizer, save_html

    vis = new_visualizer()
    # the hand that was simulated: its form (--form), not the name's default one
    add_grasp(vis, HandModel.from_params(get_hand(args.hand, args.form)), grasp, np.asarray(obj.mesh.vertices),
              np.asarray(obj.mesh.faces))
    save_html(vis, args.meshcat)
