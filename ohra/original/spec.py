"""HandSpec: the minimal manual input that brings an original hand into the canonical form.

A spec is a small YAML file (the registered hands' specs live in ``ohra/hands/specs/<name>.yaml``)::

    name: shadow_hand_right                  # registry name (default: the file stem)
    urdf: shadow_hand/shadow_hand_right.urdf  # original URDF (.urdf / .xacro), relative to the
                                              # hand-assets root (ohra.paths.hands_root()) or absolute
    palm_origin:                              # canonical palm frame in the original root frame
      xyz: [0.01, 0.0, 0.247]                 #   metres
      rpy: [0.0, 0.0, 0.0]                    #   fixed-axis x-y-z radians (also: a flat list of 6)
    joints:                                   # canonical slot -> original joint, shared by all forms
      thumb_joint1: {joint: THJ5, sign: -1}   #   q_canon = sign * q_orig + offset
      index_joint2: FFJ3                      #   shorthand for {joint: FFJ3, sign: 1, offset: 0}
      index_joint4: {joint: FFJ1, offset: 0.785}
    forms:                                    # the forms this hand is registered in
      base:                                   #   per-form changes to the shared mapping
        joints: {index_joint1: null}          #   null removes a slot from this form
        fixed: {index_joint1: -0.0873}        #   slots frozen at a value (limits [v, v])
      extended: {}
    overrides:                                # values that cannot be measured from the URDF
      - {form: base, key: finger_radius, value: 0.0087, reason: "why it cannot be measured"}
      - {key: "finger_lengths[0][2]", value: 0.03, reason: "..."}   # indexed key; form omitted = all
    fit: {samples: 96, seed: 0}               # optional least-squares fit settings

Canonical slots are the 22 names of :data:`ohra.canonical.params.JOINT_NAMES`. Each original joint drives at
most one slot per form (a duplicate is an error), a slot is either mapped or fixed, and every
named original joint must be a movable joint of the URDF (checked by :meth:`HandSpec.check_joints`).
Malformed specs raise :class:`ohra.SpecError` naming the file and the key.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import yaml

from ohra.original.action import ActionMap, SlotMap
from ohra.errors import SpecError
from ohra.canonical.params import JOINT_INDEX, JOINT_NAMES
from ohra.paths import hands_root

FORMS = ("base", "extended")
_KEY_RE = re.compile(r"^([a-z_]+)((?:\[\d+\])*)$")


@dataclass(frozen=True)
class Override:
    """A value set by hand after parsing: ``key`` (optionally indexed, e.g. ``finger_lengths[0][2]``)."""

    key: str
    value: Any
    reason: str
    form: str | None = None  # None: every form that has the key

    @property
    def name(self) -> str:
        return _KEY_RE.match(self.key).group(1)  # type: ignore[union-attr]

    @property
    def index(self) -> tuple[int, ...]:
        return tuple(int(i) for i in re.findall(r"\[(\d+)\]", self.key))


@dataclass(frozen=True)
class FormSpec:
    """The mapping of one form: slots driven by original joints, and frozen slots."""

    slots: dict[str, SlotMap]
    fixed: dict[str, float]


@dataclass
class HandSpec:
    name: str
    urdf: str
    palm_origin: np.ndarray  # (6,) xyz + rpy
    forms: dict[str, FormSpec]
    overrides: tuple[Override, ...] = ()
    fit_samples: int = 96
    fit_seed: int = 0
    source: str = "<spec>"
    notes: str = ""
    extra: dict[str, Any] = field(default_factory=dict)

    # -- paths -----------------------------------------------------------------------------------
    def urdf_path(self, root: str | Path | None = None) -> Path:
        """The original URDF: absolute, or relative to ``root`` (default :func:`ohra.paths.hands_root`)."""
        p = Path(self.urdf).expanduser()
        if p.is_absolute():
            return p
        base = Path(root) if root is not None else hands_root()
        return base / p

    # -- mapping ---------------------------------------------------------------------------------
    def form(self, form: str) -> FormSpec:
        if form not in self.forms:
            raise SpecError(f"{self.source}: hand {self.name!r} has no {form!r} form (forms: {', '.join(self.forms)})")
        return self.forms[form]

    def check_joints(self, original_joints: tuple[str, ...] | list[str]) -> None:
        """Raise :class:`SpecError` if a slot names a joint that is not a movable joint of the URDF."""
        known = set(original_joints)
        for fname, fs in self.forms.items():
            for slot, sm in fs.slots.items():
                if sm.name not in known:
                    raise SpecError(
                        f"{self.source}: forms.{fname} slot {slot!r} names joint {sm.name!r}, which is not a movable "
                        f"joint of {self.urdf} (movable joints: {', '.join(original_joints)})"
                    )

    def action_map(self, form: str, original_joints: tuple[str, ...] | list[str]) -> ActionMap:
        """The :class:`ohra.ActionMap` of ``form`` for an original hand with these joint names (file order)."""
        self.check_joints(original_joints)
        fs = self.form(form)
        return ActionMap(fs.slots, list(original_joints), self.palm_origin, fs.fixed)

    def overrides_for(self, form: str) -> list[Override]:
        return [o for o in self.overrides if o.form in (None, form)]


# -- YAML loading with duplicate-key detection -----------------------------------------------------
class _UniqueKeyLoader(yaml.SafeLoader):
    pass


def _construct_mapping(loader: yaml.SafeLoader, node: yaml.MappingNode, deep: bool = False) -> dict:
    seen: dict[Any, int] = {}
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=deep)
        if key in seen:
            raise SpecError(f"duplicate key {key!r} (line {key_node.start_mark.line + 1}; first on line {seen[key] + 1})")
        seen[key] = key_node.start_mark.line
    return yaml.SafeLoader.construct_mapping(loader, node, deep=deep)


_UniqueKeyLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)


def _number(v: Any, where: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise SpecError(f"{where}: expected a number, got {v!r}")
    if not np.isfinite(v):
        raise SpecError(f"{where}: expected a finite number, got {v!r}")
    return float(v)


def _slot_map(v: Any, where: str) -> SlotMap:
    if isinstance(v, str):
        if not v:
            raise SpecError(f"{where}: empty joint name")
        return SlotMap(v)
    if isinstance(v, Mapping):
        unknown = sorted(set(v) - {"joint", "sign", "offset"})
        if unknown:
            raise SpecError(f"{where}: unknown key(s) {unknown}; expected joint, sign, offset")
        if "joint" not in v or not isinstance(v["joint"], (str, int)) or isinstance(v["joint"], bool):
            raise SpecError(f"{where}: needs 'joint: <original joint name>'")
        sign = _number(v.get("sign", 1), where + ".sign")
        if sign not in (1.0, -1.0):
            raise SpecError(f"{where}.sign: expected 1 or -1, got {v.get('sign')!r}")
        return SlotMap(str(v["joint"]), sign, _number(v.get("offset", 0.0), where + ".offset"))
    if isinstance(v, int) and not isinstance(v, bool):  # joints named "0".."15" (LEAP) written unquoted
        return SlotMap(str(v))
    raise SpecError(f"{where}: expected a joint name or {{joint, sign, offset}}, got {v!r}")


def _slot_name(k: Any, where: str) -> str:
    if k not in JOINT_INDEX:
        raise SpecError(f"{where}: unknown canonical slot {k!r}; expected one of {', '.join(JOINT_NAMES)}")
    return str(k)


def _slots(d: Any, where: str, allow_null: bool) -> dict[str, SlotMap | None]:
    if d is None:
        return {}
    if not isinstance(d, Mapping):
        raise SpecError(f"{where}: expected a mapping of canonical slot -> original joint")
    out: dict[str, SlotMap | None] = {}
    for k, v in d.items():
        slot = _slot_name(k, where)
        if v is None:
            if not allow_null:
                raise SpecError(f"{where}.{slot}: null is only allowed in forms.<form>.joints (to drop a slot)")
            out[slot] = None
        else:
            out[slot] = _slot_map(v, f"{where}.{slot}")
    return out


def _palm_origin(v: Any, where: str) -> np.ndarray:
    if isinstance(v, Mapping):
        unknown = sorted(set(v) - {"xyz", "rpy"})
        if unknown:
            raise SpecError(f"{where}: unknown key(s) {unknown}; expected xyz, rpy")
        xyz, rpy = v.get("xyz", [0, 0, 0]), v.get("rpy", [0, 0, 0])
        if not isinstance(xyz, list) or not isinstance(rpy, list) or len(xyz) != 3 or len(rpy) != 3:
            raise SpecError(f"{where}: xyz and rpy must be lists of 3 numbers")
        vals = list(xyz) + list(rpy)
    elif isinstance(v, list) and len(v) == 6:
        vals = v
    else:
        raise SpecError(f"{where}: expected {{xyz: [3], rpy: [3]}} or a list of 6 numbers, got {v!r}")
    return np.array([_number(x, f"{where}[{i}]") for i, x in enumerate(vals)])


def _override(v: Any, where: str) -> Override:
    if not isinstance(v, Mapping):
        raise SpecError(f"{where}: expected {{key, value, reason[, form]}}")
    unknown = sorted(set(v) - {"key", "value", "reason", "form"})
    if unknown:
        raise SpecError(f"{where}: unknown key(s) {unknown}")
    for k in ("key", "value", "reason"):
        if k not in v:
            raise SpecError(f"{where}: missing {k!r} (every override must say why)" if k == "reason" else f"{where}: missing {k!r}")
    key = v["key"]
    if not isinstance(key, str) or not _KEY_RE.match(key):
        raise SpecError(f"{where}.key: expected a parameter key like 'finger_radius' or 'finger_lengths[0][2]', got {key!r}")
    reason = v["reason"]
    if not isinstance(reason, str) or not reason.strip():
        raise SpecError(f"{where}.reason: must be a non-empty explanation")
    form = v.get("form")
    if form is not None and form not in FORMS:
        raise SpecError(f"{where}.form: expected one of {FORMS}, got {form!r}")
    value = v["value"]
    try:
        np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise SpecError(f"{where}.value: expected a number or a list of numbers, got {value!r}") from None
    return Override(key, value, reason.strip(), form)


def spec_from_dict(d: Any, source: str = "<spec>", default_name: str = "hand") -> HandSpec:
    """Build and validate a :class:`HandSpec` from a parsed YAML mapping."""
    if not isinstance(d, Mapping):
        raise SpecError(f"{source}: expected a mapping at the top level")
    known = {"name", "urdf", "palm_origin", "joints", "forms", "overrides", "fit", "notes"}
    unknown = sorted(set(d) - known)
    if unknown:
        raise SpecError(f"{source}: unknown key(s) {unknown}; expected some of {sorted(known)}")
    for k in ("urdf", "palm_origin", "joints"):
        if k not in d:
            raise SpecError(f"{source}: missing key {k!r}")
    if not isinstance(d["urdf"], str) or not d["urdf"]:
        raise SpecError(f"{source}: 'urdf' must be a path string")
    name = d.get("name", default_name)
    if not isinstance(name, str) or not re.match(r"^[A-Za-z0-9_.-]+$", name):
        raise SpecError(f"{source}: 'name' must be a simple identifier, got {name!r}")
    palm = _palm_origin(d["palm_origin"], f"{source}: palm_origin")
    shared = _slots(d["joints"], f"{source}: joints", allow_null=False)

    forms_raw = d.get("forms", {"base": {}, "extended": {}})
    if not isinstance(forms_raw, Mapping) or not forms_raw:
        raise SpecError(f"{source}: 'forms' must map base/extended to their settings")
    forms: dict[str, FormSpec] = {}
    for fname, fraw in forms_raw.items():
        where = f"{source}: forms.{fname}"
        if fname not in FORMS:
            raise SpecError(f"{where}: unknown form; expected one of {FORMS}")
        fraw = fraw or {}
        if not isinstance(fraw, Mapping):
            raise SpecError(f"{where}: expected a mapping with 'joints' and/or 'fixed'")
        bad = sorted(set(fraw) - {"joints", "fixed"})
        if bad:
            raise SpecError(f"{where}: unknown key(s) {bad}; expected joints, fixed")
        merged: dict[str, SlotMap | None] = dict(shared)
        merged.update(_slots(fraw.get("joints"), where + ".joints", allow_null=True))
        slots = {k: v for k, v in merged.items() if v is not None}
        fixed_raw = fraw.get("fixed") or {}
        if not isinstance(fixed_raw, Mapping):
            raise SpecError(f"{where}.fixed: expected a mapping of canonical slot -> value")
        fixed = {_slot_name(k, where + ".fixed"): _number(v, f"{where}.fixed.{k}") for k, v in fixed_raw.items()}
        both = sorted(set(fixed) & set(slots))
        if both:
            raise SpecError(f"{where}: slot {both[0]!r} is both mapped and fixed")
        used: dict[str, str] = {}
        for slot in JOINT_NAMES:  # canonical order: the message names the two slots deterministically
            if slot not in slots:
                continue
            j = slots[slot].name
            if j in used:
                raise SpecError(f"{where}: duplicate mapping: original joint {j!r} drives both {used[j]!r} and {slot!r}")
            used[j] = slot
        if not slots:
            raise SpecError(f"{where}: no canonical slot is mapped")
        forms[fname] = FormSpec({s: slots[s] for s in JOINT_NAMES if s in slots}, fixed)

    over_raw = d.get("overrides") or []
    if not isinstance(over_raw, list):
        raise SpecError(f"{source}: 'overrides' must be a list")
    overrides = tuple(_override(o, f"{source}: overrides[{i}]") for i, o in enumerate(over_raw))
    fit = d.get("fit") or {}
    if not isinstance(fit, Mapping) or set(fit) - {"samples", "seed"}:
        raise SpecError(f"{source}: 'fit' accepts only samples and seed")
    samples = fit.get("samples", 96)
    seed = fit.get("seed", 0)
    if not isinstance(samples, int) or samples < 8:
        raise SpecError(f"{source}: fit.samples must be an integer >= 8, got {samples!r}")
    if not isinstance(seed, int):
        raise SpecError(f"{source}: fit.seed must be an integer, got {seed!r}")
    notes = d.get("notes", "")
    return HandSpec(name, d["urdf"], palm, forms, overrides, samples, seed, source, str(notes or ""))


def load_spec(source: str | Path) -> HandSpec:
    """Read a spec YAML file (or YAML text containing a newline)."""
    if isinstance(source, str) and "\n" in source:
        text, where, stem = source, "<spec text>", "hand"
    else:
        p = Path(source)
        if not p.is_file():
            raise SpecError(f"hand spec not found: {p}")
        text, where, stem = p.read_text(), str(p), p.name.split(".")[0]
    try:
        d = yaml.load(text, Loader=_UniqueKeyLoader)
    except SpecError as exc:
        raise SpecError(f"{where}: {exc}") from None
    except yaml.YAMLError as exc:
        raise SpecError(f"{where}: not valid YAML ({exc})") from None
    return spec_from_dict(d, where, stem)


__all__ = ["HandSpec", "FormSpec", "Override", "load_spec", "spec_from_dict", "FORMS"]
