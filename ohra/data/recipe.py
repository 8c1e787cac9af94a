"""Dataset recipes: which hands, which objects, how many grasps, which split, seed and protocol.

A recipe is a YAML mapping (plain values only; unknown keys are errors naming the file and key)::

    name: leap-small                 # default output folder: out/<name>
    seed: 0
    hands:
      - leap_3333                    # a registered hand or LEAP variant
      - {pattern: "leap_*", digit_sum: [10, 11]}   # glob over hand names; LEAP digit-sum range
      - {params: my_hand.json}       # a params file (or just my_hand.json), named my_hand
      - {spec: my_hand.yaml, form: base}           # a hand spec, parsed (and fitted) on load; form defaults to
                                                   # extended (a bare my_hand.yaml too), unlike synth --hand (base)
    objects:
      - builtin                      # all built-ins, or builtin:NAME
      - {path: meshes/mug.obj}       # a folder, a mesh or an object URDF
      - {glob: "@objects/ycb/*Can", scale: 1.0}     # @objects/ = the shared object root (OHRA_OBJECTS_ROOT)
      - {procedural: superquadric, count: 20, seed: 0}
    grasps_per_pair: 16              # solver starts per (hand, object) pair
    cap: 8                           # stop a pair once this many grasps are kept
    split: {test_fraction: 0.25, seed: 0}          # or {test: [name, ...]}
    protocol: reference              # reference | strict | isaac-step | isaac-drive, or {preset: ..., <Protocol field>: value}
    robustness: {trials: 2}          # RobustnessSettings fields
    filter: true

Relative paths are relative to the recipe file; ``@objects/`` starts a path in the shared object
root (:func:`ohra.paths.objects_root`). The LEAP digit-sum rule keeps variants whose four
digits (links kept on thumb, index, middle, little) add up to a value in the range: a cheap way to
ask for hands of similar complexity.
"""

from __future__ import annotations

import fnmatch
import glob
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ohra.errors import OhraError

RECIPE_KEYS = ("name", "seed", "hands", "objects", "grasps_per_pair", "cap", "split", "protocol", "robustness", "filter")


class RecipeError(OhraError, ValueError):
    """A dataset recipe is malformed or names hands or objects that do not exist."""


@dataclass(frozen=True)
class Recipe:
    """A parsed recipe (see the module doc); ``source`` resolves relative paths."""

    name: str
    hands: list
    objects: list
    seed: int = 0
    grasps_per_pair: int = 8
    cap: int | None = None
    split: dict = field(default_factory=dict)
    protocol: Any = "reference"
    robustness: dict = field(default_factory=dict)
    filter: bool = True
    source: Path | None = None

    @classmethod
    def from_dict(cls, d: Any, source: str | Path | None = None) -> "Recipe":
        where = str(source or "<recipe>")
        if not isinstance(d, dict):
            raise RecipeError(f"{where}: a recipe is a mapping with keys {', '.join(RECIPE_KEYS)}")
        unknown = [k for k in d if k not in RECIPE_KEYS]
        if unknown:
            raise RecipeError(f"{where}: unknown key(s) {', '.join(map(str, unknown))}; known: {', '.join(RECIPE_KEYS)}")
        for k in ("hands", "objects"):
            if not isinstance(d.get(k), list) or not d[k]:
                raise RecipeError(f"{where}: '{k}' must be a non-empty list")
        for k in ("seed", "grasps_per_pair"):
            if k in d and (not isinstance(d[k], int) or isinstance(d[k], bool) or d[k] < (0 if k == "seed" else 1)):
                raise RecipeError(f"{where}: '{k}' must be an integer >= {0 if k == 'seed' else 1}, got {d[k]!r}")
        if d.get("cap") is not None and (not isinstance(d["cap"], int) or d["cap"] < 1):
            raise RecipeError(f"{where}: 'cap' must be an integer >= 1 or null, got {d['cap']!r}")
        name = str(d["name"]) if d.get("name") not in (None, "") else None  # a number is a name; empty: the file's stem
        if name is not None and (any(c in name for c in "/\\") or name in (".", "..")):
            raise RecipeError(f"{where}: 'name' is a folder name under out/ (no '/' or '..'), got {d['name']!r}")
        for i, o in enumerate(d["objects"]):
            if isinstance(o, dict) and "procedural" in o:
                for k, least in (("count", 1), ("seed", 0)):
                    v = o.get(k, least)
                    if not isinstance(v, int) or isinstance(v, bool) or v < least:
                        raise RecipeError(f"{where}: objects[{i}]: '{k}' must be an integer >= {least}, got {v!r}")
        src = Path(source) if source else None
        return cls(name=name or (src.stem if src else "dataset"), hands=d["hands"], objects=d["objects"],
                   seed=d.get("seed", 0), grasps_per_pair=d.get("grasps_per_pair", 8), cap=d.get("cap"),
                   split=d.get("split") or {}, protocol=d.get("protocol", "reference"), robustness=d.get("robustness") or {},
                   filter=bool(d.get("filter", True)), source=src)

    @classmethod
    def load(cls, path: str | Path) -> "Recipe":
        path = Path(path)
        if path.is_dir():
            raise RecipeError(f"{path} is a folder; give the recipe's YAML file")
        if not path.is_file():
            raise RecipeError(f"recipe not found: {path}")
        try:
            d = yaml.safe_load(path.read_text())
        except UnicodeDecodeError:
            raise RecipeError(f"{path}: not a text file (a recipe is YAML)") from None
        except yaml.YAMLError as exc:
            raise RecipeError(f"{path}: not valid YAML ({str(exc).splitlines()[0]})") from None
        return cls.from_dict(d, path)

    def with_seed(self, seed: int) -> "Recipe":
        """The same recipe with another seed (solver starts, procedural objects keep their own seeds)."""
        if not isinstance(seed, int) or isinstance(seed, bool) or seed < 0:
            raise RecipeError(f"{self.source or '<recipe>'}: seed must be an integer >= 0, got {seed!r}")
        split = dict(self.split)
        if "test_fraction" in split:
            split.setdefault("seed", self.seed)  # the object split must not move with the data seed
        return replace(self, seed=seed, split=split)

    def to_dict(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self) if f.name != "source"}

    # -- resolution ----------------------------------------------------------------------------------
    def _path(self, p: str) -> Path:
        if str(p).startswith("@objects/"):  # the shared object root (ohra.paths.objects_root)
            from ohra.paths import objects_root

            return objects_root() / str(p)[len("@objects/"):]
        q = Path(p).expanduser()
        return q if q.is_absolute() or self.source is None else self.source.parent / q

    def resolve_hands(self) -> list[tuple[str, Any]]:
        """(name, params) of every hand, in recipe order, each once."""
        return [(n, e[1]) for n, e in self._entries().items()]

    def resolve_coupled_hands(self) -> list[tuple[str, Any, tuple]]:
        """(name, params, couplings) of every hand, in recipe order, each once: a coupled hand's couplings
        (URDF ``<mimic>`` tags, a spec's ``couplings``, a params JSON's ``"couplings"`` key), which synthesis
        needs as equality rows; empty for an uncoupled hand."""
        return [(n, e[1], tuple(e[2]) if len(e) > 2 else _couplings(n)) for n, e in self._entries().items()]

    def _entries(self) -> dict[str, tuple]:
        out: dict[str, tuple] = {}
        for i, h in enumerate(self.hands):
            for entry in self._hand(h, f"{self.source or '<recipe>'}: hands[{i}]"):
                out.setdefault(entry[0], entry)
        return out

    def _hand(self, h: Any, where: str) -> list[tuple[str, Any]]:
        from ohra.hands import get_hand, list_hands

        if isinstance(h, str) and h.endswith(".json"):  # a file, like the objects: relative to the recipe
            h = {"params": h}
        elif isinstance(h, str) and h.endswith((".yaml", ".yml")):
            h = {"spec": h}
        if isinstance(h, str) and not any(c in h for c in "*?["):
            return [(h, get_hand(h))]
        if isinstance(h, str):
            h = {"pattern": h}
        if not isinstance(h, dict) or len({"pattern", "params", "spec"} & set(h)) != 1:
            raise RecipeError(f"{where}: a hand is a name, or a mapping with one of 'pattern', 'params', 'spec'")
        if "params" in h:
            from ohra.canonical.couplings import read_couplings

            p = self._path(h["params"])
            return [(p.stem, get_hand(str(p)), read_couplings(p))]
        if "spec" in h:
            return [_hand_from_spec(self._path(h["spec"]), h.get("form", "extended"), where)]
        names = [n for n in list_hands(include_variants=True) if fnmatch.fnmatchcase(n, h["pattern"])]
        if "digit_sum" in h:
            lo, hi = _range(h["digit_sum"], where + ".digit_sum")
            names = [n for n in names if n.startswith("leap_") and n[5:].isdigit() and lo <= sum(map(int, n[5:])) <= hi]
        hands = [(n, get_hand(n)) for n in names]
        hands = [(n, p) for n, p in hands if p.num_fingers >= 2]  # one-finger variants cannot grasp
        if not hands:
            raise RecipeError(f"{where}: pattern {h['pattern']!r} matches no hand with two or more fingers")
        return hands

    def resolve_objects(self) -> list:
        """Every object, in recipe order."""
        from ohra.objects.procedural import procedural_objects
        from ohra.objects.resolve import resolve_objects

        out = []
        for i, o in enumerate(self.objects):
            where = f"{self.source or '<recipe>'}: objects[{i}]"
            if isinstance(o, str):
                out += resolve_objects([o if o.startswith(("builtin", "procedural:")) else str(self._path(o))])
            elif isinstance(o, dict) and "procedural" in o:
                out += procedural_objects(o["procedural"], int(o.get("count", 1)), int(o.get("seed", 0)))
            elif isinstance(o, dict) and ("path" in o or "glob" in o):
                paths = [self._path(o["path"])] if "path" in o else sorted(Path(p) for p in glob.glob(str(self._path(o["glob"]))))
                if not paths:
                    raise RecipeError(f"{where}: glob {o['glob']!r} matches nothing")
                out += resolve_objects([str(p) for p in paths], scale=o.get("scale"))
            else:
                raise RecipeError(f"{where}: an object is a spec string or a mapping with 'path', 'glob' or 'procedural'")
        return out

    def synth_settings(self):
        """The :class:`~ohra.synth.pipeline.SynthSettings` of this recipe."""
        from ohra.sim import Protocol
        from ohra.synth.pipeline import SynthSettings
        from ohra.synth.robust import RobustnessSettings

        prot = self.protocol if isinstance(self.protocol, dict) else {"preset": self.protocol}
        try:
            protocol = replace(Protocol.preset(prot.get("preset", "reference")), **{k: v for k, v in prot.items() if k != "preset"})
            robust = RobustnessSettings(**self.robustness)
        except (TypeError, ValueError) as exc:
            raise RecipeError(f"{self.source or '<recipe>'}: protocol/robustness: {exc}") from None
        return SynthSettings(grasps_per_object=self.grasps_per_pair, seed=self.seed, filter=self.filter, cap=self.cap,
                             robustness=robust, protocol=protocol)

    def split_objects(self, keys: list[str]) -> dict:
        """{"train": [...], "test": [...]} over object keys: an explicit ``test`` list, or a seeded
        ``test_fraction`` (rounded, at least one test object when the fraction is > 0)."""
        sp = self.split
        unknown = set(sp) - {"test", "test_fraction", "seed"}
        if unknown:
            raise RecipeError(f"{self.source or '<recipe>'}: split: unknown key(s) {', '.join(sorted(unknown))}")
        if "test" in sp:
            missing = [k for k in sp["test"] if k not in keys]
            if missing:
                raise RecipeError(f"{self.source or '<recipe>'}: split.test names unknown object(s) {', '.join(missing)}")
            test = set(sp["test"])
        else:
            frac = float(sp.get("test_fraction", 0.0))
            if not 0.0 <= frac < 1.0:
                raise RecipeError(f"{self.source or '<recipe>'}: split.test_fraction must be in [0, 1), got {frac}")
            n = max(int(round(frac * len(keys))), 1 if frac > 0 else 0)
            order = np.random.default_rng(int(sp.get("seed", self.seed))).permutation(len(keys))
            test = {keys[i] for i in order[:n]}
        return {"train": [k for k in keys if k not in test], "test": [k for k in keys if k in test], **sp}


def _range(v: Any, where: str) -> tuple[int, int]:
    if isinstance(v, int):
        return v, v
    if isinstance(v, list) and len(v) == 2 and all(isinstance(x, int) for x in v):
        return v[0], v[1]
    raise RecipeError(f"{where}: expected an integer or [min, max], got {v!r}")


def _hand_from_spec(path: Path, form: str, where: str) -> tuple[str, Any]:
    from ohra.original.parse import parse
    from ohra.original.spec import load_spec

    if not path.is_file():
        raise RecipeError(f"{where}: hand spec not found: {path}")
    sp = load_spec(path)
    res = parse(sp, form, fit_params=True)
    return sp.name, res.params, res.couplings


def _couplings(name: str) -> tuple:
    """Couplings of a registered hand or LEAP variant (none for a variant)."""
    from ohra.hands import get_couplings

    return tuple(get_couplings(name))
