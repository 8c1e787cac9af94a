"""The hand registry: registered real hands, the 256 LEAP variants, and params files.

``get_hand(name)`` accepts a registered hand name (``shadow_hand_right``, ...), a LEAP variant
(``leap_3303``), or a path to a params JSON file.
"""

from __future__ import annotations

from pathlib import Path
from typing import Union

from ohra.errors import HandNotFoundError, ParamsError
from ohra.canonical.params import BaseParams, ExtendedParams, load_params
from ohra.hands.leap.variants import is_variant, leap_variant, variant_names

Params = Union[BaseParams, ExtendedParams]
FORMS = ("base", "extended")


def list_hands(include_variants: bool = False) -> list[str]:
    """Registered hand names (plus the 256 ``leap_XXXX`` variants if asked)."""
    from ohra.hands import registry  # imported on use; an error in it surfaces here, never hidden

    names = sorted(registry.registered_hands())
    if include_variants:
        names += variant_names()
    return names


def get_hand(name: str | Path, form: str | None = None) -> Params:
    """Params of a registered hand, a LEAP variant or a params JSON file.

    ``form`` is ``"base"`` or ``"extended"``; None picks the hand's natural form (base for registered
    hands that have one, extended for LEAP variants and extended-only hands, the file's own form).
    """
    if form is not None and form not in FORMS:
        raise HandNotFoundError(f"unknown form {form!r}; expected one of {FORMS}")
    key = str(name)
    if is_variant(key):
        if form == "base":
            raise HandNotFoundError(f"{key} exists only in the extended form (LEAP flavour)")
        return leap_variant(key)
    from ohra.hands import registry

    if key in registry.registered_hands():
        return registry.registered_params(key, form)
    p = Path(key)
    if p.suffix == ".json" or p.is_file():
        if not p.is_file():
            raise HandNotFoundError(f"params file not found: {p}")
        params = load_params(p)
        if form == "extended" and isinstance(params, BaseParams):
            return params.to_extended()
        if form == "base" and isinstance(params, ExtendedParams):
            try:
                return params.to_base()
            except ParamsError as exc:
                raise HandNotFoundError(f"{p}: {exc}") from None
        return params
    known = ", ".join(list_hands()) or "(no registered hands)"
    raise HandNotFoundError(f"unknown hand {key!r}: not a registered hand ({known}), not leap_XXXX, not a params JSON file")


__all__ = ["get_hand", "list_hands", "variant_names", "leap_variant", "FORMS"]
