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
      - {spec: my_hand.yaml, name: my_hand_ext}    # name: the hand's name in the dataset (default: the spec's
                                                   # name, a params file's stem), e.g. both forms of one spec
    objects:
      - builtin                      # all built-ins, or builtin:NAME
      - {path: meshes/mug.obj}       # a folder, a mesh or an object URDF
      - {glob: "@objects/ycb/*Can", scale: 1.0}     # @objects/ = the shared object root (OHRA_OBJECTS_ROOT)
      - {path: meshes/cup.obj, body: vhacd}        # the body to grasp and simulate it as: auto (default), hull,
                                                   # provided, vhacd (ohra.objects.model.BODY_CHOICES)
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
import re
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ohra.errors import OhraError, SpecError
from ohra.objects.model import BODY_CHOICES

RECIPE_KEYS = ("name", "seed", "hands", "objects", "grasps_per_pair", "cap", "split", "protocol", "robustness", "filter")


class RecipeError(OhraError, ValueError):
    """A dataset recipe is malformed or names hands or objects that do not exist."""


def _checked_fields(defaults: Any, given: dict, where: str) -> dict:
    """``given`` overrides of the dataclass instance ``defaults``, each a known field of the default's kind (a
    number, a whole number, true/false, text): a typo or a wrong type is named with its key, not left to fail
    inside the dataclass (``'<' not supported``, ``unexpected keyword argument``)."""
    known = {f.name: getattr(defaults, f.name) for f in fields(defaults)}
    unknown = sorted(set(given) - set(known))
    if unknown:
        raise RecipeError(f"{where}: unknown key(s) {unknown}; known: {', '.join(known)}")
    for k, v in given.items():
        d = known[k]
        if isinstance(d, bool):
            ok, what = isinstance(v, bool), "true or false"
        elif isinstance(d, int):
            ok, what = isinstance(v, int) and not isinstance(v, bool), "a whole number"
        elif isinstance(d, float):
            ok = isinstance(v, (int, float)) and not isinstance(v, bool) and bool(np.isfinite(v))
            what = "a finite number"
        elif isinstance(d, str):
            ok, what = isinstance(v, str), "text"
        else:
            continue  # tuples and optional settings: the dataclass checks them
        if not ok:
            raise RecipeError(f"{where}.{k} must be {what}, got {v!r}")
    return given


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
        if d.get("cap") is not None and (not isinstance(d["cap"], int) or isinstance(d["cap"], bool) or d["cap"] < 1):
            raise RecipeError(f"{where}: 'cap' must be an integer >= 1 or null, got {d['cap']!r}")
        if "filter" in d and not isinstance(d["filter"], bool):
            raise RecipeError(f"{where}: 'filter' must be true or false, got {d['filter']!r}")
        if d.get("robustness") is not None and not isinstance(d["robustness"], dict):  # `false` read as "the defaults"
            raise RecipeError(f"{where}: 'robustness' is a mapping of RobustnessSettings fields, e.g. {{trials: 2}} "
                              f"({{trials: 0}}: no robustness trials), got {d['robustness']!r}")
        for i, h in enumerate(d["hands"]):
            _check_entry(h, HAND_KEYS, f"{where}: hands[{i}]")
        for i, o in enumerate(d["objects"]):
            _check_entry(o, OBJECT_KEYS, f"{where}: objects[{i}]")
        _check_split(d.get("split"), where)
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
        from ohra.original.spec_yaml import UniqueKeyLoader

        try:
            d = yaml.load(path.read_text(), Loader=UniqueKeyLoader)
        except SpecError as exc:  # a key given twice
            raise RecipeError(f"{path}: {exc}") from None
        except UnicodeDecodeError:
            raise RecipeError(f"{path}: not a text file (a recipe is YAML)") from None
        except yaml.YAMLError as exc:
            mark = getattr(exc, "problem_mark", None)
            at = f" at line {mark.line + 1} column {mark.column + 1}" if mark is not None else ""
            raise RecipeError(f"{path}: not valid YAML{at} ({str(exc).splitlines()[0]})") from None
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
        """Hand name -> (name, params[, couplings]); the same hand reached twice (a name and a pattern) counts
        once, two different hands under one name (two files called grip.json) are refused."""
        from ohra.synth.pipeline import params_hash  # the manifest's own test of "the same hand"

        out: dict[str, tuple] = {}
        first: dict[str, int] = {}
        for i, h in enumerate(self.hands):
            where = f"{self.source or '<recipe>'}: hands[{i}]"
            with _at(where):
                entries = self._hand(h, where)
            for entry in entries:
                name = entry[0]
                if name in out:
                    if params_hash(out[name][1]) != params_hash(entry[1]):
                        raise RecipeError(f"{self.source or '<recipe>'}: hands[{first[name]}] and hands[{i}] are two "
                                          f"different hands named {name!r} (a dataset keys its hands by name): give one "
                                          f"its own name in its spec or params entry, e.g. name: {name}_2")
                    continue
                out[name], first[name] = entry, i
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
            name, params = h.get("name", p.stem), get_hand(str(p))
            _check_not_a_registered_name(name, params, where)
            return [(name, params, read_couplings(p))]
        if "spec" in h:
            name, params, couplings = _hand_from_spec(self._path(h["spec"]), h.get("form", "extended"), where)
            _check_not_a_registered_name(h.get("name", name), params, where)
            return [(h.get("name", name), params, couplings)]
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
        out = []
        for i, o in enumerate(self.objects):
            where = f"{self.source or '<recipe>'}: objects[{i}]"
            with _at(where):
                out += self._object(o, where)
        return out

    def _object(self, o: Any, where: str) -> list:
        from ohra.objects.procedural import procedural_objects
        from ohra.objects.resolve import resolve_objects

        if isinstance(o, str):
            return resolve_objects([o if o.startswith(("builtin", "procedural:")) else str(self._path(o))])
        if isinstance(o, dict) and "procedural" in o:
            return procedural_objects(o["procedural"], int(o.get("count", 1)), int(o.get("seed", 0)))
        if isinstance(o, dict) and ("path" in o or "glob" in o):
            paths = [self._path(o["path"])] if "path" in o else sorted(Path(p) for p in glob.glob(str(self._path(o["glob"]))))
            if not paths:
                raise RecipeError(f"{where}: glob {o['glob']!r} matches nothing")
            return resolve_objects([str(p) for p in paths], scale=o.get("scale"), body=o.get("body", "auto"))
        raise RecipeError(f"{where}: an object is a spec string or a mapping with 'path', 'glob' or 'procedural'")

    def synth_settings(self):
        """The :class:`~ohra.synth.pipeline.SynthSettings` of this recipe."""
        from ohra.sim import Protocol
        from ohra.synth.pipeline import SynthSettings
        from ohra.synth.robust import RobustnessSettings

        src = self.source or "<recipe>"
        prot = self.protocol if isinstance(self.protocol, dict) else {"preset": self.protocol}
        try:
            base = Protocol.preset(prot.get("preset", "reference"))
        except ValueError as exc:
            raise RecipeError(f"{src}: protocol.preset: {exc}") from None
        overrides = _checked_fields(base, {k: v for k, v in prot.items() if k != "preset"}, f"{src}: protocol")
        try:
            protocol = replace(base, **overrides)
        except (TypeError, ValueError, OhraError) as exc:  # a value the dataclass itself refuses
            raise RecipeError(f"{src}: protocol: {exc}") from None
        overrides = _checked_fields(RobustnessSettings(), dict(self.robustness), f"{src}: robustness")
        try:
            robust = RobustnessSettings(**overrides)
        except (TypeError, ValueError, OhraError) as exc:
            raise RecipeError(f"{src}: robustness: {exc}") from None
        return SynthSettings(grasps_per_object=self.grasps_per_pair, seed=self.seed, filter=self.filter, cap=self.cap,
                             robustness=robust, protocol=protocol)

    def split_objects(self, keys: list[str]) -> dict:
        """{"train": [...], "test": [...]} over object keys: an explicit ``test`` list, or a seeded
        ``test_fraction`` (rounded, at least one test object when the fraction is > 0)."""
        sp = self.split
        unknown = set(sp) - {"test", "test_fraction", "seed"}
        if unknown:
            raise RecipeError(f"{self.source or '<recipe>'}: split: unknown key(s) {', '.join(sorted(unknown))}")
        where = self.source or "<recipe>"
        if "test" in sp:
            names = [sp["test"]] if isinstance(sp["test"], str) else list(sp["test"])
            missing = [k for k in names if k not in keys]
            if missing:
                raise RecipeError(f"{where}: split.test names unknown object(s) {', '.join(map(str, missing))}; the "
                                  f"recipe's objects are {', '.join(keys)}")
            test = set(names)
        else:
            frac = float(sp.get("test_fraction", 0.0))
            if not 0.0 <= frac < 1.0:
                raise RecipeError(f"{self.source or '<recipe>'}: split.test_fraction must be in [0, 1), got {frac}")
            n = max(int(round(frac * len(keys))), 1 if frac > 0 else 0)
            order = np.random.default_rng(int(sp.get("seed", self.seed))).permutation(len(keys))
            test = {keys[i] for i in order[:n]}
        if keys and not set(keys) - test:
            raise RecipeError(f"{where}: the split leaves no training object (all {len(keys)} are test objects): "
                              "name fewer in split.test or lower split.test_fraction")
        given = {**sp, "test": [sp["test"]]} if isinstance(sp.get("test"), str) else sp
        return {"train": [k for k in keys if k not in test], "test": [k for k in keys if k in test], **given}


HAND_KEYS = {"pattern": ("pattern", "digit_sum"), "params": ("params", "name"), "spec": ("spec", "form", "name")}
OBJECT_KEYS = {"procedural": ("procedural", "count", "seed"), "path": ("path", "scale", "body"), "glob": ("glob", "scale", "body")}


def _check_entry(e: Any, kinds: dict[str, tuple[str, ...]], where: str) -> None:
    """A hand or object mapping names exactly one kind and only that kind's keys, with values of the right type."""
    if not isinstance(e, dict):
        return  # a plain string; resolved (and checked) on use
    kind = [k for k in kinds if k in e]
    if len(kind) != 1:
        raise RecipeError(f"{where}: a mapping needs exactly one of {', '.join(kinds)}, got keys {', '.join(map(str, e))}")
    allowed = kinds[kind[0]]
    unknown = [k for k in e if k not in allowed]
    if unknown:
        raise RecipeError(f"{where}: unknown key(s) {', '.join(map(str, unknown))} for a '{kind[0]}' entry; known: "
                          f"{', '.join(allowed)}")
    for k in ("pattern", "params", "spec", "path", "glob", "procedural"):
        if k in e and not isinstance(e[k], str):
            raise RecipeError(f"{where}: '{k}' must be a string, got {e[k]!r}")
    if "name" in e and (not isinstance(e["name"], str) or not re.fullmatch(r"[A-Za-z0-9_][A-Za-z0-9_.-]*", e["name"])
                        or e["name"] == "manifest.json"):
        raise RecipeError(f"{where}: 'name' is the hand's folder name in the dataset (letters, digits, '_', '.', '-', not "
                          f"starting with '.' or '-'), got {e['name']!r}")
    if "form" in e and e["form"] not in ("base", "extended"):
        raise RecipeError(f"{where}: 'form' must be base or extended, got {e['form']!r}")
    if "scale" in e and e["scale"] is not None and (isinstance(e["scale"], bool) or not isinstance(e["scale"], (int, float))
                                                    or not np.isfinite(e["scale"]) or e["scale"] <= 0):
        raise RecipeError(f"{where}: 'scale' must be a number > 0, got {e['scale']!r}")
    if "body" in e and e["body"] not in BODY_CHOICES:
        raise RecipeError(f"{where}: 'body' must be one of {', '.join(BODY_CHOICES)}, got {e['body']!r}")
    if "digit_sum" in e:
        lo, hi = _range(e["digit_sum"], where + ".digit_sum")
        if lo < 0 or hi > 12:  # four digits 0-3
            raise RecipeError(f"{where}.digit_sum: a LEAP variant's digit sum lies in 0..12 (leap_ABCD, digits 0-3), "
                              f"got {e['digit_sum']!r}")
        if not str(e.get("pattern", "")).startswith("leap_"):
            raise RecipeError(f"{where}.digit_sum: applies to LEAP variants only (pattern 'leap_*'), got pattern "
                              f"{e.get('pattern')!r}")


def _check_split(sp: Any, where: str) -> None:
    if sp is None:
        return
    if not isinstance(sp, dict):
        raise RecipeError(f"{where}: 'split' is a mapping: {{test: [name, ...]}} or {{test_fraction: 0.25, seed: 0}}, "
                          f"got {sp!r}")
    unknown = set(sp) - {"test", "test_fraction", "seed"}
    if unknown:
        raise RecipeError(f"{where}: split: unknown key(s) {', '.join(sorted(map(str, unknown)))}; known: test, "
                          "test_fraction, seed")
    if "test" in sp and not (isinstance(sp["test"], str) or (isinstance(sp["test"], list)
                                                            and all(isinstance(x, str) for x in sp["test"]))):
        raise RecipeError(f"{where}: split.test must be an object name or a list of them, got {sp['test']!r}")
    f = sp.get("test_fraction", 0.0)
    if isinstance(f, bool) or not isinstance(f, (int, float)) or not 0.0 <= f < 1.0:
        raise RecipeError(f"{where}: split.test_fraction must be a number in [0, 1), got {f!r}")
    seed = sp.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise RecipeError(f"{where}: split.seed must be an integer >= 0, got {seed!r}")


def _range(v: Any, where: str) -> tuple[int, int]:
    if isinstance(v, int) and not isinstance(v, bool):
        return v, v
    if isinstance(v, list) and len(v) == 2 and all(isinstance(x, int) and not isinstance(x, bool) for x in v):
        if v[0] > v[1]:
            raise RecipeError(f"{where}: [min, max] with min > max: {v!r}")
        return v[0], v[1]
    raise RecipeError(f"{where}: expected an integer or [min, max], got {v!r}")


def _check_not_a_registered_name(name: str, params: Any, where: str) -> None:
    """Refuse a file's hand under a registered hand's name unless it is that hand (in one of its forms): the dataset
    keys hands by name, and every later use of the name (ohra eval --hand, rotation, a model's training hands) would
    read the registered hand."""
    from ohra.hands import get_hand
    from ohra.hands.registry import registered_forms, registered_hands

    if name not in registered_hands():
        return
    for form in registered_forms(name):
        theirs = get_hand(name, form)  # a fresh fit of the registered spec lands within ~0.5 mm of it (BLAS builds)
        if type(theirs) is type(params) and np.allclose(theirs.to_vector(), params.to_vector(), atol=1e-3):
            return
    raise RecipeError(f"{where}: the hand is named {name!r}, a registered hand, but holds other parameters; give it "
                      f"its own name (name: my_{name}): a dataset keys its hands by name, and the name would read the "
                      "registered hand everywhere else")


@contextmanager
def _at(where: str) -> Iterator[None]:
    """Prefix an ohra error raised while resolving one recipe entry with that entry's place (``file: hands[2]``),
    keeping its type: an unknown hand name or a missing mesh is otherwise named without the recipe line it came
    from."""
    try:
        yield
    except OhraError as exc:
        if str(exc).startswith(where):
            raise
        try:
            new = type(exc)(f"{where}: {exc}")
        except TypeError:  # an error class with its own constructor
            new = RecipeError(f"{where}: {exc}")
        raise new from exc


def _hand_from_spec(path: Path, form: str, where: str) -> tuple[str, Any, Any]:
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
