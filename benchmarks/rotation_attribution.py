"""Which step from the canonical hand to the original URDF makes a rotation policy learn like the original's.

Reads training runs (their ``progress.csv``; no training, no simulation): reference runs of the canonical and
the original URDF (several seeds each) and attribution runs, each one step from the canonical hand toward the
original URDF (the canonical URDF with the original's finger masses; the hybrid hand, the original URDF with
the canonical collision shapes). Per run it averages the rotation per training episode over a window of PPO
steps that every run reached, and classes each attribution run by the rule written before they were trained
(``runs/rotation/README.md``): *original-like* if its window mean lies nearer the original runs' mean than the
canonical runs' mean, *canonical-like* otherwise. It also draws the rotation-per-episode curves of all groups
(mean +- std over seeds) on one figure.

    python benchmarks/rotation_attribution.py \\
        --canonical runs/rotation/shadow_canonical_s0 runs/rotation/shadow_canonical_s1 \\
        --original runs/rotation/shadow_original_canonhold_s0 runs/rotation/shadow_original_canonhold_s1 \\
        --runs "canonical, original finger masses=runs/rotation/shadow_canonical_origmass_s0" \\
               "hybrid (original URDF, canonical shapes)=runs/rotation/shadow_hybrid_s0" \\
        --window 800000 1300000 --name rotation_shadow_attribution_window
    -> benchmarks/results/rotation_shadow_attribution_window.{json,md,png}
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, write_results  # noqa: E402


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


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--canonical", nargs="+", required=True, help="runs of the canonical URDF (seeds)")
    ap.add_argument("--original", nargs="+", required=True, help="runs of the original URDF (seeds)")
    ap.add_argument("--runs", nargs="+", required=True, help="LABEL=RUN attribution runs")
    ap.add_argument("--window", nargs=2, type=float, default=(800_000, 1_300_000), metavar=("LO", "HI"),
                    help="PPO steps of the training episodes averaged (default 800000 1300000)")
    ap.add_argument("--name", default="rotation_attribution")
    args = ap.parse_args(argv)
    lo, hi = args.window
    attribution = {}
    for item in args.runs:
        label, sep, run = item.partition("=")
        if not sep:
            raise SystemExit(f"rotation_attribution: --runs takes LABEL=RUN, got {item!r}")
        attribution[label] = run
    ref = {"canonical": [window_mean(r, lo, hi) for r in args.canonical],
           "original": [window_mean(r, lo, hi) for r in args.original]}
    means = {k: float(np.mean([w["mean"] for w in v])) for k, v in ref.items()}
    verdicts = {}
    for label, run in attribution.items():
        w = window_mean(run, lo, hi)
        near = "original" if abs(w["mean"] - means["original"]) < abs(w["mean"] - means["canonical"]) else "canonical"
        verdicts[label] = {**w, "verdict": f"{near}-like"}

    from ohra.learn.rl.plots import reward_curves

    png = reward_curves({"canonical URDF": args.canonical, "original URDF": args.original,
                         **{label: [run] for label, run in attribution.items()}},
                        RESULTS / f"{args.name}.png", key="rotation_mean",
                        title="Rotation per training episode: reference pairs and attribution runs")
    lines = [f"Rotation per training episode [rad], mean of the rollouts between {lo / 1e3:.0f}k and {hi / 1e3:.0f}k PPO "
             "steps (read by the rule in `runs/rotation/README.md`: original-like if nearer the original runs' mean "
             "than the canonical runs').", "",
             "| group | run | window mean [rad] | rollouts | PPO steps reached | verdict |", "|---|---|---|---|---|---|"]
    for k, ws in ref.items():
        for w in ws:
            lines.append(f"| {k} URDF | `{w['run']}` | {w['mean']:.2f} | {w['rows']} | {w['steps_reached'] / 1e3:.0f}k | |")
        lines.append(f"| {k} URDF, mean over seeds | | **{means[k]:.2f}** | | | |")
    for label, w in verdicts.items():
        lines.append(f"| {label} | `{w['run']}` | {w['mean']:.2f} | {w['rows']} | {w['steps_reached'] / 1e3:.0f}k | {w['verdict']} |")
    lines += ["", f"Curves: `{png.name}` (mean +- std over a group's seeds)."]
    write_results(args.name, {"window": [lo, hi], "reference": ref, "reference_means": means, "attribution": verdicts},
                  "\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
