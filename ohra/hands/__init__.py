"""The hand registry: registered real hands, the 256 LEAP variants, and params files.

``get_hand(name)`` accepts a registered hand name (``shadow_hand_right``, ...; user folders from
``$OHRA_HANDS_PATH`` included), a LEAP variant (``leap_3303``), a hand spec YAML file or a params
JSON file; ``get_couplings(name)`` gives its coupled joints.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

from ohra.canonical.couplings import Coupling
from ohra.canonical.params import BaseParams, ExtendedParams, Params
from ohra.errors import HandNotFoundError
from ohra.hands.leap.variants import leap_variant, variant_names
from ohra.hands.resolve import HandRef, resolve_hand

FORMS = ("base", "extended")


def _registry():
    """The registered-hands module (specs and committed params of real hands); imported on use."""
    from ohra.hands import registry

    return registry


def list_hands(include_variants: bool = False) -> list[str]:
    """Registered hand names (package specs and ``$OHRA_HANDS_PATH`` folders), sorted.

    Args:
        include_variants: also list the 256 LEAP variants ``leap_0000`` .. ``leap_3333``, after the
            registered names.

    Returns:
        Names :func:`get_hand` accepts.
    """
    if not isinstance(include_variants, bool):  # list_hands("leap") listed the registered hands only
        raise HandNotFoundError(f"list_hands: include_variants must be True or False, got {include_variants!r}")
    reg = _registry()
    names = sorted(reg.registered_hands()) if reg is not None else []
    if include_variants:
        names += variant_names()
    return names


def get_hand(name: str | Path, form: str | None = None) -> Params:
    """Params of a registered hand, a LEAP variant, a hand spec YAML (parsed, cached) or a params JSON file.

    Couplings travel beside the params: :func:`get_couplings`, or :func:`resolve_hand` for both.

    Args:
        name: a registered name (:func:`list_hands`), ``leap_XXXX``, or a ``.yaml``/``.yml`` spec or
            ``.json`` params path.
        form: ``"base"`` or ``"extended"``; None picks the hand's natural form (base for registered
            hands that have one, extended for LEAP variants and extended-only hands, the file's own form).

    Returns:
        :class:`BaseParams` or :class:`ExtendedParams` (lengths [m], angles [rad], palm frame).

    Raises:
        HandNotFoundError: unknown name or missing file; ``form`` not ``"base"``/``"extended"``; the hand
            is not registered in ``form``; a LEAP variant, or extended params that have no base form,
            asked for as ``"base"``.
        ParamsError: a params JSON file is malformed or invalid.
        SpecError: a spec YAML is malformed, has no ``form``, or names joints its URDF lacks.
        AssetsNotFoundError: a spec's original URDF is not found.
        ParseError: a spec's original URDF does not give valid params.
    """
    return resolve_hand(name, form).params


def hands_in_form(form: str = "base") -> dict[str, Params]:
    """Params of every registered hand that has ``form`` (``"base"`` or ``"extended"``), by name in
    :func:`list_hands` order; hands not registered in that form (e.g. extended-only hands for
    ``"base"``) are left out, while a broken spec or params file of a hand that has it still raises.
    LEAP variants are not included.

    Raises:
        HandNotFoundError: ``form`` is not ``"base"`` or ``"extended"``.
    """
    if form not in FORMS:
        raise HandNotFoundError(f"unknown form {form!r}; expected one of {', '.join(map(repr, FORMS))}")
    reg = _registry()
    return {name: get_hand(name, form) for name in list_hands() if form in reg.registered_forms(name)}


def get_couplings(name: str | Path, form: str | None = None) -> tuple[Coupling, ...]:
    """Canonical couplings (``slot = multiplier * driver + offset``) of any hand :func:`get_hand` accepts."""
    return resolve_hand(name, form).couplings


def couplings_of(params: Params) -> tuple[Coupling, ...]:
    """The couplings of the registered hand (user folders included) whose params, in one of its forms, equal
    ``params`` (what ``get_hand(name)`` returned, say); ``()`` when no coupled registered hand has them (LEAP
    variants, a hand edited since). Lets APIs that take bare params (``GraspEvaluator(params, obj)``,
    ``synthesize([(name, params)], ...)``) drive a coupled hand as simulation and synthesis by name do."""
    import numpy as np

    if not isinstance(params, (BaseParams, ExtendedParams)):
        from ohra.errors import ParamsError

        hint = f" (a hand name: get_couplings({str(params)!r}))" if isinstance(params, (str, Path)) else ""
        raise ParamsError(f"couplings_of: expected BaseParams or ExtendedParams, got {type(params).__name__}{hint}")
    reg = _registry()
    files = reg._spec_files()
    key = tuple((n, str(p), p.stat().st_mtime_ns) for n, p in sorted(files.items()))
    v = np.asarray(params.to_vector(), dtype=float)
    for kind, vec, cs in _coupled_params(key):
        if kind == type(params).__name__ and vec.shape == v.shape and np.array_equal(vec, v):
            return cs
    return ()


@lru_cache(maxsize=4)
def _coupled_params(key: tuple) -> tuple:
    """(params type name, parameter vector, couplings) of every registered hand and form with couplings."""
    import numpy as np

    reg = _registry()
    out = []
    for name in reg.registered_hands():
        for form in reg.registered_forms(name):
            cs = reg.couplings(name, form)
            if cs:
                p = reg.registered_params(name, form)
                out.append((type(p).__name__, np.asarray(p.to_vector(), dtype=float), tuple(cs)))
    return tuple(out)


__all__ = ["get_hand", "get_couplings", "couplings_of", "hands_in_form", "resolve_hand", "HandRef", "list_hands", "variant_names", "leap_variant", "FORMS"]
