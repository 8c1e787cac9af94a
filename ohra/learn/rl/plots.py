"""Training curves (mean +- std over seeds) and the Table-3-style comparison of rotation runs."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from ohra.errors import CheckpointError


def read_progress(run_dir: str | Path) -> dict[str, np.ndarray]:
    """Columns of ``RUN/progress.csv`` as float arrays (empty cells -> NaN)."""
    path = Path(run_dir) / "progress.csv"
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))

    def parsed(r: dict) -> dict[str, float] | None:  # None: a row torn by a kill mid-append (cells missing)
        if None in r or any(v is None for v in r.values()):
            return None
        try:
            return {k: float(v) if v not in ("", "nan") else np.nan for k, v in r.items()}
        except ValueError:
            return None

    good = [p for p in map(parsed, rows) if p is not None]
    if not good:
        return {}
    return {k: np.array([r[k] for r in good]) for k in good[0]}


def smooth(y: np.ndarray, window: int) -> np.ndarray:
    """Trailing moving average ignoring NaNs (window in rows)."""
    if window <= 1:
        return y
    out = np.full_like(y, np.nan)
    for i in range(len(y)):
        seg = y[max(0, i - window + 1):i + 1]
        if np.isfinite(seg).any():
            out[i] = np.nanmean(seg)
    return out


def mean_std_curve(runs: list[str | Path], key: str = "ep_reward_mean", x: str = "timesteps", points: int = 100,
                   window: int = 5) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(grid, mean, std) of ``key`` over runs, each run interpolated onto a common ``x`` grid up to the
    shortest run's end."""
    curves = []
    for r in runs:
        p = read_progress(r)
        for col in (key, x):
            if col not in p:
                raise CheckpointError(f"{Path(r) / 'progress.csv'} has no column {col!r}"
                                      + (f" (columns: {', '.join(p)})" if p else " (no rows yet)"))
        ok = np.isfinite(p[key])
        if not ok.any():  # e.g. ep_reward_mean before the first episode has ended
            raise CheckpointError(f"{Path(r) / 'progress.csv'} has no value of {key!r} yet ({len(ok)} rows, all empty: "
                                  "no episode has ended); plot it once the run has trained longer")
        curves.append((p[x][ok], smooth(p[key], window)[ok]))
    # where every run has data: before a run's first finished episode np.interp would draw its first value flat
    start, end = max(c[0][0] for c in curves), min(c[0][-1] for c in curves)
    grid = np.linspace(start, max(end, start), points)
    Y = np.array([np.interp(grid, cx, cy) for cx, cy in curves])
    return grid, Y.mean(axis=0), Y.std(axis=0)


def _runs_label(runs: list[str | Path]) -> str:
    """'1 seed', 'k seeds' when the runs' PPO seeds (``config.json``) differ, else 'k runs' (one seed twice is not two)."""
    import json

    seeds = []
    for r in runs:
        try:
            seeds.append(json.loads((Path(r) / "config.json").read_text())["ppo"]["seed"])
        except (OSError, ValueError, KeyError, TypeError):
            seeds.append(None)
    if len(runs) == 1:
        return "1 seed"
    if None not in seeds and len(set(seeds)) == len(seeds):
        return f"{len(runs)} seeds"
    known = sorted({s for s in seeds if s is not None})
    return f"{len(runs)} runs" + (f", seed{'s' if len(known) > 1 else ''} {', '.join(map(str, known))}" if known else "")


def reward_curves(groups: dict[str, list[str | Path]], path: str | Path, key: str = "ep_reward_mean",
                  x: str = "timesteps", title: str = "") -> Path:
    """PNG of one curve per group (label -> run dirs): mean line, +-std band over its runs."""
    from matplotlib.figure import Figure  # no pyplot: a notebook's inline backend is left alone

    from ohra.io import atomic_path

    fig = Figure(figsize=(6.0, 3.6), dpi=120)
    ax = fig.subplots()
    for label, runs in groups.items():
        g, m, s = mean_std_curve(runs, key, x)
        ax.plot(g, m, label=f"{label} ({_runs_label(runs)})")
        ax.fill_between(g, m - s, m + s, alpha=0.25)
    ax.set_xlabel({"timesteps": "environment steps", "wall_s": "wall-clock seconds"}.get(x, x))
    ax.set_ylabel({"ep_reward_mean": "episode return", "rotation_mean": "rotation per episode [rad]",
                   "ep_length_mean": "episode length [steps]"}.get(key, key))
    if title:
        ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp)
    return path


def table3(rows: dict[str, dict], budget: str) -> str:
    """Markdown table: label -> ``EvalResult.summary()``-like dict, with the training budget stated."""
    lines = ["| policy | Steps-to-Fall (of 400) | Cumulative Rotation [rad] | survived | budget |",
             "|---|---|---|---|---|"]
    for label, s in rows.items():
        lines.append(f"| {label} | {s['steps_to_fall_mean']:.1f} +- {s['steps_to_fall_std']:.1f} | "
                     f"{s['rotation_mean']:.2f} +- {s['rotation_std']:.2f} | {100 * s['survived']:.0f} % | {budget} |")
    return "\n".join(lines)
