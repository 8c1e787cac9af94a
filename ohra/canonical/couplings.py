"""Coupled canonical joints: ``q[slot] = multiplier * q[driver] + offset``.

Many hands drive some joints through others (URDF ``<mimic>``, tendons, linkages). The canonical
hand keeps its 22 independent joints (the action space does not change); a hand's couplings travel
beside its parameters (spec, registry, :class:`ohra.original.parse.ParseResult`, the optional
``"couplings"`` key of a params JSON) and are applied by whoever moves the hand:

* :func:`coupling_matrix` gives ``A`` (22, 22) and ``b`` (22,) with ``q = A @ q_free + b`` for any
  vector ``q_free`` (only its free entries matter): the projection onto the coupled subspace, for
  linear solvers and equality constraints (``(I - A) q = b`` holds exactly for coupled ``q``).
* :func:`residual` (..., K) and :func:`project` (..., 22) on batches, :func:`free_mask` (22,) of
  the independent slots, :func:`propagate_limits` for the coupled slots' reachable ranges.

Chains (a slot driven by a slot that is itself coupled) are resolved to their root driver by
:func:`resolve`, so every function here sees at most one level. Angles in radians (prismatic
slots do not exist in the canonical hand).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

from ohra.canonical.params import JOINT_INDEX, JOINT_NAMES
from ohra.errors import ParamsError

JSON_KEY = "couplings"  # the optional key of a params JSON (reference readers ignore it)


@dataclass(frozen=True)
class Coupling:
    """``q[slot] = multiplier * q[driver] + offset`` (canonical slot names, radians).

    ``source`` says where the relation comes from (e.g. ``"urdf mimic index_intermediate_joint"``
    or ``"spec"``); it is informative only and not part of equality.
    """

    slot: str
    driver: str
    multiplier: float
    offset: float = 0.0
    source: str = ""

    def __post_init__(self) -> None:
        for what, name in (("slot", self.slot), ("driver", self.driver)):
            if name not in JOINT_INDEX:
                raise ParamsError(f"coupling {what} {name!r} is not a canonical slot; expected one of {', '.join(JOINT_NAMES)}")
        if self.slot == self.driver:
            raise ParamsError(f"coupling of {self.slot!r}: a slot cannot drive itself")
        for what, v in (("multiplier", self.multiplier), ("offset", self.offset)):
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ParamsError(f"coupling of {self.slot!r}: {what} must be a finite number, got {v!r}")
        if self.multiplier == 0.0:
            raise ParamsError(f"coupling of {self.slot!r}: multiplier 0 is a fixed slot, not a coupling (use 'fixed')")
        object.__setattr__(self, "multiplier", float(self.multiplier))
        object.__setattr__(self, "offset", float(self.offset))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Coupling):
            return NotImplemented
        return (self.slot, self.driver, self.multiplier, self.offset) == (other.slot, other.driver, other.multiplier, other.offset)

    def __hash__(self) -> int:
        return hash((self.slot, self.driver, self.multiplier, self.offset))

    @property
    def i(self) -> int:
        """Index of the coupled slot."""
        return JOINT_INDEX[self.slot]

    @property
    def d(self) -> int:
        """Index of the driving slot."""
        return JOINT_INDEX[self.driver]

    def to_dict(self) -> dict[str, Any]:
        return {"slot": self.slot, "driver": self.driver, "multiplier": self.multiplier, "offset": self.offset}


def coupling_from_dict(d: Any, where: str = "coupling") -> Coupling:
    """A :class:`Coupling` from ``{slot, driver, multiplier, offset?, source?}`` (errors name ``where``)."""
    if not isinstance(d, Mapping):
        raise ParamsError(f"{where}: expected {{slot, driver, multiplier, offset}}, got {d!r}")
    unknown = sorted(set(d) - {"slot", "driver", "multiplier", "offset", "source"})
    if unknown:
        raise ParamsError(f"{where}: unknown key(s) {unknown}; expected slot, driver, multiplier, offset")
    for k in ("slot", "driver", "multiplier"):
        if k not in d:
            raise ParamsError(f"{where}: missing {k!r}")
    try:
        return Coupling(d["slot"], d["driver"], d["multiplier"], d.get("offset", 0.0), str(d.get("source", "")))
    except ParamsError as exc:
        raise ParamsError(f"{where}: {exc}") from None


def resolve(couplings: Iterable[Coupling]) -> tuple[Coupling, ...]:
    """Validated couplings with chains composed to their root driver, in canonical slot order.

    Raises:
        ParamsError: a slot coupled twice, or a cycle (names the slots).
    """
    by_slot: dict[str, Coupling] = {}
    for c in couplings:
        if c.slot in by_slot:
            raise ParamsError(f"slot {c.slot!r} is coupled twice (to {by_slot[c.slot].driver!r} and {c.driver!r})")
        by_slot[c.slot] = c
    out = []
    for slot in JOINT_NAMES:
        if slot not in by_slot:
            continue
        c, chain = by_slot[slot], [slot]
        a, b, driver = c.multiplier, c.offset, c.driver
        while driver in by_slot:  # driver = a2 * root + b2  ->  slot = a * a2 * root + (a * b2 + b)
            if driver in chain:
                raise ParamsError(f"coupling cycle: {' -> '.join(chain + [driver])}")
            chain.append(driver)
            up = by_slot[driver]
            a, b, driver = a * up.multiplier, a * up.offset + b, up.driver
        out.append(Coupling(slot, driver, a, b, c.source))
    return tuple(out)


def free_mask(couplings: Sequence[Coupling]) -> np.ndarray:
    """(22,) bool: slots that are not coupled to another (the independent coordinates)."""
    m = np.ones(22, dtype=bool)
    for c in couplings:
        m[c.i] = False
    return m


def coupling_matrix(couplings: Sequence[Coupling]) -> tuple[np.ndarray, np.ndarray]:
    """``A`` (22, 22), ``b`` (22,) with ``q = A @ q_free + b`` the coupled vector of any ``q_free``.

    Free slots copy themselves (``A[k, k] = 1``); a coupled slot j reads its root driver i
    (``A[j, i] = multiplier``, ``b[j] = offset``) and ignores its own entry (column j is zero).
    """
    cs = resolve(couplings)
    A = np.diag(free_mask(cs).astype(float))
    b = np.zeros(22)
    for c in cs:
        A[c.i, c.d] = c.multiplier
        b[c.i] = c.offset
    return A, b


def project(couplings: Sequence[Coupling], q: np.ndarray) -> np.ndarray:
    """(..., 22) -> (..., 22): coupled slots set from their drivers; free slots unchanged."""
    q = np.array(q, dtype=float, copy=True)
    if q.shape[-1] != 22:
        raise ParamsError(f"canonical joint vector must have 22 entries, got shape {q.shape}")
    for c in resolve(couplings):
        q[..., c.i] = c.multiplier * q[..., c.d] + c.offset
    return q


def residual(couplings: Sequence[Coupling], q: np.ndarray) -> np.ndarray:
    """(..., 22) -> (..., K): ``q[slot] - (multiplier * q[driver] + offset)`` per resolved coupling [rad]."""
    q = np.asarray(q, dtype=float)
    if q.shape[-1] != 22:
        raise ParamsError(f"canonical joint vector must have 22 entries, got shape {q.shape}")
    cs = resolve(couplings)
    if not cs:
        return np.zeros(q.shape[:-1] + (0,))
    return np.stack([q[..., c.i] - (c.multiplier * q[..., c.d] + c.offset) for c in cs], axis=-1)


def propagate_limits(couplings: Sequence[Coupling], lower: np.ndarray, upper: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(22,) limits with each coupled slot's range = its driver's range mapped through the coupling."""
    lo, up = np.array(lower, dtype=float), np.array(upper, dtype=float)
    for c in resolve(couplings):
        a, b = c.multiplier * lo[c.d] + c.offset, c.multiplier * up[c.d] + c.offset
        lo[c.i], up[c.i] = min(a, b), max(a, b)
    return lo, up


# -- params JSON: the optional "couplings" key ------------------------------------------------------
def couplings_from_json_value(value: Any, where: str) -> tuple[Coupling, ...]:
    """Couplings from the value of a params JSON's ``"couplings"`` key (a list of dicts)."""
    if not isinstance(value, list):
        raise ParamsError(f"{where}: '{JSON_KEY}' must be a list of {{slot, driver, multiplier, offset}}")
    items = [coupling_from_dict(v, f"{where}: {JSON_KEY}[{k}]") for k, v in enumerate(value)]
    try:
        return resolve(items)
    except ParamsError as exc:  # a cycle or a slot coupled twice: name the file it is in
        raise ParamsError(f"{where}: {JSON_KEY}: {exc}") from None


def read_couplings(path: str | Path) -> tuple[Coupling, ...]:
    """The couplings stored in a params JSON file (empty when it has no ``"couplings"`` key)."""
    p = Path(path)
    try:
        d = json.loads(p.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise ParamsError(f"{p}: cannot read params JSON ({exc})") from None
    if not isinstance(d, dict) or JSON_KEY not in d:
        return ()
    return couplings_from_json_value(d[JSON_KEY], str(p))


def params_json(params: Any, couplings: Sequence[Coupling] = ()) -> str:
    """``params.to_json()`` with a trailing ``"couplings"`` key when there are couplings.

    The reference keys come first, unchanged (reference readers ignore the extra key;
    :func:`ohra.canonical.params.load_params` accepts it). Without couplings the text is exactly
    ``params.to_json()``.
    """
    text = params.to_json()
    cs = resolve(couplings)
    if not cs:
        return text
    body = text.rstrip().rstrip("}").rstrip()
    items = ",\n".join("    " + json.dumps(c.to_dict()) for c in cs)
    return f"{body},\n  \"{JSON_KEY}\": [\n{items}\n  ]\n}}\n"


def describe(couplings: Sequence[Coupling]) -> list[str]:
    """One line per coupling, e.g. ``index_joint3 = 1.06399 * index_joint2 - 0.04836``."""
    out = []
    for c in couplings:
        sign = "-" if c.offset < 0 else "+"
        out.append(f"{c.slot} = {c.multiplier:.6g} * {c.driver} {sign} {abs(c.offset):.6g}" + (f"  ({c.source})" if c.source else ""))
    return out


__all__ = [
    "Coupling", "coupling_from_dict", "resolve", "free_mask", "coupling_matrix", "project", "residual",
    "propagate_limits", "read_couplings", "params_json", "couplings_from_json_value", "describe", "JSON_KEY",
]
