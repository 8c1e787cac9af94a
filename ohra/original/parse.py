"""Parse an original hand URDF + :class:`~ohra.original.spec.HandSpec` into canonical parameters.

The pipeline, one module per step (no hand names anywhere; see each module for its rules):

1. :mod:`ohra.original.measure`: joint frames, finger directions, fingertips and radii of the
   original hand in the canonical palm frame at the configuration of canonical zero
   (``ActionMap.to_original(0)``).
2. :mod:`ohra.original.estimate`: initial base / extended parameters from those measurements
   (template axes checked against the slot signs).
3. :mod:`ohra.original.fit` (optional): least squares of the continuous kinematic parameters
   against the original fingertips and joint axes over seeded configurations
   (:mod:`ohra.original.keypoints` evaluates both hands).
4. Overrides from the spec (values that cannot be measured), each with its reason.

:func:`parse` runs the steps and returns a :class:`ParseResult`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ohra.canonical.params import FINGER_GAP, BaseParams, Params
from ohra.errors import ParamsError, ParseError, SpecError
from ohra.canonical.couplings import Coupling, describe
from ohra.original.action import ActionMap
from ohra.original.checks import arm_hint, check_palm_frame
from ohra.original.estimate import initial_base, initial_extended
from ohra.original.fit import FitResult, fit, rounded
from ohra.original.measure import Measurement, ParseWarning, measure
from ohra.original.spec import HandSpec, load_spec
from ohra.original.urdf import OriginalHand, load_urdf


# FINGER_GAP (m, ohra.canonical.params): how far apart synthesis keeps different fingers


def _separate_fingers(params: Params, am: ActionMap, notes: list[str]) -> Params:
    """Base form: cap the shared finger radius so that different fingers are at least
    :data:`FINGER_GAP` apart at rest (canonical zero within the limits, couplings applied).

    The base template's fingers are parallel and share one radius; the fit places their bases for the
    kinematics alone, so on a hand with closely spaced, splayed fingers (PSYONIC Ability) neighbouring
    capsules could intersect in every pose and no grasp could ever be synthesised on that hand.
    """
    if not isinstance(params, BaseParams):
        return params
    import numpy as np

    from ohra.canonical.kinematics import HandModel, _distance

    hm = HandModel.from_params(params)
    q = np.clip(am.project(np.zeros(22)), hm.lower, hm.upper)
    objs = [o for o in hm.collision_objects(q) if o[1] >= 0]
    from ohra.canonical.params import FINGERS

    pairs = [(_distance(a[2], b[2]), a[1], b[1]) for i, a in enumerate(objs) for b in objs[i + 1:] if a[1] != b[1]]
    d, fa, fb = min(pairs, default=(np.inf, 0, 0))
    if d >= FINGER_GAP:
        return params
    r_old = float(params.finger_radius)
    r = np.floor((r_old - (FINGER_GAP - d) / 2.0) * 1e6) / 1e6
    if r < 0.002:
        names = sorted({" and ".join(FINGERS[k] for k in sorted((a, b))) for dd, a, b in pairs if dd < FINGER_GAP})
        notes.append(f"approximation: canonical fingers intersect at rest ({'; '.join(names)}; {FINGERS[min(fa, fb)]} and "
                     f"{FINGERS[max(fa, fb)]} {d * 1e3:+.2f} mm apart) and a radius small enough to separate them would be "
                     f"under 2 mm; no grasp can be synthesised on this hand: check the joint mapping, and compare the "
                     f"layout parsed without the fit")
        return params
    d_params = params.to_dict()
    d_params["finger_radius"] = float(r)
    notes.append(f"approximation: finger radius {r_old * 1e3:.2f} -> {r * 1e3:.2f} mm so that neighbouring fingers are "
                 f"{FINGER_GAP * 1e3:g} mm apart at rest (they were {d * 1e3:+.2f} mm apart: no grasp could be synthesised)")
    return BaseParams.from_dict(d_params)


def apply_overrides(params: Params, spec: HandSpec, form: str) -> Params:
    """``params`` with the spec's overrides for ``form`` applied (validated; errors name the key)."""
    d = params.to_dict()
    for o in spec.overrides_for(form):
        if o.name not in d:
            if o.form is None:
                continue  # a key of the other form
            raise SpecError(f"{spec.source}: override {o.key!r}: no such key in {form} params ({', '.join(d)})")
        if not o.index:
            d[o.name] = o.value
            continue
        tgt = d[o.name]
        try:
            for i in o.index[:-1]:
                tgt = tgt[i]
            tgt[o.index[-1]] = float(o.value)
        except (IndexError, TypeError):
            raise SpecError(f"{spec.source}: override {o.key!r}: index out of range for {o.name!r}") from None
    try:
        return type(params).from_dict(d)
    except ParamsError as exc:
        raise SpecError(f"{spec.source}: overrides make invalid {form} params: {exc}") from None


def override_notes(spec: HandSpec, params: Params) -> list[str]:
    """A note per override applied to ``params`` (those of its form whose key it has)."""
    keys = {k for k, _ in type(params).KEYS}
    return [f"override {o.key} = {o.value}: {o.reason}" for o in spec.overrides_for(params.form) if o.name in keys]


@dataclass
class ParseResult:
    """What :func:`parse` returns: final params, the initial estimate, the measurement, fit and notes."""

    params: Params
    form: str
    spec: HandSpec
    measurement: Measurement
    initial: Params
    fit: FitResult | None
    notes: list[str]

    @property
    def action_map(self) -> ActionMap:
        return self.measurement.action_map

    @property
    def hand(self) -> OriginalHand:
        return self.measurement.hand

    @property
    def couplings(self) -> tuple[Coupling, ...]:
        """Canonical couplings of this hand and form (``slot = multiplier * driver + offset``)."""
        return tuple(self.measurement.action_map.couplings)


def load_original_for(spec: HandSpec, hands_root: str | Path | None = None) -> OriginalHand:
    """The original hand of ``spec`` (its URDF loaded and its joint names checked)."""
    path = spec.urdf_path(hands_root)
    if not path.is_file():
        from ohra.errors import AssetsNotFoundError

        tried = ", ".join(str(c) for c in spec.urdf_candidates(hands_root))
        raise AssetsNotFoundError(f"{spec.source}: original URDF {spec.urdf!r} not found (tried {tried}; set OHRA_HANDS_ROOT)")
    hand = load_urdf(path, root_link=spec.root_link, xacro_args=spec.xacro_args)
    spec.check_joints(hand)
    return hand


def _unmapped_mimic_drivers(slots, hand: OriginalHand) -> list[str]:
    """Notes for actuated joints that no slot maps but that mapped ``<mimic>`` joints follow: the mimic's slot
    then drives them (a palm piece's spread joint), and a finger joint forgotten in the spec shows only as a large
    fingertip error without this line."""
    from ohra.original.action import mimic_relations

    rel = mimic_relations(slots, hand)
    mapped = {sm.name for sm in slots.values()}
    out = []
    for root in sorted({r for r, _, _ in rel.values()} - mapped):
        followers = [f"{slot} (mimic {sm.name!r})" for slot, sm in sorted(slots.items()) if sm.name in rel and rel[sm.name][0] == root]
        out.append(f"approximation: actuated joint {root!r} has no slot; it moves with {', '.join(followers)}, which drives it: "
                   f"if it is a finger joint the canonical hand has, map it to its slot (else its motion counts in the errors)")
    return out


def parse(
    spec: HandSpec | str | Path,
    form: str = "base",
    fit_params: bool = True,
    hands_root: str | Path | None = None,
    hand: OriginalHand | None = None,
) -> ParseResult:
    """Original URDF + spec -> canonical params of ``form`` (``"base"`` or ``"extended"``)."""
    if not isinstance(spec, HandSpec):
        spec = load_spec(spec)
    if form not in ("base", "extended"):
        raise SpecError(f"unknown form {form!r}; expected 'base' or 'extended'")
    spec.form(form)
    if hand is None:
        hand = load_original_for(spec, hands_root)
    else:
        spec.check_joints(hand)
    m = measure(hand, spec, form)
    m.notes.extend(check_palm_frame(m, spec, form))
    m.notes.extend(_unmapped_mimic_drivers(m.action_map.slots, hand))
    try:
        init = initial_base(m, spec, form) if form == "base" else initial_extended(m, spec, form)
    except ParamsError as exc:
        pts = [np.asarray(v, dtype=float) for fm in m.fingers.values() for v in fm.p.values()]
        size = max((float(np.linalg.norm(v)) for v in pts), default=0.0)
        arm = arm_hint(m, spec)
        hint = (f" (the finger joints lie up to {size:.1f} m from the palm frame: {arm})" if arm and size > 0.5 else
                f" (the finger joints lie up to {size:.1f} m from the palm frame: is {spec.urdf} written in millimetres? "
                "URDF lengths are metres)" if size > 1.0 else "")
        raise ParseError(f"{spec.source}: measured {form} parameters are invalid: {exc}{hint}") from None
    params: Params = init
    fr = None
    if fit_params:
        params, fr = fit(init, m, spec.fit_samples, spec.fit_seed)
        m.notes.extend(fr.notes)
    else:
        params = rounded(init)
    params = _separate_fingers(params, m.action_map, m.notes)
    params = apply_overrides(params, spec, form)
    notes = list(m.notes) + override_notes(spec, params)
    notes += [f"coupling: {line}" for line in describe(m.couplings)]
    return ParseResult(params, form, spec, m, init, fr, notes)


__all__ = ["parse", "ParseResult", "ParseWarning", "apply_overrides", "load_original_for"]
