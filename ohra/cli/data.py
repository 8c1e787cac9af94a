"""``ohra data build RECIPE.yaml``, ``ohra data pack DIR`` and ``ohra data info DIR``: grasp datasets from recipes.

Plugged into :mod:`ohra.cli.main` through ``register(subparsers)``; ``python -m ohra.data`` runs
the same commands on their own. Bad input is one line on stderr and exit code 2.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any, Sequence

from ohra.errors import OhraError


def register(sub: Any) -> None:
    from ohra.cli.synth import add_backend_options

    data = sub.add_parser("data", help="grasp datasets: build from a recipe, pack, summarise")
    dsub = data.add_subparsers(dest="data_command", metavar="ACTION", parser_class=type(data))
    dsub.required = True

    p = dsub.add_parser("build", help="synthesise the dataset a recipe describes (resumable)")
    p.add_argument("recipe", help="recipe YAML (hands, objects, grasps per pair, cap, split, seed, protocol)")
    p.add_argument("-o", "--output", "--out", dest="out", default=None, help="dataset directory (default out/<recipe name>, out/<name>_s<seed> with --seed)")
    p.add_argument("--seed", type=int, default=None,
                   help="replace the recipe's seed: more data from the same recipe, into another directory")
    p.add_argument("--workers", type=int, default=1, help="processes, or local Ray CPUs (default 1)")
    p.add_argument("--resume", action="store_true", help="keep pairs whose shards are complete (sha256 checked)")
    p.add_argument("--overwrite", action="store_true", help="replace a dataset made with other settings (deletes its shards)")
    p.add_argument("--hands", nargs="+", default=None, metavar="NAME",
                   help="build only these of the recipe's hands (top up one hand; resume completes the rest later)")
    add_backend_options(p)
    p.set_defaults(func=_build)

    p = dsub.add_parser("pack", help="pack finished dataset directories: one .npz per hand (lossless, checked)")
    p.add_argument("dir", nargs="+", help="dataset directories (each holds manifest.json)")
    p.add_argument("--unpack", action="store_true", help="write every packed pair back to its own shard file")
    p.set_defaults(func=_pack)

    p = dsub.add_parser("info", help="summary table of dataset directories")
    p.add_argument("dir", nargs="+", help="dataset directories (each holds manifest.json); with several, a table "
                   "per directory and their per-hand totals")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=_info)


def _build(args: argparse.Namespace) -> int:
    from ohra.cli.synth import print_summary
    from ohra.data.build import build
    from ohra.data.recipe import Recipe

    if args.seed is not None and args.seed < 0:  # before the recipe: the command line's mistake, not the file's
        raise OhraError(f"--seed must be an integer >= 0, got {args.seed}")
    recipe = Recipe.load(args.recipe)
    if args.seed is not None:
        recipe = recipe.with_seed(args.seed)
    out = args.out or (f"out/{recipe.name}" if args.seed is None else f"out/{recipe.name}_s{recipe.seed}")
    man = build(recipe, out, workers=args.workers, resume=args.resume, overwrite=args.overwrite, backend=args.backend,
                address=args.address, progress=not args.quiet, hands=args.hands)
    print_summary(man, Path(out), filtered=recipe.filter)
    split = man.get("split", {})
    print(f"objects: {len(split.get('train', []))} train / {len(split.get('test', []))} test; {man['core_hours']:.3f} core-hours")
    return 0


def _pack(args: argparse.Namespace) -> int:
    from ohra.data.pack import pack, unpack

    for d in args.dir:
        if args.unpack:
            print(f"{d}: {unpack(d)} shards written back")
        else:
            print(pack(d).line())
    return 0


def _info(args: argparse.Namespace) -> int:
    from ohra.data.build import combined_summary, format_summary, summary
    from ohra.data.dataset import unique_dirs

    dirs = [str(d) for d in unique_dirs(args.dir)]
    if len(dirs) < len(args.dir):
        print(f"ohra: note: {len(args.dir) - len(dirs)} folder(s) given twice, counted once", file=sys.stderr)
    args.dir = dirs
    if args.json:
        print(json.dumps(combined_summary(args.dir), indent=1))
        return 0
    parts = [format_summary(summary(d)) for d in args.dir]
    if len(args.dir) > 1:
        parts.append(format_summary(combined_summary(args.dir)))
    print("\n\n".join(parts))
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m ohra.data``: the ``ohra data`` commands on their own."""
    from ohra.cli.main import Parser, execute

    parser = Parser(prog="ohra")  # the same commands as `ohra data ...`; usage lines name them so
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser)
    register(sub)
    args = parser.parse_args(["data", *(sys.argv[1:] if argv is None else argv)])
    return execute(args)
