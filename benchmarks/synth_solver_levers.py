"""Grasp NLP solver levers that issue 12 names and bench_levers.py does not: compiled CasADi functions (JIT) and
fewer IPOPT iterations.

Same hands, objects, starts and NLP for every variant; only how the solver is built or capped differs:

- ``reference``: the shipped solver (CasADi's SX virtual machine evaluates the NLP's functions);
- ``jit``: the same NLP with ``jit=True`` (CasADi writes C for the objective, constraints and their derivatives and
  compiles it with the system C compiler, ``-O1``); the compile happens once per (hand, object) NLP, which is what
  the pipeline builds per shard;
- ``max_iter N``: IPOPT stopped after N iterations (the reference allows 300; converged solves take ~60-150).

Per variant and hand: converged starts (IPOPT success, no row violated by more than 1e-3), agreement with the
reference (same success and the same grasp within 1e-6 on every start), mean IPOPT iterations, mean solve CPU
time, and the wall time to build the NLP (for ``jit``: the C compile, in a child process, so wall not CPU). The
break-even is the starts per (hand, object) pair at which the compile is paid back by the faster solves; the
pipeline solves 4-8 starts per pair (recipes: ``grasps_per_pair``). Solve time only: the six-direction test that
follows each converged solve is unchanged by these levers (``bench_ceiling.py``).

Needs a C compiler on PATH for ``jit`` (gcc or cc). About 6-10 minutes on one core with the defaults.

    python benchmarks/synth_solver_levers.py [--starts 4] [--hands ...] [--objects ...]
    -> benchmarks/results/synth_solver_levers.{json,md}
"""

from __future__ import annotations

import shutil
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import run_script, script_parser, write_results  # noqa: E402

import numpy as np  # noqa: E402

from ohra.canonical.kinematics import HandModel  # noqa: E402
from ohra.errors import OhraError  # noqa: E402
from ohra.hands import get_hand  # noqa: E402
from ohra.objects.resolve import resolve_object  # noqa: E402
from ohra.synth.init import initial_poses  # noqa: E402
from ohra.synth.nlp import GraspNLP, NLPSettings  # noqa: E402

HANDS = ["leap_3333", "allegro_hand_left", "barrett_hand", "shadow_hand_right"]
OBJECTS = ["builtin:box", "builtin:cylinder", "builtin:sphere", "builtin:ellipsoid"]
MAX_ITERS = [100]
SEED = 0


class JitNLP(GraspNLP):
    """The shipped NLP with its functions compiled to machine code."""

    def _ipopt_options(self) -> dict:
        return {**super()._ipopt_options(), "jit": True, "compiler": "shell",
                "jit_options": {"flags": ["-O1"], "verbose": False}}


def variants(max_iters: list[int]) -> list[tuple[str, type, NLPSettings]]:
    return ([("reference", GraspNLP, NLPSettings()), ("jit", JitNLP, NLPSettings())]
            + [(f"max_iter {n}", GraspNLP, NLPSettings(max_iter=n)) for n in max_iters])


def run(hand_name: str, obj_spec: str, starts: int, max_iters: list[int]) -> list[dict]:
    """Every variant on the same starts of one (hand, object) pair."""
    hand = HandModel.from_params(get_hand(hand_name))
    obj = resolve_object(obj_spec)
    poses = initial_poses(hand, obj, starts, np.random.default_rng(SEED))
    rows = []
    for name, cls, settings in variants(max_iters):
        t = time.perf_counter()
        nlp = cls(hand, obj, settings)
        build_s = time.perf_counter() - t
        for k, st in enumerate(poses):
            c = time.process_time()
            r = nlp.solve(st["R0"], st["t0"], st["q0"], st["q_pref"])
            rows.append({"hand": hand_name, "object": obj.name, "variant": name, "start": k, "success": r["success"],
                         "iterations": r["iterations"], "solve_cpu_s": time.process_time() - c, "build_wall_s": build_s,
                         "grasp": r["grasp"].tolist()})
    return rows


def summarise(rows: list[dict], hands: list[str], max_iters: list[int]) -> list[dict]:
    ref = {(r["hand"], r["object"], r["start"]): r for r in rows if r["variant"] == "reference"}
    out = []
    for hand in hands + ["all"]:
        base = None
        for name, _, _ in variants(max_iters):
            rs = [r for r in rows if r["variant"] == name and hand in ("all", r["hand"])]
            same = [r["success"] == ref[(r["hand"], r["object"], r["start"])]["success"] and
                    np.abs(np.subtract(r["grasp"], ref[(r["hand"], r["object"], r["start"])]["grasp"])).max() <= 1e-6 for r in rs]
            pairs = {(r["hand"], r["object"]): r["build_wall_s"] for r in rs}
            row = {"hand": hand, "variant": name, "starts": len(rs), "converged": sum(r["success"] for r in rs),
                   "agree": int(sum(same)), "mean_iterations": float(np.mean([r["iterations"] for r in rs])),
                   "mean_solve_cpu_s": float(np.mean([r["solve_cpu_s"] for r in rs])),
                   "mean_build_wall_s": float(np.mean(list(pairs.values())))}
            if base is None:
                base = row
            saved = base["mean_solve_cpu_s"] - row["mean_solve_cpu_s"]
            extra = row["mean_build_wall_s"] - base["mean_build_wall_s"]
            row["break_even_starts"] = (float(extra / saved) if saved > 0 and extra > 0 else None)
            out.append(row)
    return out


def report(summary: list[dict], args) -> None:
    lines = [
        f"Grasp NLP solver levers: {len(args.hands)} hands x {len(args.objects)} objects ({', '.join(args.objects)}), "
        f"{args.starts} starts each (seed {SEED}), the same starts for every variant; CPU time of the solves, wall time "
        "of building the NLP (the JIT's C compile runs in a child process). Agreement: same success and the same grasp "
        "within 1e-6 as the reference. Break-even: starts per (hand, object) pair that pay back the extra build time.",
        "",
        "| hand | variant | converged | agree with reference | mean iterations | mean solve CPU [s] | build per pair, wall [s] | break-even starts per pair |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in summary:
        be = "-" if r["break_even_starts"] is None else f"{r['break_even_starts']:.0f}"
        lines.append(f"| {r['hand']} | {r['variant']} | {r['converged']}/{r['starts']} | {r['agree']}/{r['starts']} | "
                     f"{r['mean_iterations']:.0f} | {r['mean_solve_cpu_s']:.3f} | {r['mean_build_wall_s']:.2f} | {be} |")
    write_results("synth_solver_levers", {"summary": summary, "hands": args.hands, "objects": args.objects,
                                          "starts": args.starts, "seed": SEED, "max_iters": args.max_iters}, "\n".join(lines))


def main() -> None:
    ap = script_parser(__doc__, __file__)
    ap.add_argument("--starts", type=int, default=4, help="starts per (hand, object) pair (default 4)")
    ap.add_argument("--hands", nargs="+", default=HANDS, help=f"hands (default {' '.join(HANDS)})")
    ap.add_argument("--objects", nargs="+", default=OBJECTS, help=f"objects (default {' '.join(OBJECTS)})")
    ap.add_argument("--max-iters", nargs="+", type=int, default=MAX_ITERS, help="IPOPT iteration caps to try (default 100)")
    args = ap.parse_args()
    for h in args.hands:
        get_hand(h)  # a misspelt hand fails before minutes of solves
    if shutil.which("gcc") is None and shutil.which("cc") is None:
        raise OhraError("the jit variant needs a C compiler (gcc or cc) on PATH")
    rows = []
    for hand in args.hands:
        for obj in args.objects:
            rows += run(hand, obj, args.starts, args.max_iters)
            print(hand, obj, flush=True)
    report(summarise(rows, args.hands, args.max_iters), args)


if __name__ == "__main__":
    run_script(main, __file__)
