"""Reading hand specs: YAML (duplicate keys and syntax errors as one-line :class:`SpecError`) and
validation of every key into a :class:`~ohra.original.spec.HandSpec` (the schema is documented there).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import yaml

from ohra.canonical.couplings import Coupling, coupling_from_dict, resolve
from ohra.canonical.params import JOINT_INDEX, JOINT_NAMES, MAX_POSITION
from ohra.errors import ParamsError, SpecError
from ohra.original.action import SlotMap
from ohra.original.spec import _KEY_RE, FORMS, FormSpec, HandSpec, Override


# -- YAML loading with duplicate-key detection -----------------------------------------------------
class UniqueKeyLoader(yaml.SafeLoader):
    """YAML's safe loader refusing a key given twice in one mapping (PyYAML keeps the last one silently): a
    :class:`SpecError` naming the key and both lines. Hand specs and dataset recipes load through it."""


def _construct_mapping(loader: yaml.SafeLoader, node: yaml.MappingNode, deep: bool = False) -> dict:
    seen: dict[Any, int] = {}
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=deep)
        if key in seen:
            raise SpecError(f"duplicate key {key!r} (line {key_node.start_mark.line + 1}; first on line {seen[key] + 1})")
        seen[key] = key_node.start_mark.line
    return yaml.SafeLoader.construct_mapping(loader, node, deep=deep)


UniqueKeyLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)


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


# The farthest a palm origin may sit from the original root link (the params' position bound).
PALM_ORIGIN_MAX_M = MAX_POSITION


def _palm_origin(v: Any, where: str) -> np.ndarray:
    if isinstance(v, Mapping):
        unknown = sorted(set(v) - {"xyz", "rpy"})
        if unknown:
            raise SpecError(f"{where}: unknown key(s) {unknown}; expected xyz, rpy")
        if "xyz" not in v:  # never a silent zero: the palm's place is the one measurement every hand needs
            raise SpecError(f"{where}: missing 'xyz' (the canonical palm origin in the original root frame, metres; "
                            "write xyz: [0, 0, 0] if the palm sits at the root)")
        xyz, rpy = v["xyz"], v.get("rpy", [0, 0, 0])
        if not isinstance(xyz, list) or not isinstance(rpy, list) or len(xyz) != 3 or len(rpy) != 3:
            raise SpecError(f"{where}: xyz and rpy must be lists of 3 numbers")
        vals = list(xyz) + list(rpy)
    elif isinstance(v, list) and len(v) == 6:
        vals = v
    else:
        raise SpecError(f"{where}: expected {{xyz: [3], rpy: [3]}} or a list of 6 numbers, got {v!r}")
    out = np.array([_number(x, f"{where}[{i}]") for i, x in enumerate(vals)])
    dist = float(np.linalg.norm(out[:3]))
    if dist > PALM_ORIGIN_MAX_M:  # a hand's palm is centimetres from its root link; this is a unit slip
        raise SpecError(f"{where}: xyz {out[:3].tolist()} is {dist:.3g} m from the root link (expected metres, at most "
                        f"{PALM_ORIGIN_MAX_M} m; millimetres? xyz [0, 0, -95] is written [0, 0, -0.095]; a hand on an arm? "
                        "name the hand's own root link with root_link: and give palm_origin in its frame)")
    if np.any(np.abs(out[3:]) > 2 * np.pi + 1e-9):
        raise SpecError(f"{where}: rpy {out[3:].tolist()} beyond +-2 pi (expected radians; degrees?)")
    return out


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
    from ohra.canonical.params import BaseParams, ExtendedParams

    known = {"base": [k for k, _ in BaseParams.KEYS], "extended": [k for k, _ in ExtendedParams.KEYS]}
    name = _KEY_RE.match(key).group(1)  # type: ignore[union-attr]
    allowed = known[form] if form else known["base"] + [k for k in known["extended"] if k not in known["base"]]
    if name not in allowed:
        # a misspelt key was skipped as "a key of the other form" and then reported as applied
        raise SpecError(f"{where}.key: no parameter {name!r} in the {form or 'base or extended'} form "
                        f"(keys: {', '.join(allowed)})")
    value = v["value"]
    try:
        np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise SpecError(f"{where}.value: expected a number or a list of numbers, got {value!r}") from None
    return Override(key, value, reason.strip(), form)


def _form(fname: Any, fraw: Any, shared: dict[str, SlotMap], source: str) -> FormSpec:
    """One entry of ``forms``: the shared mapping changed by its ``joints`` (null drops) and ``fixed``."""
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
    return FormSpec({s: slots[s] for s in JOINT_NAMES if s in slots}, fixed)


def _fit_settings(fit: Any, source: str) -> tuple[int, int]:
    fit = fit or {}
    if not isinstance(fit, Mapping) or set(fit) - {"samples", "seed"}:
        raise SpecError(f"{source}: 'fit' accepts only samples and seed")
    samples = fit.get("samples", 96)
    seed = fit.get("seed", 0)
    if not isinstance(samples, int) or samples < 8:
        raise SpecError(f"{source}: fit.samples must be an integer >= 8, got {samples!r}")
    if not isinstance(seed, int):
        raise SpecError(f"{source}: fit.seed must be an integer, got {seed!r}")
    return samples, seed


def spec_from_dict(d: Any, source: str = "<spec>", default_name: str = "hand", base_dir: Path | None = None) -> HandSpec:
    """Build and validate a :class:`HandSpec` from a parsed YAML mapping."""
    if not isinstance(d, Mapping):
        raise SpecError(f"{source}: expected a mapping at the top level")
    known = {"name", "urdf", "root_link", "xacro_args", "palm_origin", "joints", "forms", "overrides", "fit", "notes", "couplings"}
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
    root_link = d.get("root_link")
    if root_link is not None and (not isinstance(root_link, str) or not root_link):
        raise SpecError(f"{source}: 'root_link' must be a link name (the hand's own root in a URDF that holds an arm), "
                        f"got {root_link!r}")
    xacro_args = d.get("xacro_args") or {}
    if not isinstance(xacro_args, Mapping) or not all(isinstance(k, str) and isinstance(v, (str, int, float))
                                                      for k, v in xacro_args.items()):
        raise SpecError(f"{source}: 'xacro_args' maps a .xacro URDF's <xacro:arg> names to values (strings, numbers or "
                        f"true/false), got {xacro_args!r}")
    palm = _palm_origin(d["palm_origin"], f"{source}: palm_origin")
    shared = _slots(d["joints"], f"{source}: joints", allow_null=False)
    forms_raw = d.get("forms", {"base": {}, "extended": {}})
    if not isinstance(forms_raw, Mapping) or not forms_raw:
        raise SpecError(f"{source}: 'forms' must map base/extended to their settings")
    forms = {fname: _form(fname, fraw, shared, source) for fname, fraw in forms_raw.items()}  # type: ignore[arg-type]
    over_raw = d.get("overrides") or []
    if not isinstance(over_raw, list):
        raise SpecError(f"{source}: 'overrides' must be a list")
    overrides = tuple(_override(o, f"{source}: overrides[{i}]") for i, o in enumerate(over_raw))
    samples, seed = _fit_settings(d.get("fit"), source)
    couplings = _declared_couplings(d.get("couplings"), forms, source)
    return HandSpec(name, d["urdf"], palm, forms, overrides, samples, seed, source, str(d.get("notes", "") or ""),
                    couplings=couplings, base_dir=base_dir, root_link=root_link,
                    xacro_args={str(k): (str(v).lower() if isinstance(v, bool) else str(v)) for k, v in xacro_args.items()})


def _declared_couplings(raw: Any, forms: dict[str, FormSpec], source: str) -> tuple[Coupling, ...]:
    """The spec's ``couplings`` list: each applies to the forms mapping both its slots (at least one)."""
    if raw is None:
        return ()
    if not isinstance(raw, list):
        raise SpecError(f"{source}: 'couplings' must be a list of {{slot, driver, multiplier, offset}}")
    out = []
    for k, v in enumerate(raw):
        where = f"{source}: couplings[{k}]"
        try:
            c = coupling_from_dict(v, where)
        except ParamsError as exc:
            raise SpecError(str(exc)) from None
        if not any(c.slot in fs.slots and c.driver in fs.slots for fs in forms.values()):
            raise SpecError(f"{where}: slots {c.slot!r} and {c.driver!r} are not both mapped in any form")
        out.append(Coupling(c.slot, c.driver, c.multiplier, c.offset, "spec"))
    try:
        resolve(out)
    except ParamsError as exc:
        raise SpecError(f"{source}: couplings: {exc}") from None
    return tuple(out)


def read_yaml(text: str, where: str) -> Any:
    """Parse YAML text; a syntax error or duplicate key is a one-line :class:`SpecError` with the line."""
    try:
        return yaml.load(text, Loader=UniqueKeyLoader)
    except SpecError as exc:
        raise SpecError(f"{where}: {exc}") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        at = f" line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        what = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        ctx = getattr(exc, "context", None)
        raise SpecError(f"{where}:{at}: invalid YAML: {what}" + (f" ({ctx})" if ctx else "")) from None


def load_spec(source: str | Path) -> HandSpec:
    """Read a spec YAML file (or YAML text containing a newline)."""
    base_dir = None
    if isinstance(source, str) and "\n" in source:
        text, where, stem = source, "<spec text>", "hand"
    else:
        p = Path(source).expanduser()
        if not p.is_file():
            raise SpecError(f"hand spec not found: {p}")
        text, where, stem, base_dir = p.read_text(), str(p), p.name.split(".")[0], p.resolve().parent
    return spec_from_dict(read_yaml(text, where), where, stem, base_dir)


__all__ = ["load_spec", "spec_from_dict", "read_yaml"]
