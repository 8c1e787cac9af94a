"""Table 3 analogue: rotation policies trained on the canonical vs the original URDF, same budget and seed.

Evaluates each policy (Steps-to-Fall, Cumulative Rotation) over the same seeded episodes and draws
their training curves. Default: the four Table 3 policies shipped in ``ohra/learn/models/rotate_*`` (each an
export of a run trained with ``ohra rotate train``; the budget is read from its progress.csv).

    python benchmarks/rotation_table3.py [--episodes 20] [--runs LABEL=DIR ...] [--no-transfer]

Each canonical-URDF policy is also run on the hand's original URDF through the action map
(``ohra.learn.rl.on_urdf``), the same seeded episodes.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, run_script, script_parser, write_results  # noqa: E402

import numpy as np  # noqa: E402

PAPER = {"leap_hand_right": {"canonical": (326.98, 6.31), "original": (397.62, 5.63)},
         "shadow_hand_right": {"canonical": (390.62, 10.92), "original": (369.66, 9.09)}}


def _budget_text(budget: dict) -> str:
    """``1688k steps, 120 min``; a run started from another's policy: ``3578k + 2200k steps, 170 + 60 min``."""
    src = budget.get("init_from")
    if not src:
        return f"{budget['steps'] / 1e3:.0f}k steps, {budget['minutes']:.0f} min"
    steps = "?" if src.get("steps") is None else f"{src['steps'] / 1e3:.0f}k"  # a source that recorded no budget
    minutes = "?" if src.get("minutes") is None else f"{src['minutes']:.0f}"
    return f"{steps} + {budget['steps'] / 1e3:.0f}k steps, {minutes} + {budget['minutes']:.0f} min"


def main(argv: list[str] | None = None) -> int:
    ap = script_parser(__doc__, __file__)
    ap.add_argument("--episodes", type=int, default=20)
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--runs", nargs="*", metavar="LABEL=DIR", help="default: the four shipped Table 3 policies")
    ap.add_argument("--name", default="rotation_table3",
                    help="results name: benchmarks/results/NAME.{json,md} and NAME_curves*.png (default: the shipped "
                         "table, whose curves are rotation_curves*.png)")
    ap.add_argument("--no-transfer", action="store_true",
                    help="skip running each canonical-URDF policy on the original URDF as well")
    args = ap.parse_args(argv)
    from ohra.learn.rl.evaluate import Policy, evaluate_policy, on_urdf
    from ohra.learn.rl.plots import read_progress, reward_curves
    from ohra.learn.rl.train import read_config
    from ohra.sim.rotation.rewards import TERMS

    runs = dict(r.split("=", 1) for r in args.runs) if args.runs else _shipped()
    rows, data, ret_rows, grip_rows, moved_rows = [], {}, [], [], []
    for label, d in runs.items():
        pol = Policy(d)
        grip = starting_grip(pol)
        grip_rows.append(f"| {label} | {grip['mean_gap_rad']:.4f} | {grip['max_gap_rad']:.3f} | "
                         f"{100 * grip['pressed_fraction']:.0f} % |")
        res = evaluate_policy(pol, pol.env_cfg, args.episodes, args.seed, str(d), grasps=pol.grasps)
        prog = read_progress(d)
        budget = {"steps": int(prog["timesteps"][-1]), "minutes": float(prog["wall_s"][-1]) / 60.0,
                  "envs": pol.ppo.n_envs, "seed": pol.ppo.seed}
        init = read_config(d).get("init_from")  # a run started from another's policy: state both budgets
        if init:
            budget["init_from"] = {"run": init["run"], "steps": init.get("timesteps"),
                                   "minutes": None if init.get("wall_s") is None else init["wall_s"] / 60.0}
        s = res.summary()
        cfg = pol.env_cfg
        hybrid = cfg.collisions == "canonical"  # the original URDF with the canonical collision shapes
        urdf = f"{cfg.urdf} + canonical collisions" if hybrid else cfg.urdf
        paper = None if hybrid else PAPER.get(cfg.hand, {}).get(cfg.urdf)
        data[label] = {"hand": cfg.hand, "urdf": urdf, "space": cfg.resolved_space, "summary": s, "budget": budget,
                       "per_episode": res.to_dict(), "paper": paper, "starting_grip": grip}
        rows.append(f"| {label} | {cfg.hand} | {urdf} | {s['steps_to_fall_mean']:.1f} +- {s['steps_to_fall_std']:.1f} | "
                    f"{s['rotation_mean']:.2f} +- {s['rotation_std']:.2f} | {100 * s['survived']:.0f} % | "
                    f"{_budget_text(budget)}, seed {budget['seed']} | "
                    f"{'%.1f / %.2f' % paper if paper else '-'} |")
        print(rows[-1], file=sys.stderr)
        zero_res = evaluate_policy(lambda o, n=pol.space_dim: np.zeros(n), cfg, args.episodes, args.seed,
                                   grasps=pol.grasps)
        zero = zero_res.summary()
        data[label]["zero_actions"] = zero
        ret, zero_ret = res.return_summary(), zero_res.return_summary()
        data[label]["returns"], data[label]["zero_actions_returns"] = ret, zero_ret
        for name, r in ((label, ret), (f"{label} (zero actions)", zero_ret)):
            ret_rows.append(f"| {name} | {r['total']:.1f} | " + " | ".join(f"{r[k]:+.1f}" for k in TERMS) + " |")
        rows.append(f"| (zero actions) | {cfg.hand} | {urdf} | {zero['steps_to_fall_mean']:.1f} +- "
                    f"{zero['steps_to_fall_std']:.1f} | {zero['rotation_mean']:.2f} +- {zero['rotation_std']:.2f} | "
                    f"{100 * zero['survived']:.0f} % | no training | - |")
        if cfg.urdf == "canonical" and not args.no_transfer:
            # the same policy on the original URDF through the action map, from the canonical holding pose
            moved = evaluate_policy(pol, on_urdf(cfg, "original"), args.episodes, args.seed, str(d)).summary()
            data[label]["on_original_urdf"] = moved
            moved_rows.append(f"| {label} | {cfg.hand} | {summary_cell(s)} | {summary_cell(moved)} |")
            print(moved_rows[-1], file=sys.stderr)
    groups = {k: [v] for k, v in runs.items()}
    stem = "rotation_curves" if args.name == "rotation_table3" else f"{args.name}_curves"
    curve = reward_curves(groups, RESULTS / f"{stem}.png",
                          title="PPO on in-hand rotation (cube, 20 Hz): canonical vs original URDF")
    reward_curves(groups, RESULTS / f"{stem}_rotation.png", key="rotation_mean",
                  title="Rotation about +z per training episode")
    table = "\n".join([
        f"Rotation policies, {args.episodes} episodes each (seeds {args.seed}..{args.seed + args.episodes - 1}, "
        "deterministic actions, 400-step episodes). Steps-to-Fall: steps before the object falls or leaves "
        "(400 if it never does); Cumulative Rotation: radians about world +z per episode. Budget: PPO env "
        "steps and wall minutes on the shared 2-core machine (other jobs running). \"(zero actions)\": the same "
        "episodes with the targets held, the baseline a policy must beat (the grasps hold; the object creeps a little).", "",
        "| policy | hand | urdf | Steps-to-Fall | Cumulative Rotation [rad] | survived | budget | paper (steps / rad) |",
        "|---|---|---|---|---|---|---|---|", *rows, "",
        f"Training curves: `{curve.relative_to(RESULTS.parent.parent)}` (return), `{stem}_rotation.png` (rotation).",
        "", "Mean episode return split into its weighted reward terms (same episodes; what the policy was trained "
        "to maximise, penalties negative):", "",
        "| policy | return | " + " | ".join(TERMS) + " |", "|---|---|" + "---|" * len(TERMS), *ret_rows,
        "", f"Grip of the starting states each policy was trained and evaluated from ({GRIP_NOTE}):", "",
        "| policy | mean abs(target - q) [rad] | mean over states of the largest joint gap [rad] | "
        f"states with a joint pressed > {PRESSED} rad |", "|---|---|---|---|", *grip_rows,
        *(["", "Each canonical-URDF policy also run on the hand's original URDF through the action map (canonical "
           "22-D actions and observations, starting states from the canonical holding pose on the original URDF; "
           "same seeds; Steps-to-Fall / Cumulative Rotation [rad] / survived):", "",
           "| policy | hand | on the canonical URDF (trained) | on the original URDF |", "|---|---|---|---|",
           *moved_rows] if moved_rows else [])])
    write_results(args.name, {"episodes": args.episodes, "seed": args.seed, "runs": data}, table)
    return 0


def summary_cell(s: dict, sep: str = " / ") -> str:
    """Steps-to-Fall, Cumulative Rotation and survival of an ``EvalResult.summary()``, joined by ``sep``."""
    return sep.join([f"{s['steps_to_fall_mean']:.1f} +- {s['steps_to_fall_std']:.1f}",
                     f"{s['rotation_mean']:.2f} +- {s['rotation_std']:.2f}", f"{100 * s['survived']:.0f} %"])


PRESSED = 0.05  # rad: a joint whose motor target lies this far past its settled angle is pressing on something
GRIP_NOTE = ("every cached starting state; a finger the object blocks keeps its motor target inside the object, so "
             "abs(target - q) measures how hard the start grasp squeezes; 0 for a run with start_targets='settled', "
             "whose motors start at the settled angles")


def starting_grip(pol) -> dict:
    """How hard the starting states squeeze the object: statistics of abs(motor target - settled joint angle)."""
    from ohra.sim.rotation.grasps import load_or_generate
    from ohra.sim.rotation.task import resolve

    gs = pol.grasps if pol.grasps is not None else load_or_generate(resolve(pol.env_cfg))
    # start_targets="settled" resets the motors to the settled angles: no joint starts pressed
    target = gs.q if pol.env_cfg.start_targets == "settled" else gs.target
    gap = np.abs(np.asarray(target) - np.asarray(gs.q))
    return {"states": int(len(gap)), "mean_gap_rad": float(gap.mean()), "max_gap_rad": float(gap.max(axis=1).mean()),
            "pressed_fraction": float((gap.max(axis=1) > PRESSED).mean())}


# the Table 3 pairs: same settings per hand, canonical vs original (other shipped policies, such as the LEAP
# policy fine-tuned with a drop penalty, change the reward and are evaluated with --runs)
TABLE3 = ("rotate_leap_canonical", "rotate_leap_original", "rotate_shadow_canonical", "rotate_shadow_original")


def _shipped() -> dict[str, Path]:
    from importlib import resources

    root = Path(str(resources.files("ohra.learn").joinpath("models")))
    return {name.replace("rotate_", ""): root / name for name in TABLE3 if (root / name / "policy.pth").is_file()}


if __name__ == "__main__":
    run_script(main, __file__)
