"""The table of committed datasets in ``datasets/README.md``, computed from their manifests.

One row per dataset folder: the command that made it (recipe, seed, and ``--hands`` when only some
of the recipe's hands were built), its status (pairs done of the recipe's, per selected hand),
robust grasps per hand and CPU-hours; then per-recipe totals per hand. The table sits between the
``<!-- dataset-table -->`` markers of the README and is replaced in place.

Run: python benchmarks/dataset_table.py [--root datasets] [--check] [--exclude FOLDER ...]
  --check: exit 1 when the README's table differs from the manifests (nothing written)
"""

from __future__ import annotations

import re
import sys
from collections import defaultdict
from functools import lru_cache
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import run_script, script_parser  # noqa: E402
from ohra.data.build import summary  # noqa: E402
from ohra.data.dataset import read_manifest
from ohra.data.recipe import Recipe

ROOT = Path(__file__).resolve().parents[1]
START, END = "<!-- dataset-table -->", "<!-- /dataset-table -->"


def _seed_key(path: Path) -> tuple:
    m = re.search(r"_s(\d+)$", path.name)
    return (path.name[: m.start()] if m else path.name, int(m.group(1)) if m else -1)


def _kept(per_hand: dict[str, int]) -> str:
    """Per-hand grasp counts, or their total when there are too many hands to list."""
    if len(per_hand) <= 4:
        return ", ".join(f"{h} {n:,}" for h, n in per_hand.items())
    return f"{sum(per_hand.values()):,} over {len(per_hand)} hands"


@lru_cache(maxsize=None)
def _recipe(name: str) -> tuple[Recipe, tuple[str, ...], int]:
    """(recipe, its hand names, its object count), resolved once per recipe."""
    recipe = Recipe.load(ROOT / "recipes" / f"{name}.yaml")
    return recipe, tuple(h for h, _ in recipe.resolve_hands()), len(recipe.resolve_objects())


def rows(root: Path, exclude: tuple[str, ...] = ()) -> tuple[list[str], list[str]]:
    """(dataset rows, total rows) of the markdown table; ``exclude``: folder names left out."""
    out, totals = [], defaultdict(lambda: defaultdict(int))
    cpu = defaultdict(float)
    for d in sorted((p for p in root.iterdir() if (p / "manifest.json").is_file() and p.name not in exclude), key=_seed_key):
        man = read_manifest(d / "manifest.json")
        s = summary(d)
        name, seed = man["recipe"]["name"], man["settings"]["seed"]
        recipe, hands_all, n_obj = _recipe(name)
        built = list(man["hands"])
        some_hands = set(built) != set(hands_all)
        cmd = f"ohra data build recipes/{name}.yaml" + ("" if seed == recipe.seed else f" --seed {seed}") + \
              f" --out {root.name}/{d.name} --resume"
        per = {r["hand"]: r["grasps"] for r in s["rows"]}
        done, want = s["total"]["pairs"], n_obj * len(built)
        status = "complete" if done == want else f"partial: {done} of {want} pairs"
        packed = sum("pack" in sh for e in man["hands"].values() for sh in e.get("shards", {}).values())
        if packed:
            status += ", packed" if packed == done else f", {packed} pairs packed"
        if some_hands:
            cmd += " --hands " + " ".join(built) if len(built) <= 4 else f" (--hands: {len(built)} of {len(hands_all)} hands)"
            status += f" ({len(built)} of {len(hands_all)} hands)"
        out.append(f"| `{d.name}` | `{cmd}` | {status} | {_kept(per)} | {s['cpu_hours']:.2f} |")
        for h, n in per.items():
            totals[name][h] += n
        cpu[name] += s["cpu_hours"]
    tot_rows = [f"| **{name}, all folders** | `ohra data info {root.name}/{name}_s*` | | {_kept(per)} | {cpu[name]:.2f} |"
                for name, per in totals.items()]
    return out, tot_rows, totals


def per_hand_lines(totals: dict[str, dict[str, int]]) -> list[str]:
    """For recipes with too many hands for the table: every hand's robust grasps over all folders,
    fewest first, and the recipe's hands that have none (built or not), named."""
    out = []
    for name, per in totals.items():
        if len(per) <= 4:
            continue
        _, hands_all, _ = _recipe(name)
        none = sorted({h for h in hands_all if not per.get(h)})
        listed = sorted(((n, h) for h, n in per.items() if n), key=lambda t: (t[0], t[1]))
        out += ["", f"**{name}, robust grasps per hand over all folders** (fewest first): "
                + ", ".join(f"{h} {n:,}" for n, h in listed) + ". Hands of the recipe without a grasp: "
                + (", ".join(none) if none else "none") + "."]
    return out


def table(root: Path, exclude: tuple[str, ...] = ()) -> str:
    data, tot, totals = rows(root, exclude)
    head = ["| folder | made by | status | robust grasps | CPU-hours |", "|---|---|---|---|---|"]
    return "\n".join([START, *head, *data, *tot, *per_hand_lines(totals), END])


def main() -> int:
    ap = script_parser(__doc__, __file__)
    ap.add_argument("--root", type=Path, default=ROOT / "datasets")
    ap.add_argument("--check", action="store_true")
    ap.add_argument("--exclude", nargs="+", default=[], help="folders to leave out (e.g. one still being built)")
    args = ap.parse_args()
    readme = args.root / "README.md"
    text = readme.read_text()
    if START not in text or END not in text:
        print(f"{readme}: no {START} ... {END} markers", file=sys.stderr)
        return 2
    tab = table(args.root, tuple(args.exclude))
    new = text[: text.index(START)] + tab + text[text.index(END) + len(END):]
    if args.check:
        return 0 if new == text else 1
    readme.write_text(new)
    print(tab)
    return 0


if __name__ == "__main__":
    run_script(main, __file__)
