"""``ohra hand ...``: list, render, info, check, parse, compare and show canonical hands.

    ohra hand list [--variants]
    ohra hand render HAND [-o URDF] [--extended]
    ohra hand info HAND [--extended] [--neutral] [--json]
    ohra hand check [HAND ...] [--all]
    ohra hand parse SPEC.yaml [-o PARAMS.json] [--extended] [--fit] [--no-fidelity] [--surface]
    ohra hand compare HAND [--extended] [--samples N] [--no-surface] [--json] [--html OUT.html]
    ohra hand show HAND [--extended] [--original] [--q Q] [--no-wait]
    ohra hand mirror HAND [-o PARAMS.json] [--extended]

``HAND`` is a registered hand, a LEAP variant ``leap_XXXX``, a hand spec YAML (parsed with the fit)
or a params JSON file (see :func:`ohra.hands.resolve_hand`); ``compare`` and ``show --original`` need
the original hand, so not a LEAP variant, and a params JSON only with its spec beside it (same stem).
Plugged into :mod:`ohra.cli.main` through :func:`register`.
"""

from __future__ import annotations

import argparse
import json
import sys
import warnings

import numpy as np

from ohra.cli.main import wrote

HAND_HELP = "registered hand, leap_XXXX, hand spec YAML (parsed with the fit), or params JSON file"
# what compare needs: a hand whose original is known
ORIGINAL_HAND_HELP = ("registered hand, hand spec YAML (parsed with the fit), or params JSON file with its spec "
                      "YAML beside it (same stem)")


def register(sub) -> None:
    """Add ``hand`` and its actions to the top-level subparsers ``sub``."""
    hand = sub.add_parser("hand", help="canonical hands: list, render, info, check, parse, compare, show, mirror",
                          description="List, render, inspect, check, parse, compare, show and mirror canonical hands.")
    hsub = hand.add_subparsers(dest="hand_command", metavar="ACTION", parser_class=type(hand))
    hsub.required = True

    p = hsub.add_parser("list", help="registered hands and LEAP variants")
    p.add_argument("--variants", action="store_true", help="list all 256 leap_XXXX variants")
    p.set_defaults(func=_cmd_list)

    p = hsub.add_parser("render", help="write the canonical URDF of a hand")
    p.add_argument("hand", help=HAND_HELP)
    p.add_argument("-o", "--output", "--out", dest="output", help="output URDF path (default: stdout)")
    _form_option(p)
    p.set_defaults(func=_cmd_render)

    p = hsub.add_parser("info", help="DoF, fingers, limits and fingertip positions")
    p.add_argument("hand", help=HAND_HELP)
    _form_option(p)
    p.add_argument("--neutral", action="store_true", help="fingertips at 0 clamped into the limits")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=_cmd_info)

    p = hsub.add_parser("check", help="render every hand and load it in Pinocchio and PyBullet")
    p.add_argument("hands", nargs="*", help="hands to check, each a " + HAND_HELP
                   + " (default: all registered hands and LEAP variants)")
    p.add_argument("--all", action="store_true", help="print every LEAP variant too")
    p.set_defaults(func=_cmd_check)

    p = hsub.add_parser("parse", help="parse an original hand URDF from a hand spec (YAML) into canonical params")
    p.add_argument("spec", help="hand spec YAML (see ohra.original.spec)")
    p.add_argument("-o", "--output", "--out", dest="output", help="write params JSON here (default: stdout)")
    _form_option(p, "base")
    p.add_argument("--fit", action="store_true", help="refine by least squares against the original kinematics")
    p.add_argument("--no-fidelity", action="store_true", help="skip the fidelity table")
    p.add_argument("--surface", action="store_true",
                   help="add the surface distance to the fidelity table (seconds on detailed meshes)")
    p.set_defaults(func=_cmd_parse)

    p = hsub.add_parser("compare", help="canonical vs original fidelity of a hand (registered, spec YAML or params JSON)")
    p.add_argument("hand", help=ORIGINAL_HAND_HELP)
    _form_option(p)
    p.add_argument("--samples", type=int, default=200, help="random configurations (default 200)")
    p.add_argument("--no-surface", action="store_true", help="skip the surface distance (faster)")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.add_argument("--html", help="also write a static HTML overlay (original meshes + canonical capsules)")
    p.set_defaults(func=_cmd_compare)

    p = hsub.add_parser("show", help="meshcat viewer of a hand (canonical, optionally over the original)")
    p.add_argument("hand", help=HAND_HELP)
    _form_option(p)
    p.add_argument("--original", action="store_true",
                   help="overlay the original meshes (a registered hand, spec YAML, or params JSON with its spec beside it)")
    p.add_argument("--q", help="22 canonical joint values (comma or space separated)")
    p.add_argument("--no-wait", action="store_true", help="draw and exit: the viewer stops with the command (with -o, the "
                   "page stays)")
    p.add_argument("-o", "--output", "--out", dest="output", help="also save the view as a static, framed HTML page (opens without a server)")
    p.set_defaults(func=_cmd_show)

    p = hsub.add_parser("mirror", help="the hand's mirror image (left <-> right) as params JSON")
    p.add_argument("hand", help=HAND_HELP)
    p.add_argument("-o", "--output", "--out", dest="output", help="write params JSON here (default: stdout)")
    _form_option(p, "the hand's own form")
    p.set_defaults(func=_cmd_mirror)


def _form_option(p: argparse.ArgumentParser, default: str = "the hand's own form: base for a registered hand "
                 "that has one, extended for a LEAP variant or an extended params JSON") -> None:
    """``--form base|extended`` (``args.form``; None when not given) and its shorthand ``--extended``."""
    g = p.add_mutually_exclusive_group()
    g.add_argument("--form", choices=("base", "extended"), default=None, help=f"canonical form (default: {default})")
    g.add_argument("--extended", action="store_const", const="extended", dest="form", help="the same as --form extended")


def _form(args: argparse.Namespace) -> str:
    return args.form or "base"


def _params(ref, form: str | None):
    """The params of the resolved hand ``ref`` in ``form`` (``--form``; None: its own): a base hand asked for in its
    extended form is converted."""
    from ohra.canonical.params import BaseParams

    return ref.params.to_extended() if form == "extended" and isinstance(ref.params, BaseParams) else ref.params


def _jobs(names: list[str]) -> list[tuple[str, str | None]]:
    """(hand, form) pairs to check: each form of a registered hand or a spec YAML, else the hand as named.

    An unknown name raises :class:`ohra.HandNotFoundError` here, before anything runs.
    """
    from ohra.hands import get_hand, registry
    from ohra.hands.leap.variants import is_variant

    registered = set(registry.registered_hands())
    jobs: list[tuple[str, str | None]] = []
    for n in names:
        if n in registered:
            jobs += [(n, f) for f in registry.registered_forms(n)]
        elif n.lower().endswith((".yaml", ".yml")):  # a spec: each form it declares, as for a registered hand
            from ohra.original.spec import load_spec

            jobs += [(n, f) for f in load_spec(n).forms]
        else:
            if not is_variant(n):
                get_hand(n)  # a params file: fails here on an unknown name, naming it
            jobs.append((n, None))
    return jobs


# -- commands ---------------------------------------------------------------------------------------
def _cmd_list(args: argparse.Namespace) -> int:
    from ohra.hands import registry, variant_names

    for n in registry.registered_hands():
        print(f"{n:24s} {'/'.join(registry.registered_forms(n))}")
    if args.variants:
        print("\n".join(variant_names()))
    else:
        print("leap_0000 .. leap_3333     extended (LEAP flavour; --variants lists all 256)")
    return 0


def _cmd_render(args: argparse.Namespace) -> int:
    from ohra.canonical.urdfgen import render, write
    from ohra.hands.resolve import resolve_hand

    if args.output:  # a URDF written to plot.png was accepted
        from ohra.io import check_output, check_suffix

        check_suffix(check_output(args.output), ".urdf", "-o")
    ref = resolve_hand(args.hand, args.form)  # the hand's name becomes the robot's
    params = _params(ref, args.form)
    if args.output:
        path = write(params, args.output, robot_name=ref.name)
        wrote(path)
    else:
        sys.stdout.write(render(params, robot_name=ref.name))
    return 0


def _cmd_mirror(args: argparse.Namespace) -> int:
    from ohra.canonical.couplings import params_json
    from ohra.canonical.mirror import mirror_couplings, mirror_params
    from ohra.canonical.params import JOINT_NAMES
    from ohra.hands.resolve import resolve_hand

    ref = resolve_hand(args.hand, args.form)
    params = _params(ref, args.form)
    if args.output:
        from ohra.io import check_output, check_suffix

        check_suffix(check_output(args.output), ".json", "-o")
    image = mirror_params(params)
    text = params_json(image.params, mirror_couplings(ref.couplings, image.signs))
    if args.output:
        from ohra.io import write_text

        write_text(args.output, text)
    else:
        sys.stdout.write(text)
    reversed_ = [JOINT_NAMES[i] for i in np.flatnonzero((image.signs < 0) & np.asarray(params.movable_joints))]
    if args.output:
        wrote(args.output)
    print(f"the mirror image of {ref.name} "
          f"({params.handedness} -> {image.params.handedness} hand); joints turning the other way "
          f"(angle -q, limits [-upper, -lower]): {', '.join(reversed_) or 'none'}", file=sys.stderr)
    return 0


def _cmd_info(args: argparse.Namespace) -> int:
    from ohra.canonical.couplings import describe
    from ohra.canonical.kinematics import HandModel
    from ohra.canonical.params import FINGERS, JOINT_NAMES
    from ohra.hands.resolve import resolve_hand

    ref = resolve_hand(args.hand, args.form)  # a spec YAML: its name and couplings
    params = _params(ref, args.form)
    hm = HandModel.from_params(params)
    tips = hm.fingertips(np.zeros(22) if not args.neutral else hm.neutral())
    info = {
        "hand": ref.name,
        "form": params.form if params.form == "base" else getattr(params, "template", "extended"),
        "handedness": params.handedness,
        "dof": int(params.dof),
        "present_fingers": [f for f, p in zip(FINGERS, params.present_fingers) if p],
        "movable_joints": [n for n, m in zip(JOINT_NAMES, params.movable_joints) if m],
        "limits": {n: [float(lo), float(up)] for n, lo, up, m in zip(JOINT_NAMES, hm.lower, hm.upper, params.present_joints) if m},
        "fingertips_q0_m": {f: [round(float(x), 6) for x in tips[i]] for i, f in enumerate(FINGERS) if params.present_fingers[i]},
        "couplings": describe(ref.couplings),  # "slot = a * driver + b" lines
    }
    if args.json:
        print(json.dumps(info, indent=2))
        return 0
    print(f"{info['hand']}  form={info['form']}  {info['handedness']} hand  dof={info['dof']}  fingers={','.join(info['present_fingers'])}")
    if ref.kind in ("spec", "params"):
        print(f"from {args.hand}")
    print("joint limits [rad]:")
    for n, (lo, up) in info["limits"].items():
        print(f"  {n:16s} [{lo:+.4f}, {up:+.4f}]")
    print(f"fingertips at q={'neutral' if args.neutral else '0'} [m, palm frame]:")
    for f, p in info["fingertips_q0_m"].items():
        print(f"  {f:7s} ({p[0]:+.4f}, {p[1]:+.4f}, {p[2]:+.4f})")
    if info["couplings"]:
        print("couplings (slot = a * driver + b):")
        for line in info["couplings"]:
            print(f"  {line}")
    return 0


def _cmd_check(args: argparse.Namespace) -> int:
    from ohra.hands import list_hands, variant_names
    from ohra.hands.check import check_hands
    from ohra.hands.leap.variants import is_variant

    jobs = _jobs(args.hands or list_hands() + variant_names())
    results = check_hands(jobs)
    bad = [r for r in results if not r.ok]
    few = ("leap_3333", "leap_3303", "leap_0000")  # without --all, three LEAP variants stand for the 256
    shown = results if args.all else [r for r in results if not is_variant(r.name) or r.name in few]
    print(f"{'hand':22s} {'form':9s} {'fingers':>7s} {'dof':>4s} {'pin nq':>6s} {'bullet j':>8s} {'ms':>7s}  status")
    for r in shown:
        print(f"{r.name:22s} {r.form:9s} {r.fingers:7d} {r.dof:4d} {r.pinocchio_nq:6d} {r.bullet_joints:8d} "
              f"{1e3 * r.seconds:7.1f}  {'ok' if r.ok else 'FAIL ' + r.warnings[:60]}")
    if len(shown) < len(results):
        print(f"... and {len(results) - len(shown)} more LEAP variants (--all shows them)")
    total = sum(r.seconds for r in results)
    hands = len({r.name for r in results})
    forms = f" ({len(results)} hand forms)" if len(results) != hands else ""
    print(f"{hands} hand{'' if hands == 1 else 's'}{forms} rendered and loaded in Pinocchio and PyBullet in {total:.2f} s; {len(bad)} failed")
    return 1 if bad else 0


def _cmd_parse(args: argparse.Namespace) -> int:
    from ohra.io import check_output, check_suffix
    from ohra.original.fidelity import compare
    from ohra.original.parse import parse
    from ohra.original.spec import load_spec

    if args.output:
        check_suffix(check_output(args.output), ".json", "-o")  # before the parse and the fit (seconds), not after
    spec = load_spec(args.spec)
    if args.form is None and "base" not in spec.forms and "extended" in spec.forms:
        args.form = "extended"  # the spec's only form, as info and render take it (it was "has no 'base' form")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = parse(spec, _form(args), fit_params=args.fit)
    # each line once: a parse warning that is also a note is printed as the note; the coupling and
    # approximation notes are the fidelity table's last lines, so with the table they are left to it
    approx = "approximation: "
    bodies = {n[len(approx):] if n.startswith(approx) else n for n in res.notes}
    for w in caught:
        if str(w.message) not in bodies:
            print(f"warning: {w.message}", file=sys.stderr)
    from ohra.canonical.couplings import params_json
    from ohra.io import write_text

    text = params_json(res.params, res.couplings)  # + the optional "couplings" key of a coupled hand
    if args.output:
        write_text(args.output, text)
        wrote(args.output)
    else:
        sys.stdout.write(text)
    if res.fit is not None:
        from ohra.hands.resolve import POOR_FIT_MM

        print(f"fit: keypoint rms {res.fit.initial_rms_mm:.2f} -> {res.fit.final_rms_mm:.2f} mm "
              f"({res.fit.samples} configurations, {res.fit.iterations} evaluations)", file=sys.stderr)
        if res.fit.final_rms_mm > POOR_FIT_MM:
            print(f"warning: this {_form(args)} form follows the original URDF poorly (keypoint RMS above {POOR_FIT_MM:.0f} mm; "
                  "registered hands: at most 17 mm): grasps or policies made on it may not carry over to the original"
                  + ("; try --form extended" if args.form is None and "extended" in spec.forms else ""), file=sys.stderr)
    print("measured: palm radius, finger radii, lengths, joint positions/axes, limits from the URDF", file=sys.stderr)
    rep = None if args.no_fidelity else compare(res, _form(args), samples=100, surface=args.surface)
    in_table = set() if rep is None else {f"coupling: {c}" for c in rep.couplings} | {approx + a for a in rep.approximations}
    for n in res.notes:
        if n not in in_table:
            print(n, file=sys.stderr)
    if rep is not None:
        hint = "--surface adds it (seconds on detailed meshes)"
        print(rep.table(surface_hint=hint), file=sys.stderr)
    return 0


def _cmd_compare(args: argparse.Namespace) -> int:
    from ohra.errors import OhraError
    from ohra.hands.resolve import keep_mesh_warnings, resolve_hand
    from ohra.io import check_output, check_suffix
    from ohra.original.fidelity import compare

    if args.samples < 1:
        raise OhraError(f"--samples must be >= 1 (random configurations compared), got {args.samples}")
    if args.html:
        check_suffix(check_output(args.html), ".html", "--html")  # before the comparison (seconds), not after
    with warnings.catch_warnings():
        # the parse's notes are not this command's output; a missing mesh is: the fidelity numbers (and the
        # surface column) are measured on the geometry that is there
        warnings.simplefilter("ignore")
        keep_mesh_warnings()
        ref = resolve_hand(args.hand, args.form)
        rep = compare(ref, ref.form, samples=args.samples, surface=not args.no_surface)
    print(json.dumps(rep.to_dict(), indent=2) if args.json else rep.table(surface_hint="--no-surface skipped it"))
    if args.html:
        from ohra import viz

        path = viz.compare_html(ref, ref.form, args.html)
        wrote(path)
    return 0


def limits_note(params, q: np.ndarray) -> str:
    """'' or a sentence naming the joints of ``q`` (22,) outside the hand's limits, and nonzero absent joints:
    the viewer draws them as given (a pose the hand cannot take), as a note for stderr."""
    from ohra.canonical.params import JOINT_NAMES

    lo, up = np.asarray(params.joint_lowers, float), np.asarray(params.joint_uppers, float)
    present = np.asarray(params.present_joints)
    out = [i for i in range(22) if present[i] and not lo[i] - 1e-9 <= q[i] <= up[i] + 1e-9]
    absent = [i for i in range(22) if not present[i] and q[i] != 0.0]
    parts = []
    if out:
        parts.append(f"{len(out)} joint(s) outside the hand's limits, drawn as given: " + ", ".join(
            f"{JOINT_NAMES[i]} {q[i]:g} (limits {lo[i]:.3g} to {up[i]:.3g})" for i in out[:4]) + (" ..." if len(out) > 4 else ""))
    if absent:
        parts.append(f"the hand has no {', '.join(JOINT_NAMES[i] for i in absent[:4])}{' ...' if len(absent) > 4 else ''}"
                     " (its joints with both limits 0), drawn as given")
    return "; ".join(parts)


def _cmd_show(args: argparse.Namespace) -> int:  # pragma: no cover - starts a server
    from ohra import viz
    from ohra.errors import OhraError

    q = None
    if args.q:
        try:
            q = np.array([float(x) for x in args.q.replace(",", " ").split()])
        except ValueError:
            raise OhraError(f"--q: expected 22 numbers separated by commas or spaces, got {args.q!r}") from None
        if not np.isfinite(q).all():  # before the limits note, which would list a NaN as outside its limits
            raise OhraError(f"--q: expected finite numbers, got {', '.join(f'{v:g}' for v in q[~np.isfinite(q)][:4])} at "
                            f"index {', '.join(str(i) for i in np.flatnonzero(~np.isfinite(q))[:4])}")
    from ohra.hands.resolve import resolve_hand

    ref = resolve_hand(args.hand, args.form)  # a bad name fails here, before a meshcat server starts
    if q is not None and q.shape == (22,):
        note = limits_note(ref.params, q)
        if note:
            print(f"ohra: note: --q: {note}", file=sys.stderr)
    if args.output:
        from ohra.io import check_output, check_suffix

        check_suffix(check_output(args.output), ".html", "-o")
    vis = viz.new_visualizer()
    viz.show_hand(vis, ref, ref.form, q=q, original=args.original)
    if args.output:
        viz.save_html(vis, args.output)
        wrote(args.output)
    if args.no_wait:
        if not args.output:  # the server lives as long as this process: its URL would be dead once printed
            print("ohra: note: --no-wait stops the viewer with the command; -o PAGE.html saves a page that stays",
                  file=sys.stderr)
        return 0
    print(vis.url())
    if not sys.stdin.isatty():  # piped, CI, nohup: input() had no line to read (an EOFError traceback)
        print("ohra: note: stdin is not a terminal: the viewer stops now (keep it open from a terminal, or save a page "
              "with -o PAGE.html)", file=sys.stderr)
        return 0
    try:
        input("press Enter to stop the viewer ")
    except EOFError:
        pass
    return 0
