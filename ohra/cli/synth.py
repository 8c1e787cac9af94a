"""``ohra synth`` (also ``python -m ohra.synth``): synthesise a filtered grasp dataset for one or more hands.

    ohra synth --hand NAME|all-leap [--objects builtin|builtin:NAME|FILE|FOLDER ...] [--grasps-per-object K]
               [--workers K] [--seed S] [--out DIR] [--no-filter] [--resume] [--quiet]

Both spellings build their arguments with :func:`configure` and run through
:func:`ohra.cli.main.execute`, so they accept the same options and fail the same way (one line on
stderr, exit code 2).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Sequence

from ohra.cli.main import BODY_CHOICES, BODY_HELP, Parser, execute
from ohra.errors import OhraError

DESCRIPTION = "Synthesise force-closure grasps (CasADi/IPOPT) and filter them in PyBullet."
EPILOG = "Exit codes: 0 ok, 2 bad input. The dataset is a directory with manifest.json and one .npz shard per (hand, object)."


def configure(p: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Add the synth options to ``p`` and make :func:`run` its command; returns ``p``."""
    p.add_argument("--hand", required=True,
                   help="registered hand, leap_XXXX, a hand spec YAML, a params JSON, or all-leap. A spec YAML is parsed "
                        "(with the fit) in its BASE form (its only form if it has no base); for the extended form write "
                        "its params first (ohra hand parse SPEC.yaml --extended --fit -o HAND.json) and pass the JSON, "
                        "which is used in its own form. A dataset recipe's {spec: ...} entry defaults to extended instead")
    p.add_argument("--objects", nargs="+", default=["builtin"],
                   help="builtin | builtin:NAME | procedural:FAMILY:SEED | mesh/URDF file | folder (default: builtin)")
    p.add_argument("--scale", type=float, default=None, help="multiply the coordinates of object files (0.001 for millimetre meshes)")
    p.add_argument("--body", choices=BODY_CHOICES, default="auto", help=BODY_HELP)
    p.add_argument("--cap", type=int, default=None, help="stop a (hand, object) pair once this many grasps are kept")
    p.add_argument("--robust-trials", type=int, default=None,
                   help="perturbed re-tests a kept grasp must also pass (default 2; 0 = off); sizes: ohra.synth.robust")
    p.add_argument("--grasps-per-object", type=int, default=8, help="solver restarts per object (default 8)")
    p.add_argument("--workers", type=int, default=1, help="worker processes (default 1)")
    p.add_argument("--seed", type=int, default=0, help="seed of the solver starts (default 0)")
    p.add_argument("-o", "--output", "--out", dest="out", default="out/grasps", help="dataset directory (default out/grasps)")
    p.add_argument("--no-filter", action="store_true", help="skip the PyBullet filter")
    p.add_argument("--resume", action="store_true", help="skip shards that are complete (sha256 checked)")
    p.add_argument("--overwrite", action="store_true", help="replace a dataset in --out made with other settings (deletes its shards)")
    add_backend_options(p)
    p.set_defaults(func=run)
    return p


def add_backend_options(p: argparse.ArgumentParser) -> None:
    """The options that pick how a grasp build runs (``--backend``, ``--address``, ``--quiet``), shared
    by ``ohra synth`` and ``ohra data build``."""
    p.add_argument("--backend", choices=("process", "ray"), default="process", help="process pool (default) or Ray")
    p.add_argument("--address", default=None, help="Ray cluster address (with --backend ray; default: a local cluster)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def register(sub) -> None:
    """Add ``synth`` to the top-level subparsers ``sub``."""
    configure(sub.add_parser("synth", help="synthesise a filtered grasp dataset (CasADi/IPOPT + PyBullet)",
                             description=DESCRIPTION, epilog=EPILOG))


def build_parser(prog: str = "python -m ohra.synth") -> argparse.ArgumentParser:
    """The stand-alone parser of ``python -m ohra.synth`` (the same options as ``ohra synth``)."""
    return configure(Parser(prog=prog, description=DESCRIPTION, epilog=EPILOG))


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m ohra.synth``."""
    return execute(build_parser().parse_args(argv))


def _hands(spec: str):
    from ohra.hands import get_hand, resolve_hand, variant_names

    if spec == "all-leap":
        return [(n, get_hand(n)) for n in variant_names() if get_hand(n).num_fingers >= 2]
    ref = resolve_hand(spec)  # its couplings (if any) become equality rows of the NLP
    # a spec YAML goes by its hand name (the dataset's folder for the hand), a params JSON by its stem
    name = ref.name if ref.kind == "spec" else Path(spec).stem if spec.endswith(".json") else spec
    return [(name, ref.params, ref.couplings)]


def run(args: argparse.Namespace) -> int:
    """Check the arguments, synthesise, print one summary line per hand."""
    if args.workers < 1:
        raise OhraError(f"--workers must be >= 1, got {args.workers}")
    if args.grasps_per_object < 1:
        raise OhraError(f"--grasps-per-object must be >= 1, got {args.grasps_per_object}")
    if args.robust_trials is not None and args.robust_trials < 0:
        raise OhraError(f"--robust-trials must be >= 0 (0: no robustness trials), got {args.robust_trials}")
    if args.cap is not None and args.cap < 1:
        raise OhraError(f"--cap must be >= 1 (leave it out to try every start), got {args.cap}")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise OhraError(f"--out {out} exists and is not a directory")
    from dataclasses import replace

    from ohra.objects.resolve import resolve_objects
    from ohra.synth.pipeline import SynthSettings, synthesize

    hands = _hands(args.hand)
    objects = resolve_objects(args.objects, scale=args.scale, body=args.body)
    settings = SynthSettings(grasps_per_object=args.grasps_per_object, seed=args.seed, filter=not args.no_filter, cap=args.cap)
    if args.robust_trials is not None:
        settings = replace(settings, robustness=replace(settings.robustness, trials=args.robust_trials))
    man = synthesize(hands, objects, out, settings, workers=args.workers, resume=args.resume, progress=not args.quiet,
                     overwrite=args.overwrite, backend=args.backend, address=args.address)
    print_summary(man, out, filtered=not args.no_filter, only=[h[0] for h in hands])
    return 0


def print_summary(man: dict, out: Path, filtered: bool = True, only: list[str] | None = None) -> None:
    """One line per hand (candidates, converged, kept, pass rate) and one per pair where nothing converged;
    ``only``: the hands this run synthesised (the folder may hold others from earlier runs, named in one line)."""
    trials = int(man.get("settings", {}).get("robustness", {}).get("trials", 1))
    max_pen = man.get("settings", {}).get("max_penetration_m")
    others = [n for n in man["hands"] if only is not None and n not in only]
    for name, entry in man["hands"].items():
        if name in others:
            continue
        c = entry["counts"]
        if filtered:
            rate = c["grasps"] / max(c["solved"], 1)
            robust = (f"{c['grasps']} also passed the robustness trials" if trials > 0 else
                      "no robustness trials (--robust-trials 0)")
            deep = (f" ({c['prefiltered']} sunk more than {1e3 * max_pen:g} mm into the object, not simulated)"
                    if c.get("prefiltered") and max_pen is not None else "")
            print(f"{name}: {c['candidates']} solves, {c['solved']} converged{deep}, {c.get('sim_passed', c['grasps'])} passed the "
                  f"filter, {robust} (kept {rate:.0%} of converged) -> {out.resolve()}")
        else:
            print(f"{name}: {c['candidates']} solves, {c['solved']} converged, {c['grasps']} kept without the filter "
                  f"(not simulated) -> {out.resolve()}")
        for key, sh in entry["shards"].items():
            if sh.get("diagnosis"):
                print(f"  {key}: {sh['diagnosis']}")
    if others:
        print(f"{out.resolve()} also holds {', '.join(others)} from earlier runs (ohra data info {out} sums the folder)")
