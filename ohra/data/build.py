"""Build a grasp dataset from a recipe, and summarise a dataset directory.

``build(recipe, out)`` resolves the recipe's hands and objects, splits the objects into train and
test, and runs the synthesis pipeline (resumable, any backend); the manifest records the recipe,
the split, per-pair counts and core-hours. ``summary(out)`` / ``format_summary`` are what
``ohra data info`` prints.
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

from ohra.data.dataset import require_manifest
from ohra.data.manifest import object_keys
from ohra.data.recipe import Recipe, RecipeError


def build(recipe: Recipe | str | Path, out: str | Path | None = None, workers: int = 1, resume: bool = False,
          overwrite: bool = False, backend: str = "process", address: str | None = None, progress: bool = True,
          hands: list[str] | None = None) -> dict:
    """Synthesise the dataset ``recipe`` describes into ``out``; see
    :func:`ohra.synth.pipeline.synthesize` for the run options.

    Args:
        recipe: a :class:`Recipe` or the path of its YAML file.
        out: the dataset directory; None: ``out/<recipe name>`` under the working directory.
        workers: processes (``backend="process"``) or CPUs of a local Ray cluster; >= 1.
        resume: keep pairs whose shards are already complete.
        overwrite: replace a dataset or hand made with other settings or params (its shards are deleted).
        backend: ``"process"`` or ``"ray"`` (``address``: an existing cluster).
        progress: show a progress bar.
        hands: build only these of the recipe's hands (names as resolved; None: all). Hands differ
            in yield per CPU-second several-fold, so topping up one hand's count with extra seeds
            should not pay for the others; the same directory can later be completed with the rest
            (``resume``).

    Returns:
        The manifest written to ``out/manifest.json`` (recipe, object split, per-pair counts, core-hours).

    Raises:
        RecipeError: the recipe is missing or invalid; a name in ``hands`` is not one of its hands.
        HandNotFoundError: the recipe names an unknown hand.
        ParamsError, SpecError, ParseError: a hand's params or spec file is invalid (as in
            :func:`ohra.hands.get_hand`).
        ObjectError: an object cannot be loaded or is outside the graspable size range.
        DatasetError: ``out`` holds a manifest written with other settings or other params of a hand
            (without ``overwrite``), or a corrupt one.
        FolderInUseError: another process is building into ``out``.
        OhraError: ``out`` is a file; ``workers`` < 1; a hand with fewer than two fingers.
    """
    from ohra.synth.pipeline import synthesize

    r = recipe if isinstance(recipe, Recipe) else Recipe.load(recipe)
    every = r.resolve_coupled_hands()  # coupled hands keep their couplings
    hands = _select(every, hands, r)
    objects = r.resolve_objects()
    settings = r.synth_settings()
    split = r.split_objects(object_keys(objects))
    # every hand of the recipe, built here or not (--hands): ohra data info names the ones with no pairs yet
    header = {"recipe": r.to_dict(), "split": split, "recipe_hands": [h[0] for h in every]}
    return synthesize(hands, objects, Path(out) if out else Path("out") / r.name, settings, workers=workers, resume=resume,
                      progress=progress, overwrite=overwrite, backend=backend, address=address, header=header)


def _select(resolved: list[tuple], names: list[str] | None, r: Recipe) -> list[tuple]:
    if names is None:
        return resolved
    known = [h[0] for h in resolved]
    unknown = [n for n in names if n not in known]
    if unknown:
        raise RecipeError(f"{r.source or '<recipe>'}: hand(s) {', '.join(unknown)} not in the recipe (its hands: {', '.join(known)})")
    return [h for h in resolved if h[0] in set(names)]


_COUNTS = ("pairs", "candidates", "solved", "prefiltered", "sim_passed", "grasps", "grasps_test", "core_s", "cpu_s")


def summary(path: str | Path) -> dict:
    """Per-hand and total counts of a dataset directory, with core-hours and the object split."""
    return _summarise(Path(path), require_manifest(path))


def _summarise(path: Path, man: dict) -> dict:
    split = man.get("split") or {}
    test = set(split.get("test", []))
    planned = len(split.get("train", [])) + len(test)  # a recipe build makes every (hand, object) pair
    rows = []
    for hand, entry in man["hands"].items():
        sh = entry.get("shards", {})
        row = {"hand": hand, "pairs": len(sh)}
        for k in ("candidates", "solved", "prefiltered", "sim_passed", "grasps"):  # prefiltered: 0 in shards made before it was recorded
            row[k] = sum(s.get(f"n_{k}", 0) for s in sh.values())
        row["grasps_test"] = sum(s.get("n_grasps", 0) for key, s in sh.items() if key in test)
        row["core_s"] = sum(s.get("timing", {}).get("total_s", 0.0) for s in sh.values())
        row["cpu_s"] = sum(s.get("timing", {}).get("cpu_s", 0.0) for s in sh.values())
        row["no_convergence"] = sorted(k for k, s in sh.items() if s.get("diagnosis"))
        row["planned"] = planned or None  # None: not a recipe build, no plan to compare with
        rows.append(row)
    total = {k: sum(r[k] for r in rows) for k in _COUNTS}
    unbuilt = [h for h in man.get("recipe_hands", []) if h not in man["hands"]] if planned else []
    return {"path": str(path), "format": man.get("format"), "unbuilt": unbuilt, "planned": planned or None, "ohra_version": man.get("ohra_version"),
            "settings_digest": man.get("settings_digest"), "recipe": (man.get("recipe") or {}).get("name"),
            "core_hours": man.get("core_hours", total["core_s"] / 3600.0), "cpu_hours": total["cpu_s"] / 3600.0, "split": {"train": len(split.get("train", [])), "test": len(test)},
            "objects": len(_object_keys(man)), "rows": rows, "total": total}


def _object_keys(man: dict) -> set[str]:
    """Every object (shard key) a manifest holds, of any hand."""
    return {k for entry in man["hands"].values() for k in entry.get("shards", {})}


def combined_summary(paths: Sequence[str | Path]) -> dict:
    """Per-hand totals over several dataset directories (e.g. the seeds of one recipe), in the form of
    :func:`summary`: counts and hours add up; ``split`` counts the distinct object keys of all of them."""
    mans = [(Path(p), require_manifest(p)) for p in paths]
    parts = [_summarise(p, man) for p, man in mans]
    if len(parts) == 1:
        return parts[0]
    # one row per hand, unless a name stands for different params in different folders (e.g. a spec's base
    # form in one, its extended form in another): those rows stay apart, labelled by their params hash
    hashes: dict[str, set] = {}
    for _, man in mans:
        for hand, entry in man["hands"].items():
            hashes.setdefault(hand, set()).add(entry.get("params_hash"))
    rows: dict[str, dict] = {}
    for part, (_, man) in zip(parts, mans):
        for r in part["rows"]:
            label = r["hand"] if len(hashes[r["hand"]]) == 1 else f"{r['hand']} [{str(man['hands'][r['hand']].get('params_hash'))[:8]}]"
            acc = rows.setdefault(label, {"hand": label, **{k: 0 for k in _COUNTS}, "no_convergence": []})
            for k in _COUNTS:
                acc[k] += r[k]
            acc["no_convergence"] += [f"{Path(part['path']).name}/{k}" for k in r["no_convergence"]]
    split: dict[str, set] = {"train": set(), "test": set()}
    for _, man in mans:
        man_split = man.get("split") or {}
        for side in split:
            split[side].update(man_split.get(side, []))
    total = {k: sum(r[k] for r in rows.values()) for k in _COUNTS}

    def joined(key: str) -> str | None:
        vals = sorted({str(x[key]) for x in parts if x[key] is not None})
        return ", ".join(vals) if vals else None

    return {"path": f"{len(parts)} folders ({', '.join(Path(x['path']).name for x in parts)})",
            "format": joined("format"), "ohra_version": joined("ohra_version"), "settings_digest": joined("settings_digest"),
            "recipe": joined("recipe"), "core_hours": sum(x["core_hours"] for x in parts),
            "cpu_hours": sum(x["cpu_hours"] for x in parts),
            "split": {k: len(v) for k, v in split.items()},
            "objects": len(set().union(*(_object_keys(man) for _, man in mans))),
            "rows": list(rows.values()), "total": total,
            "folders": [x["path"] for x in parts]}


def format_summary(s: dict) -> str:
    """The table ``ohra data info`` prints."""
    lines = [f"{s['path']}: {s['format']}, ohra {s['ohra_version']}, settings {s['settings_digest']}"
             + (f", recipe {s['recipe']}" if s["recipe"] else "")
             + f", {s['core_hours']:.3f} core-hours (wall per shard; {s['cpu_hours']:.3f} CPU-hours), "
             + (f"objects {s['split']['train']} train / {s['split']['test']} test" if sum(s["split"].values())
                else f"{s['objects']} objects (no train/test split: not built from a recipe)")]
    head = f"{'hand':22s} {'pairs':>5s} {'solves':>7s} {'converged':>9s} {'sim pass':>8s} {'kept':>6s} {'kept/conv':>9s} {'test kept':>9s} {'kept/core-h':>11s} {'kept/CPU-h':>10s}"
    lines += [head, "-" * len(head)]
    for r in s["rows"] + [{"hand": "total", **s["total"], "no_convergence": []}]:
        rate = f"{r['grasps'] / r['solved']:.0%}" if r["solved"] else "-"
        per_h = f"{r['grasps'] / (r['core_s'] / 3600):.0f}" if r["core_s"] > 0 else "-"
        per_cpu = f"{r['grasps'] / (r['cpu_s'] / 3600):.0f}" if r.get("cpu_s", 0) > 0 else "-"
        lines.append(f"{r['hand']:22s} {r['pairs']:5d} {r['candidates']:7d} {r['solved']:9d} {r['sim_passed']:8d} {r['grasps']:6d} "
                     f"{rate:>9s} {r['grasps_test']:9d} {per_h:>11s} {per_cpu:>10s}")
        if r.get("prefiltered") and r["hand"] != "total":
            lines.append(f"  {r['prefiltered']} converged sank too deep into the object to simulate (max_penetration_m)")
        if r["no_convergence"]:
            lines.append(f"  nothing converged on: {', '.join(r['no_convergence'])}")
    unfinished = [f"{r['hand']} {r['pairs']} of {r['planned']}" for r in s["rows"] if r.get("planned") and r["pairs"] < r["planned"]]
    unfinished += [f"{h} 0 of {s['planned']}" for h in s.get("unbuilt", [])]  # a recipe hand not reached or left out
    if unfinished:  # an interrupted build looked like a small finished one
        lines.append(f"incomplete: {'; '.join(unfinished)} objects (the same build with --resume finishes it)")
    return "\n".join(lines)
