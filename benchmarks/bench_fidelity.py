"""Canonical vs original fidelity of every registered hand, base and extended.

Writes ``results/fidelity.json`` and ``results/fidelity.md``: per hand and form, the mean / p95 /
max fingertip error, the mean joint-position error (distance to the original joint axis) and the
symmetric mean surface distance, in millimetres, over 200 seeded configurations (surface: 3).
Targets: mean fingertip error <= 2 mm (extended) and <= 8 mm (base).

    python benchmarks/bench_fidelity.py [hand ...]
"""

from __future__ import annotations

import sys
import time
import warnings

from _common import write_results

from ohra.original.fidelity import compare
from ohra.hands import registry

TARGET = {"base": 8.0, "extended": 2.0}
SAMPLES = 200


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
                f"{srf.mean:.2f} | {ok} |"
            )
            print(rows[-1], flush=True)
    table = "\n".join([
        f"Canonical vs original fidelity ({SAMPLES} seeded configurations per hand; mm). Target: mean fingertip "
        "error <= 2 mm extended, <= 8 mm base.",
        "",
        "| hand | form | tip mean | tip p95 | tip max | joint mean | surface mean | target met |",
        "|---|---|---|---|---|---|---|---|",
        *rows,
    ])
    write_results("fidelity", {"samples": SAMPLES, "targets_mm": TARGET, "hands": data}, table)


if __name__ == "__main__":
    main(sys.argv[1:])
