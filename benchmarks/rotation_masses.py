"""Do the finger masses explain a canonical rotation policy's behaviour? Each shipped canonical-URDF policy
run on its canonical URDF with the original URDF's finger masses (``inertials="original"``: canonical
geometry, the original's link masses and inertias; starting states generated for that URDF), next to its
own URDF, the same seeded episodes.

    python benchmarks/rotation_masses.py [--episodes 20] [--policies rotate_leap_canonical ...]
    -> benchmarks/results/rotation_masses.{json,md}
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import run_script, script_parser, write_results  # noqa: E402
from rotation_table3 import summary_cell  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    ap = script_parser(__doc__, __file__)
    ap.add_argument("--episodes", type=int, default=20)
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--policies", nargs="+", default=["rotate_leap_canonical", "rotate_shadow_canonical"])
    args = ap.parse_args(argv)
    from ohra.learn.rl.evaluate import Policy, evaluate_policy, shipped

    rows, data = [], {}
    for name in args.policies:
        pol = Policy(shipped(name))
        if pol.env_cfg.urdf != "canonical":
            raise SystemExit(f"{name} was trained on the {pol.env_cfg.urdf} URDF; this compares canonical-URDF policies")
        own = evaluate_policy(pol, pol.env_cfg, args.episodes, args.seed, name, grasps=pol.grasps).summary()
        heavy_cfg = dataclasses.replace(pol.env_cfg, inertials="original")
        heavy = evaluate_policy(pol, heavy_cfg, args.episodes, args.seed, name).summary()
        data[name] = {"hand": pol.env_cfg.hand, "capsule_inertials": own, "original_inertials": heavy}
        rows += [f"| {name} | {kind} | {summary_cell(r, ' | ')} |"
                 for kind, r in (("capsule (trained)", own), ("original finger masses", heavy))]
        print(rows[-2], rows[-1], sep="\n", file=sys.stderr)
    table = "\n".join([
        f"Shipped canonical-URDF rotation policies on their canonical URDF with the trained (capsule) inertials and with "
        f"the original URDF's finger masses and inertias (`inertials=\"original\"`), {args.episodes} episodes "
        f"(seeds {args.seed}..{args.seed + args.episodes - 1}), deterministic actions.", "",
        "| policy | inertials | Steps-to-Fall | Cumulative Rotation [rad] | survived |", "|---|---|---|---|---|", *rows])
    write_results("rotation_masses", {"episodes": args.episodes, "seed": args.seed, "policies": data}, table)
    return 0


if __name__ == "__main__":
    run_script(main, __file__)
