"""Which step from the canonical hand to the original URDF makes a rotation policy learn like the original's.

Reads training runs (their ``progress.csv``; no training, no simulation): reference runs of the canonical and
the original URDF (several seeds each) and attribution arms, each one step from the canonical hand toward the
original URDF (the canonical URDF with the original's finger masses; the hybrid hand, the original URDF with
the canonical collision shapes), each arm one or more seeds. Per run it averages the rotation per training
episode over a window of PPO steps that every run reached; an arm's mean is the mean of its seeds' window
means, and it is classed by the rule written before the runs were trained (``runs/rotation/README.md``):
*original-like* if nearer the original runs' mean than the canonical runs' mean, *canonical-like* otherwise
(each seed's own class is listed beside it). It also draws the rotation-per-episode curves of all groups
(mean +- std over seeds) on one figure. With ``--evals``, the ``rotation_table3.py`` results holding the
arms' evaluation episodes are pooled per arm (every seed's episodes together: mean, standard error, each
seed's mean), the episodes matched to an arm by their run folder.

    python benchmarks/rotation_attribution.py \\
        --canonical runs/rotation/shadow_canonical_s0 runs/rotation/shadow_canonical_s1 \\
        --original runs/rotation/shadow_original_canonhold_s0 runs/rotation/shadow_original_canonhold_s1 \\
        --runs "canonical, original finger masses=runs/rotation/shadow_canonical_origmass_s0" \\
               "hybrid (original URDF, canonical shapes)=runs/rotation/shadow_hybrid_s0" \\
        --window 800000 1300000 --name rotation_shadow_attribution_window
    -> benchmarks/results/rotation_shadow_attribution_window.{json,md,png}

    # two seeds per arm (LABEL=RUN,RUN), their evaluations pooled
    python benchmarks/rotation_attribution.py --canonical ... --original ... \\
        --runs "canonical, original finger masses=runs/rotation/shadow_canonical_origmass_s0,runs/rotation/shadow_canonical_origmass_s1" \\
               "hybrid (original URDF, canonical shapes)=runs/rotation/shadow_hybrid_s0,runs/rotation/shadow_hybrid_s1" \\
        --evals rotation_shadow_attribution rotation_shadow_attribution_s1 --name rotation_shadow_attribution_seeds
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, read_results, run_script, script_parser, write_results  # noqa: E402
from rotation_seeds import METRICS, pooled  # noqa: E402


def window_mean(run: str, lo: float, hi: float) -> dict:
    """Mean rotation per training episode over the rollouts logged at ``lo`` <= PPO steps <= ``hi``."""
    from ohra.learn.rl.plots import read_progress

    p = read_progress(run)
    steps, rot = p["timesteps"], p["rotation_mean"]
    keep = (steps >= lo) & (steps <= hi) & np.isfinite(rot)
    if not keep.any():
        raise SystemExit(f"rotation_attribution: {run} logged no rollout between {lo:.0f} and {hi:.0f} PPO steps "
                         f"(it reached {steps.max():.0f})")
    return {"run": run, "rows": int(keep.sum()), "mean": float(rot[keep].mean()), "steps_reached": float(steps.max())}


def arm_of(entry: dict, arms: dict[str, list[str]]) -> str | None:
    """The arm whose runs include the evaluated run's folder (``per_episode.run``), else None."""
    run = Path(entry["per_episode"]["run"]).resolve()
    return next((label for label, runs in arms.items() if run in {Path(r).resolve() for r in runs}), None)


def pooled_evals(names: list[str], arms: dict[str, list[str]]) -> dict[str, dict]:
    """Per arm, every seed's evaluation episodes pooled (``rotation_seeds.pooled``) over the named results."""
    results = read_results(names, "rotation_attribution")
    if len({(r["episodes"], r["seed"]) for r in results.values()}) != 1:
        raise SystemExit("rotation_attribution: the results were evaluated on different episodes")
    found: dict[str, list[dict]] = {label: [] for label in arms}
    for res in results.values():
        for entry in res["runs"].values():
            label = arm_of(entry, arms)
            if label is not None:
                found[label].append(entry)
    out = {}
    for label, entries in found.items():
        if len(entries) != len(arms[label]):
            raise SystemExit(f"rotation_attribution: arm {label!r} has {len(arms[label])} run(s) but the results "
                             f"{names} evaluate {len(entries)} of them")
        out[label] = {"runs": [e["per_episode"]["run"] for e in entries],
                      "budget": [{"steps": e["budget"]["steps"], "minutes": e["budget"]["minutes"]} for e in entries],
                      **{k: pooled([e["per_episode"][k] for e in entries]) for k in METRICS}}
    return out


def main(argv: list[str] | None = None) -> int:
    ap = script_parser(__doc__, __file__)
    ap.add_argument("--canonical", nargs="+", required=True, help="runs of the canonical URDF (seeds)")
    ap.add_argument("--original", nargs="+", required=True, help="runs of the original URDF (seeds)")
    ap.add_argument("--runs", nargs="+", required=True, help="LABEL=RUN[,RUN...] attribution arms (one run per seed)")
    ap.add_argument("--window", nargs=2, type=float, default=(800_000, 1_300_000), metavar=("LO", "HI"),
                    help="PPO steps of the training episodes averaged (default 800000 1300000)")
    ap.add_argument("--evals", nargs="+", default=[], metavar="NAME",
                    help="rotation_table3.py results (benchmarks/results/NAME.json) holding the arms' evaluations")
    ap.add_argument("--name", default="rotation_attribution")
    args = ap.parse_args(argv)
    lo, hi = args.window
    arms: dict[str, list[str]] = {}
    for item in args.runs:
        label, sep, runs = item.partition("=")
        if not sep or not all(runs.split(",")):
            raise SystemExit(f"rotation_attribution: --runs takes LABEL=RUN[,RUN...], got {item!r}")
        arms[label] = runs.split(",")
    ref = {"canonical": [window_mean(r, lo, hi) for r in args.canonical],
           "original": [window_mean(r, lo, hi) for r in args.original]}
    means = {k: float(np.mean([w["mean"] for w in v])) for k, v in ref.items()}

    def verdict(x: float) -> str:
        return ("original" if abs(x - means["original"]) < abs(x - means["canonical"]) else "canonical") + "-like"

    verdicts = {}
    for label, runs in arms.items():
        seeds = [{**w, "verdict": verdict(w["mean"])} for w in (window_mean(r, lo, hi) for r in runs)]
        mean = float(np.mean([w["mean"] for w in seeds]))
        verdicts[label] = {"seeds": seeds, "mean": mean, "verdict": verdict(mean)}
    evals = pooled_evals(args.evals, arms) if args.evals else {}

    from ohra.learn.rl.plots import reward_curves

    png = reward_curves({"canonical URDF": args.canonical, "original URDF": args.original, **arms},
                        RESULTS / f"{args.name}.png", key="rotation_mean",
                        title="Rotation per training episode: reference pairs and attribution runs")
    lines = [f"Rotation per training episode [rad], mean of the rollouts between {lo / 1e3:.0f}k and {hi / 1e3:.0f}k PPO "
             "steps (read by the rule in `runs/rotation/README.md`: original-like if nearer the original runs' mean "
             "than the canonical runs'; an arm of several seeds by the mean of its seeds' window means).", "",
             "| group | run | window mean [rad] | rollouts | PPO steps reached | verdict |", "|---|---|---|---|---|---|"]
    for k, ws in ref.items():
        for w in ws:
            lines.append(f"| {k} URDF | `{w['run']}` | {w['mean']:.2f} | {w['rows']} | {w['steps_reached'] / 1e3:.0f}k | |")
        lines.append(f"| {k} URDF, mean over seeds | | **{means[k]:.2f}** | | | |")
    for label, v in verdicts.items():
        for w in v["seeds"]:
            tail = w["verdict"] if len(v["seeds"]) == 1 else f"({w['verdict']})"
            lines.append(f"| {label} | `{w['run']}` | {w['mean']:.2f} | {w['rows']} | {w['steps_reached'] / 1e3:.0f}k | {tail} |")
        if len(v["seeds"]) > 1:
            lines.append(f"| {label}, mean over seeds | | **{v['mean']:.2f}** | | | {v['verdict']} |")
    lines += ["", f"Curves: `{png.name}` (mean +- std over a group's seeds)."]
    if evals:
        lines += ["", f"Evaluation episodes pooled per arm (`{'`, `'.join(args.evals)}`; mean +- standard error over "
                  "every seed's episodes, each seed's mean in brackets):", "",
                  "| arm | episodes | " + " | ".join(METRICS.values()) + " | budget |", "|---|---|---|---|---|"]
        for label, e in evals.items():
            budget = ", ".join(f"{b['steps'] / 1e3:.0f}k steps / {b['minutes']:.0f} min" for b in e["budget"])
            lines.append(f"| {label} | {e['steps_to_fall']['n']} | " + " | ".join(
                f"{e[k]['mean']:.2f} +- {e[k]['se']:.2f} ({', '.join(f'{m:.2f}' for m in e[k]['seed_means'])})"
                for k in METRICS) + f" | {budget} |")
    write_results(args.name, {"window": [lo, hi], "reference": ref, "reference_means": means, "attribution": verdicts,
                              "evaluations": evals}, "\n".join(lines))
    return 0


if __name__ == "__main__":
    run_script(main, __file__)
