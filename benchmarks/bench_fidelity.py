"""Canonical vs original fidelity of every registered hand, base and extended.

Writes ``results/fidelity.json`` and ``results/fidelity.md``: per hand and form, the mean / p95 /
max fingertip error against the *true* fingertip (end of the finger's geometry over every link it
moves, mimic-driven links included), the mean joint-position error (distance to the original joint
axis) and the symmetric mean surface distance, in millimetres, over 200 seeded configurations of the
actuated joints inside the hand, couplings propagated (surface: 3). Hands with coupled joints list
their couplings; what the canonical form cannot express is named in the last column. Targets: mean
fingertip error <= 2 mm (extended) and <= 8 mm (base).

    python benchmarks/bench_fidelity.py [hand ...]
"""

from __future__ import annotations

import re
import time
import warnings

from _common import run_script, script_parser, write_results

from ohra.original.fidelity import compare
from ohra.hands import registry

TARGET = {"base": 8.0, "extended": 2.0}
SAMPLES = 200


def _short(approximations: list[str]) -> str:
    """The approximations in a table cell: the joints named, e.g. "joint_0.0 (no slot)"."""
    out = []
    for a in approximations:
        mimic = re.findall(r"'([^']+)' \(mimic of", a)
        loose = re.findall(r"'([^']+)' \(unmapped\)", a) + re.findall(r"^joint '([^']+)' \(\[", a)
        out += [f"{n} (mimic, no slot)" for n in mimic] + [f"{n} (no slot)" for n in loose]
        if not mimic and not loose:
            out.append(a.split(":")[0])
    return "; ".join(out)


def main(names: list[str]) -> None:
    rows, data = [], []
    for n in names or registry.registered_hands():
        for form in registry.registered_forms(n):
            t = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                rep = compare(n, form, samples=SAMPLES, surface_configs=3, surface_points=1500)
            d = rep.to_dict()
            d["seconds"] = round(time.perf_counter() - t, 2)
            data.append(d)
            tip, jnt, srf = rep.tips["hand"], rep.joints["hand"], rep.surface.get("hand")
            ok = "yes" if tip.mean <= TARGET[form] else "**no**"
            rows.append(
                f"| {n} | {form} | {tip.mean:.2f} | {tip.p95:.2f} | {tip.max:.2f} | {jnt.mean:.2f} | "
                f"{srf.mean:.2f} | {ok} | {len(rep.couplings) or ''} | {_short(rep.approximations)} |"
                + (f" {rep.tips_held.mean:.2f} |" if rep.tips_held is not None else " |")
            )
            print(rows[-1], flush=True)
    table = "\n".join([
        f"Canonical vs original fidelity ({SAMPLES} seeded configurations per hand; mm). Target: mean fingertip "
        "error <= 2 mm extended, <= 8 mm base.",
        "",
        "| hand | form | tip mean | tip p95 | tip max | joint mean | surface mean | target met | couplings | approximation "
        "(what the canonical form cannot follow) | tip mean, unmapped joints held |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
        *rows,
    ])
    write_results("fidelity", {"samples": SAMPLES, "targets_mm": TARGET, "hands": data}, table)


if __name__ == "__main__":
    ap = script_parser(__doc__, __file__)
    ap.add_argument("hands", nargs="*", help="registered hands to measure (default: all)")
    args = ap.parse_args()
    unknown = [h for h in args.hands if h not in registry.registered_hands()]
    if unknown:
        ap.error(f"unknown hand(s) {', '.join(unknown)}; registered: {', '.join(registry.registered_hands())}")
    run_script(lambda: main(args.hands), __file__)
