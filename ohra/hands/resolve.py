"""Any hand, no package edits: one reference string -> params, couplings and (when known) the original.

:func:`resolve_hand` accepts

* a registered hand name (package specs and user folders, see :mod:`ohra.hands.registry`);
* a LEAP variant ``leap_XXXX``;
* a hand spec YAML file (``*.yaml`` / ``*.yml``): parsed with the least-squares fit (kept for the
  process while the file is unchanged), couplings from its URDF ``<mimic>`` tags and the spec;
* a params JSON file: its params and optional ``"couplings"`` key; the original hand is known
  when a spec is given (``spec=``) or a spec with the same stem lies beside the JSON.

The result, a :class:`HandRef`, is what the ``ohra hand`` commands, :func:`ohra.original.fidelity.compare`
and the viewers work from.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

from ohra.canonical.couplings import Coupling, read_couplings
from ohra.canonical.params import BaseParams, ExtendedParams, Params, load_params
from ohra.errors import HandNotFoundError, HandWarning, ParamsError

SPEC_SUFFIXES = (".yaml", ".yml")
# keypoint RMS after the fit [mm] beyond which a spec's form is called a poor fit: the registered hands' forms fit
# within 16.6 mm (LEAP's base form, whose 22.6 mm mean fingertip error is already a stated miss of its 8 mm target);
# a hand the template cannot express (D'Claw's fingers at 120 deg in the base form) fits at ~47 mm
POOR_FIT_MM = 25.0
_warned_fits: set[tuple[Path, tuple[float, int], str]] = set()


@dataclass
class HandRef:
    """A resolved hand: params of one form, its couplings, and its spec when the original is known."""

    name: str
    form: str
    params: Params
    couplings: tuple[Coupling, ...] = ()
    spec: Any = None  # HandSpec, or None (LEAP variants, params JSON without a spec)
    result: Any = None  # the ParseResult when the hand was parsed from a spec
    kind: str = "registered"  # registered | variant | spec | params

    def require_spec(self, what: str):
        if self.spec is None:
            hint = " (pass its spec YAML, or put <name>.yaml beside the params JSON)" if self.kind == "params" else ""
            raise HandNotFoundError(f"{what} needs the original hand, which is unknown for {self.name!r}{hint}")
        return self.spec

    def original(self):
        """The :class:`~ohra.original.hand.OriginalHand` (loaded from the spec's URDF)."""
        from ohra.original.parse import load_original_for

        if self.result is not None:
            return self.result.hand
        return load_original_for(self.require_spec("the original hand"))

    def action_map(self):
        """The :class:`ohra.ActionMap` of this form (couplings included)."""
        if self.result is not None:
            return self.result.action_map
        return self.require_spec("the action map").action_map(self.form, self.original())

    def parse_result(self):
        """A :class:`~ohra.original.parse.ParseResult` for these params (measured on the original)."""
        from ohra.original.measure import measure
        from ohra.original.parse import ParseResult, override_notes

        if self.result is not None and self.result.params is self.params:
            return self.result
        sp = self.require_spec("a fidelity report")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the measurement's notes are kept below
            keep_mesh_warnings()
            m = measure(self.original(), sp, self.form)
        notes = list(m.notes) + override_notes(sp, self.params)
        return ParseResult(self.params, self.form, sp, m, self.params, None, notes)


@lru_cache(maxsize=32)
def _parse_cached(path: Path, mtime: tuple[float, int], form: str):
    from ohra.original.parse import parse

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the parse's notes travel in its result
        keep_mesh_warnings()
        return parse(path, form, fit_params=True)


def keep_mesh_warnings() -> None:
    """Inside a block that ignores warnings, still show a missing mesh: what is measured on the original hand
    (fingertips, link surfaces) changes without it."""
    from ohra.original.hand import MissingMeshWarning

    warnings.simplefilter("default", MissingMeshWarning)


def parse_spec_file(path: str | Path, form: str | None = None):
    """ParseResult of a spec file (fit included), cached while the file is unchanged."""
    from ohra.original.spec import load_spec

    p = Path(path).expanduser().resolve()
    sp = load_spec(p)
    if form is None:
        form = "base" if "base" in sp.forms else next(iter(sp.forms))
    sp.form(form)
    urdf = next((c for c in sp.urdf_candidates() if c.is_file()), None)
    # the URDF's time too: a notebook that edits the hand's URDF and not its spec must not get the old parse
    mtime = (p.stat().st_mtime, urdf.stat().st_mtime_ns if urdf is not None else 0)
    res = _parse_cached(p, mtime, form)
    if res.fit is not None and res.fit.final_rms_mm > POOR_FIT_MM and (p, mtime, form) not in _warned_fits:
        _warned_fits.add((p, mtime, form))
        other = (f"; the extended form may follow it (ohra hand parse {p.name} --extended --fit -o HAND.json, then use "
                 "HAND.json)") if form == "base" and "extended" in sp.forms else ""
        warnings.warn(f"hand spec {p}: its {form} form follows the original URDF poorly (keypoint RMS {res.fit.final_rms_mm:.0f} mm "
                      f"after the fit; registered hands: at most 17 mm), so grasps or policies made on it may not carry over to "
                      f"the original; `ohra hand compare {p.name}` shows where{other}", HandWarning, stacklevel=2)
    return res


def _in_form(params: Params, form: str | None, where: str) -> Params:
    if form == "extended" and isinstance(params, BaseParams):
        return params.to_extended()
    if form == "base" and isinstance(params, ExtendedParams):
        try:
            return params.to_base()
        except ParamsError as exc:
            raise HandNotFoundError(f"{where}: {exc}; these are extended-form params: ask for the extended form "
                                    "(--extended for ohra hand, --form extended for ohra eval, form='extended' in Python)") from None
    return params


def _from_params_file(p: Path, form: str | None, spec: str | Path | None) -> HandRef:
    from ohra.original.spec import load_spec

    params = load_params(p)
    nat = params.form if params.form == "base" else "extended"
    params = _in_form(params, form, str(p))
    side = next((p.with_suffix(s) for s in SPEC_SUFFIXES if p.with_suffix(s).is_file()), None)
    sp = load_spec(spec) if spec is not None else (load_spec(side) if side is not None else None)
    return HandRef(p.stem if sp is None else sp.name, form or nat, params, read_couplings(p), sp, None, "params")


def resolve_hand(ref: Any, form: str | None = None, spec: str | Path | None = None) -> HandRef:
    """Resolve a hand reference (see the module docstring); ``form`` None picks the natural form.

    Raises:
        HandNotFoundError: names what was tried (registered names, variants, files).
    """
    from ohra.hands import registry
    from ohra.hands.leap.variants import is_variant, leap_variant

    if isinstance(ref, HandRef):
        return ref
    if form is not None and form not in ("base", "extended"):
        raise HandNotFoundError(f"unknown form {form!r}; expected 'base' or 'extended'")
    key = str(ref)
    if is_variant(key):
        if form == "base":
            raise HandNotFoundError(f"{key} is a LEAP variant: it exists only in the extended form (LEAP flavour), and "
                                    "this needs a hand's base form (a registered hand, its spec or base params JSON)")
        return HandRef(key, "extended", leap_variant(key), kind="variant")
    if key in registry.registered_hands():
        f = registry._resolve_form(key, form)
        return HandRef(key, f, registry.registered_params(key, f), registry.couplings(key, f), registry.spec(key))
    p = Path(key).expanduser()
    if p.suffix in SPEC_SUFFIXES:
        if not p.is_file():
            raise HandNotFoundError(f"hand spec not found: {p}")
        res = parse_spec_file(p, form)
        return HandRef(res.spec.name, res.form, res.params, res.couplings, res.spec, res, "spec")
    if p.suffix == ".json" or p.is_file():
        if not p.is_file():
            raise HandNotFoundError(f"params file not found: {p}")
        return _from_params_file(p, form, spec)
    known = ", ".join(registry.registered_hands()) or "(no registered hands)"
    raise HandNotFoundError(
        f"unknown hand {key!r}: not a registered hand ({known}), not a LEAP variant "
        f"leap_ABCD (digits 0-3: links kept on the thumb, index, middle and little finger), not a spec YAML or params JSON file "
        f"(a hand whose spec is in your own folder: ohra --hands-path DIR, or ${registry.PATH_ENV})"
    )


__all__ = ["HandRef", "resolve_hand", "parse_spec_file", "keep_mesh_warnings"]
