"""The ``ohra`` command: a thin layer over the library API.

Subcommands of other modules plug in through ``register(subparsers)`` (top level) and
``register_hand(hand_subparsers)`` (under ``ohra hand``); each parser sets ``func(args) -> int``.
Any :class:`ohra.OhraError` (and bad usage) becomes one line on stderr and exit code 2.
"""

from __future__ import annotations

import argparse
import importlib
import json
import sys
from typing import Sequence

import numpy as np

from ohra.errors import OhraError

PLUGINS = ("parse", "eval", "learn")
EXIT_USAGE = 2


class _Parser(argparse.ArgumentParser):
    """argparse that reports usage errors in one line."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message}\n")


def _cmd_hand_list(args: argparse.Namespace) -> int:
    from ohra.hands import get_hand, list_hands

    names = list_hands(include_variants=args.variants)
    for n in names:
        if args.variants and n.startswith("leap_"):
            print(n)
            continue
        forms = []
        for form in ("base", "extended"):
            try:
                get_hand(n, form)
                forms.append(form)
            except OhraError:
                pass
        print(f"{n:24s} {'/'.join(forms)}")
    if not args.variants:
        print("leap_0000 .. leap_3333     extended (LEAP flavour; --variants lists all 256)")
    return 0


def _resolve(name: str, extended: bool):
    from ohra.hands import get_hand
    from ohra.canonical.params import BaseParams

    params = get_hand(name, "extended" if extended else None)
    if extended and isinstance(params, BaseParams):
        params = params.to_extended()
    return params


def _cmd_hand_render(args: argparse.Namespace) -> int:
    from ohra.canonical.urdfgen import render, write

    params = _resolve(args.hand, args.extended)
    if args.output:
        path = write(params, args.output)
        print(f"wrote {path}", file=sys.stderr)
    else:
        sys.stdout.write(render(params))
    return 0


def _cmd_hand_info(args: argparse.Namespace) -> int:
    from ohra.canonical.kinematics import HandModel
    from ohra.canonical.params import FINGERS, JOINT_NAMES

    params = _resolve(args.hand, args.extended)
    hm = HandModel.from_params(params)
    tips = hm.fingertips(np.zeros(22) if not args.neutral else hm.neutral())
    info = {
        "hand": args.hand,
        "form": params.form if params.form == "base" else getattr(params, "template", "extended"),
        "handedness": params.handedness,
        "dof": int(params.dof),
        "present_fingers": [f for f, p in zip(FINGERS, params.present_fingers) if p],
        "movable_joints": [n for n, m in zip(JOINT_NAMES, params.movable_joints) if m],
        "limits": {n: [float(lo), float(up)] for n, lo, up, m in zip(JOINT_NAMES, hm.lower, hm.upper, params.present_joints) if m},
        "fingertips_q0_m": {f: [round(float(x), 6) for x in tips[i]] for i, f in enumerate(FINGERS) if params.present_fingers[i]},
    }
    if args.json:
        print(json.dumps(info, indent=2))
        return 0
    print(f"{info['hand']}  form={info['form']}  {info['handedness']} hand  dof={info['dof']}  fingers={','.join(info['present_fingers'])}")
    print("joint limits [rad]:")
    for n, (lo, up) in info["limits"].items():
        print(f"  {n:16s} [{lo:+.4f}, {up:+.4f}]")
    print(f"fingertips at q={'neutral' if args.neutral else '0'} [m, palm frame]:")
    for f, p in info["fingertips_q0_m"].items():
        print(f"  {f:7s} ({p[0]:+.4f}, {p[1]:+.4f}, {p[2]:+.4f})")
    return 0


def _cmd_hand_check(args: argparse.Namespace) -> int:
    from ohra.hands import list_hands, variant_names
    from ohra.hands.check import check_hands

    jobs: list[tuple[str, str | None]] = []
    for n in args.hands or list_hands():
        if n.startswith("leap_"):
            jobs.append((n, None))
            continue
        for form in ("base", "extended"):
            try:
                from ohra.hands import get_hand

                get_hand(n, form)
                jobs.append((n, form))
            except OhraError:
                pass
    if not args.hands:
        jobs += [(n, None) for n in variant_names()]
    results = check_hands(jobs)
    bad = [r for r in results if not r.ok]
    shown = results if args.all else [r for r in results if not r.name.startswith("leap_") or r.name in ("leap_3333", "leap_3303", "leap_0000")]
    print(f"{'hand':22s} {'form':9s} {'fingers':>7s} {'dof':>4s} {'pin nq':>6s} {'bullet j':>8s} {'ms':>7s}  status")
    for r in shown:
        print(f"{r.name:22s} {r.form:9s} {r.fingers:7d} {r.dof:4d} {r.pinocchio_nq:6d} {r.bullet_joints:8d} {1e3 * r.seconds:7.1f}  {'ok' if r.ok else 'FAIL ' + r.warnings[:60]}")
    if len(shown) < len(results):
        print(f"... and {len(results) - len(shown)} more LEAP variants (--all shows them)")
    total = sum(r.seconds for r in results)
    print(f"{len(results)} hands rendered and loaded in Pinocchio and PyBullet in {total:.2f} s; {len(bad)} failed")
    return 1 if bad else 0


def build_parser() -> argparse.ArgumentParser:
    from ohra import __version__

    parser = _Parser(prog="ohra", description="Canonical dexterous hands: render, inspect, parse, evaluate, synthesise, learn.")
    parser.add_argument("--version", action="version", version=f"ohra {__version__}")
    parser.add_argument("--hands", action="append", default=[], metavar="DIR", dest="hands_dirs",
                        help="user hand folder: its *.yaml specs join the registry (also $OHRA_HANDS_PATH)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    hand = sub.add_parser("hand", help="canonical hands: list, render, info, ...")
    hsub = hand.add_subparsers(dest="hand_command", metavar="ACTION", parser_class=_Parser)
    hsub.required = True

    p = hsub.add_parser("list", help="registered hands and LEAP variants")
    p.add_argument("--variants", action="store_true", help="list all 256 leap_XXXX variants")
    p.set_defaults(func=_cmd_hand_list)

    p = hsub.add_parser("render", help="write the canonical URDF of a hand")
    p.add_argument("hand", help="registered hand, leap_XXXX, or a params JSON file")
    p.add_argument("-o", "--output", help="output URDF path (default: stdout)")
    p.add_argument("--extended", action="store_true", help="use the extended form")
    p.set_defaults(func=_cmd_hand_render)

    p = hsub.add_parser("info", help="DoF, fingers, limits and fingertip positions")
    p.add_argument("hand", help="registered hand, leap_XXXX, or a params JSON file")
    p.add_argument("--extended", action="store_true", help="use the extended form")
    p.add_argument("--neutral", action="store_true", help="fingertips at 0 clamped into the limits")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=_cmd_hand_info)

    p = hsub.add_parser("check", help="render every hand and load it in Pinocchio and PyBullet")
    p.add_argument("hands", nargs="*", help="hands to check (default: all registered hands and LEAP variants)")
    p.add_argument("--all", action="store_true", help="print every LEAP variant too")
    p.set_defaults(func=_cmd_hand_check)

    for name in PLUGINS:
        mod = importlib.import_module(f"ohra.cli.{name}")
        if hasattr(mod, "register_hand"):
            mod.register_hand(hsub)
        if hasattr(mod, "register"):
            mod.register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        for folder in args.hands_dirs:
            from ohra.hands.registry import add_hands_path

            add_hands_path(folder)
        return int(args.func(args) or 0)
    except OhraError as exc:
        print(f"ohra: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except (FileNotFoundError, IsADirectoryError, NotADirectoryError, PermissionError) as exc:
        print(f"ohra: error: {exc.strerror or exc}: {exc.filename}", file=sys.stderr)
        return EXIT_USAGE
    except BrokenPipeError:
        sys.stderr.close()  # output was cut short by its reader (e.g. `| head`): not an error
        return 0
    except KeyboardInterrupt:
        print("ohra: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
