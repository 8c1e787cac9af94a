"""``ohra hand parse | compare | show``: parse a user's hand, measure fidelity, view original vs canonical.

Plugs into :mod:`ohra.cli.main` through :func:`register_hand` (sub-commands of ``ohra hand``).
"""

from __future__ import annotations

import argparse
import json
import sys
import warnings

import numpy as np


def _cmd_parse(args: argparse.Namespace) -> int:
    from ohra.canonical.couplings import params_json
    from ohra.original.fidelity import compare
    from ohra.original.spec import load_spec
    from ohra.original.parse import parse

    spec = load_spec(args.spec)
    form = "extended" if args.extended else "base"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = parse(spec, form, fit_params=args.fit)
    for w in caught:
        print(f"warning: {w.message}", file=sys.stderr)
    text = params_json(res.params, res.couplings)  # + the optional "couplings" key of a coupled hand
    if args.output:
        from pathlib import Path

        Path(args.output).write_text(text)
        print(f"wrote {args.output}", file=sys.stderr)
    else:
        sys.stdout.write(text)
    if res.fit is not None:
        print(f"fit: keypoint rms {res.fit.initial_rms_mm:.2f} -> {res.fit.final_rms_mm:.2f} mm "
              f"({res.fit.samples} configurations, {res.fit.iterations} evaluations)", file=sys.stderr)
    print("measured: palm radius, finger radii, lengths, joint positions/axes, limits from the URDF", file=sys.stderr)
    for n in res.notes:
        print(n, file=sys.stderr)
    if not args.no_fidelity:
        rep = compare(res, form, samples=100, surface=False)
        print(rep.table(), file=sys.stderr)
    return 0


def _cmd_compare(args: argparse.Namespace) -> int:
    from ohra.original.fidelity import compare

    form = "extended" if args.extended else "base"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rep = compare(args.hand, form, samples=args.samples, surface=not args.no_surface)
    if args.json:
        print(json.dumps(rep.to_dict(), indent=2))
    else:
        print(rep.table())
    if args.html:
        from ohra import viz

        path = viz.compare_html(args.hand, form, args.html)
        print(f"wrote {path}", file=sys.stderr)
    return 0


def _cmd_show(args: argparse.Namespace) -> int:  # pragma: no cover - starts a server
    from ohra import viz

    form = "extended" if args.extended else "base"
    q = None
    if args.q:
        q = np.array([float(x) for x in args.q.replace(",", " ").split()])
    from ohra.hands.resolve import resolve_hand

    ref = resolve_hand(args.hand, form)  # a bad name fails here, before a meshcat server starts
    vis = viz.new_visualizer()
    viz.show_hand(vis, ref, form, q=q, original=args.original)
    print(vis.url())
    if not args.no_wait:
        input("press Enter to stop the viewer ")
    return 0


def register_hand(hsub) -> None:
    p = hsub.add_parser("parse", help="parse an original hand URDF from a hand spec (YAML) into canonical params")
    p.add_argument("spec", help="hand spec YAML (see ohra.original.spec)")
    p.add_argument("-o", "--output", help="write params JSON here (default: stdout)")
    p.add_argument("--extended", action="store_true", help="extended form (default: base)")
    p.add_argument("--fit", action="store_true", help="refine by least squares against the original kinematics")
    p.add_argument("--no-fidelity", action="store_true", help="skip the fidelity table")
    p.set_defaults(func=_cmd_parse)

    p = hsub.add_parser("compare", help="canonical vs original fidelity of a registered hand")
    p.add_argument("hand")
    p.add_argument("--extended", action="store_true")
    p.add_argument("--samples", type=int, default=200)
    p.add_argument("--no-surface", action="store_true", help="skip the surface distance (faster)")
    p.add_argument("--json", action="store_true")
    p.add_argument("--html", help="also write a static HTML overlay (original meshes + canonical capsules)")
    p.set_defaults(func=_cmd_compare)

    p = hsub.add_parser("show", help="meshcat viewer of a hand (canonical, optionally over the original)")
    p.add_argument("hand")
    p.add_argument("--extended", action="store_true")
    p.add_argument("--original", action="store_true", help="overlay the original meshes")
    p.add_argument("--q", help="22 canonical joint values (comma or space separated)")
    p.add_argument("--no-wait", action="store_true", help="print the URL and exit")
    p.set_defaults(func=_cmd_show)
