"""What a rotation policy's gait earns and costs on another body: its episode return split into reward terms.

Evaluates each policy (a run or an export, deterministic actions, seeded episodes) in its own environment and in
that environment with some settings changed (``--set KEY=JSON``, e.g. ``collisions='"own"'`` runs a policy
trained on the hybrid LEAP on the original URDF with its own link shapes), next to holding still (zero actions)
in the changed environment: what the gait earns and pays, term by term, on each body. (An episode return against
holding still does not say what PPO will learn: on the hybrid LEAP, where PPO learned the gait, holding still
ranks above it too; see runs/rotation/README.md.)

    python benchmarks/rotation_returns.py --runs hybrid=runs/rotation/leap_hybrid_settled_s0 \\
        --set 'collisions="own"' --which last --name rotation_leap_hybrid_on_original
    -> benchmarks/results/rotation_leap_hybrid_on_original.{json,md}
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import run_script, script_parser, write_results  # noqa: E402


def row(label: str, res) -> tuple[str, dict]:
    """A markdown row of the mean episode return per reward term, and the numbers behind it."""
    from ohra.sim.rotation.rewards import TERMS

    ret, s = res.return_summary(), res.summary()
    cells = " | ".join(f"{ret[t]:+.1f}" for t in TERMS)
    text = (f"| {label} | {s['rotation_mean']:.2f} +- {s['rotation_std']:.2f} | {s['steps_to_fall_mean']:.1f} | "
            f"{ret['total']:+.1f} | {cells} |")
    return text, {"summary": s, "returns": ret}


def main(argv: list[str] | None = None) -> int:
    ap = script_parser(__doc__, __file__)
    ap.add_argument("--runs", nargs="+", required=True, metavar="LABEL=DIR", help="runs or exported policies")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=JSON", help="environment settings changed")
    ap.add_argument("--which", choices=("model", "last"), default="model", help="final policy or last checkpoint")
    ap.add_argument("--episodes", type=int, default=20)
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--name", default="rotation_returns")
    args = ap.parse_args(argv)
    from ohra.errors import OhraError

    try:
        return _run(args)
    except OhraError as exc:  # a bad run, setting or name: one line, as the CLI
        print(f"rotation_returns: error: {exc}", file=sys.stderr)
        return 2


def _run(args: argparse.Namespace) -> int:
    from ohra.cli.rotate import _key_values  # the CLI's own --set reading (a value that is not JSON stays a string)
    from ohra.errors import OhraError
    from ohra.learn.rl.evaluate import Policy, evaluate_policy, policy_dir
    from ohra.sim.rotation.rewards import TERMS

    changes = _key_values(args.set, "--set", OhraError)
    head = ("| policy, environment | Cumulative Rotation [rad] | Steps-to-Fall | return | " + " | ".join(TERMS) + " |\n|"
            + "---|" * (4 + len(TERMS)))
    rows, data = [head], {"episodes": args.episodes, "seed": args.seed, "changes": changes, "runs": {}}
    for item in args.runs:
        label, _, path = item.partition("=")
        pol = Policy(policy_dir(path), which=args.which)  # a run, an export or a shipped name
        other = pol.env_cfg.with_overrides(**changes)
        own = evaluate_policy(pol, pol.env_cfg, args.episodes, args.seed, grasps=pol.grasps)
        moved = evaluate_policy(pol, other, args.episodes, args.seed)
        still = evaluate_policy(lambda o, n=pol.space_dim: np.zeros(n), other, args.episodes, args.seed)
        entry = {}
        for name, res, where in (("own", own, "its own environment"), ("changed", moved, f"with {changes}"),
                                 ("zero_actions", still, f"zero actions, with {changes}")):
            text, entry[name] = row(f"{label}, {where}", res)
            rows.append(text)
        data["runs"][label] = {"run": path, **entry}
    table = (f"Mean episode return per reward term ({args.episodes} episodes, seeds {args.seed}..{args.seed + args.episodes - 1}, "
             "deterministic actions; penalties negative):\n\n" + "\n".join(rows))
    write_results(args.name, data, table)
    return 0


if __name__ == "__main__":
    run_script(main, __file__)
