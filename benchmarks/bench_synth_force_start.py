"""Grasp NLP: initial contact forces zero vs a unit push toward the object's centre.

Same hands, objects, starts and solver; only the forces in x0 differ. Per variant and hand: starts
that converge (IPOPT success, no row violated by more than 1e-3), converged solutions whose fingers
intersect (exact Coal check; the pipeline discards them), median objective of the converged,
mean IPOPT iterations and mean solve time.

Run: python benchmarks/bench_synth_force_start.py [--seeds 100 200] -> benchmarks/results/synth_force_start.{json,md}
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import run_script, script_parser, write_results  # noqa: E402

import numpy as np  # noqa: E402

from ohra.canonical.kinematics import HandModel  # noqa: E402
from ohra.hands import get_hand  # noqa: E402
from ohra.objects.builtin import BUILTINS  # noqa: E402
from ohra.objects.model import ObjectModel  # noqa: E402
from ohra.synth.init import initial_poses  # noqa: E402
from ohra.synth.nlp import GraspNLP  # noqa: E402

HANDS = ["leap_2200", "leap_3303", "leap_3333", "shadow_hand_right"]


class ZeroForceStart(GraspNLP):
    """The NLP with the earlier initial guess: every contact force zero."""

    def _initial_guess(self, p, t0, q0):
        x0 = super()._initial_guess(p, t0, q0)
        x0[self.force_slice] = 0.0
        return x0


def run(hand_name: str, variant: str, seed: int, starts: int) -> list[dict]:
    hand = HandModel.from_params(get_hand(hand_name))
    rows = []
    for name in BUILTINS:
        obj = ObjectModel.builtin(name)
        nlp = (ZeroForceStart if variant == "zero" else GraspNLP)(hand, obj)
        s = nlp.s
        for st in initial_poses(hand, obj, starts, np.random.default_rng(seed)):
            t = time.perf_counter()
            r = nlp.solve(st["R0"], st["t0"], st["q0"], st["q_pref"])
            dt = time.perf_counter() - t
            q = r["grasp"][9:][nlp.movable]
            J = s.w_force * float(np.sum(r["forces"] ** 2)) + s.w_posture * float(np.sum((q - st["q_pref"][nlp.movable]) ** 2))
            rows.append({"hand": hand_name, "variant": variant, "seed": seed, "object": name, "success": r["success"],
                         "self_collision": bool(r["success"] and hand.self_collision(r["grasp"][9:])),
                         "objective": J, "iterations": r["iterations"], "solve_s": dt})
    return rows


def summarise(rows: list[dict], hands: list[str]) -> list[dict]:
    """One row per (hand or "all", variant): the table's columns."""
    out = []
    for hand in hands + ["all"]:
        for variant in ("zero", "centre"):
            rs = [r for r in rows if r["variant"] == variant and hand in ("all", r["hand"])]
            ok = [r for r in rs if r["success"]]
            out.append({"hand": hand, "variant": variant, "starts": len(rs), "converged": len(ok),
                        "self_intersecting": sum(r["self_collision"] for r in rs),
                        "median_objective": float(np.median([r["objective"] for r in ok])),
                        "mean_iterations": float(np.mean([r["iterations"] for r in rs])),
                        "mean_solve_s": float(np.mean([r["solve_s"] for r in rs]))})
    return out


def report(summary: list[dict], seeds: list[int], starts: int) -> None:
    lines = [
        f"The {len(BUILTINS)} built-in objects, {starts} starts each, seeds {seeds}: the same starts for both variants.",
        "",
        "| hand | initial forces | converged | self-intersecting | median objective | mean iterations | mean solve [s] |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in summary:
        lines.append(f"| {r['hand']} | {r['variant']} | {r['converged']}/{r['starts']} | {r['self_intersecting']} | "
                     f"{r['median_objective']:.3f} | {r['mean_iterations']:.0f} | {r['mean_solve_s']:.2f} |")
    write_results("synth_force_start", {"summary": summary, "seeds": seeds, "starts": starts}, "\n".join(lines))


def main() -> None:
    ap = script_parser(__doc__, __file__)
    ap.add_argument("--seeds", nargs="+", type=int, default=[100, 200])
    ap.add_argument("--starts", type=int, default=8, help="starts per object")
    ap.add_argument("--hands", nargs="+", default=HANDS)
    args = ap.parse_args()
    rows = []
    for hand in args.hands:
        for variant in ("zero", "centre"):
            for seed in args.seeds:
                rows += run(hand, variant, seed, args.starts)
                print(hand, variant, seed, flush=True)
    report(summarise(rows, args.hands), args.seeds, args.starts)


if __name__ == "__main__":
    run_script(main, __file__)
