"""HandSpec: the minimal manual input that brings an original hand into the canonical form.

A spec is a small YAML file (the registered hands' specs live in ``ohra/hands/specs/<name>.yaml``)::

    name: shadow_hand_right                  # registry name (default: the file stem)
    urdf: shadow_hand/shadow_hand_right.urdf  # original URDF (.urdf / .xacro), relative to the
                                              # hand-assets root (ohra.paths.hands_root()) or absolute
    root_link: forearm                        # optional: the hand's own root in a URDF that holds an arm
                                              #   (only it and its subtree are loaded; default: the URDF's root)
    xacro_args: {prefix: ""}                  # optional: <xacro:arg> values for a .xacro URDF ($(find pkg) is
                                              #   resolved by folder name, as package:// mesh paths are)
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
    couplings:                                # optional: canonical couplings the URDF does not state
      - {slot: index_joint4, driver: index_joint3, multiplier: 0.8, offset: 0.0}
    fit: {samples: 96, seed: 0}               # optional least-squares fit settings

A slot may name a ``<mimic>`` joint of the URDF like any other joint: its coupling to the slot of
the joint it follows (through chains of mimics) is read from the URDF and carried as
``slot = multiplier * driver + offset`` in canonical terms (:mod:`ohra.canonical.couplings`);
when the followed joint has no slot, the first such mimic slot drives it
(:func:`ohra.original.action.mimic_couplings`). ``couplings`` declares more such relations (both slots
mapped in each form where it applies). A relative ``urdf`` path is looked up next to the spec file
first, then under the hand-assets root.

Canonical slots are the 22 names of :data:`ohra.canonical.params.JOINT_NAMES`. Each original joint drives at
most one slot per form (a duplicate is an error), a slot is either mapped or fixed, and every
named original joint must be a movable joint of the URDF, mimic joints included (checked by
:meth:`HandSpec.check_joints`). Malformed specs raise :class:`ohra.SpecError` naming the file and
the key; a YAML syntax error is one line with its line and column.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from ohra.canonical.couplings import Coupling
from ohra.errors import MappingError, SpecError
from ohra.original.action import ActionMap, SlotMap, mimic_relations
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
    couplings: tuple[Coupling, ...] = ()  # declared in the spec (canonical slots)
    base_dir: Path | None = None  # folder of the spec file (relative urdf paths are tried here first)
    root_link: str | None = None  # the hand's own root link in a URDF that holds more (an arm); None: the URDF's root
    xacro_args: dict[str, str] = field(default_factory=dict)  # <xacro:arg> values of a .xacro URDF

    # -- paths -----------------------------------------------------------------------------------
    def urdf_candidates(self, root: str | Path | None = None) -> list[Path]:
        """Where the original URDF is looked for, in order: next to the spec file, then under the
        hand-assets root (``root`` when given, tried first; default :func:`ohra.paths.hands_root`)."""
        p = Path(self.urdf).expanduser()
        if p.is_absolute():
            return [p]
        out = [Path(root) / p] if root is not None else []
        if self.base_dir is not None:
            out.append(self.base_dir / p)
        if root is None:
            out.append(hands_root() / p)
        return out

    def urdf_path(self, root: str | Path | None = None) -> Path:
        """The original URDF: the first of :meth:`urdf_candidates` that exists (else the first)."""
        cands = self.urdf_candidates(root)
        return next((c for c in cands if c.is_file()), cands[0])

    # -- mapping ---------------------------------------------------------------------------------
    def form(self, form: str) -> FormSpec:
        if form not in self.forms:
            raise SpecError(f"{self.source}: hand {self.name!r} has no {form!r} form (forms: {', '.join(self.forms)})")
        return self.forms[form]

    def check_joints(self, hand: Any) -> None:
        """Raise :class:`SpecError` if a slot names a joint that is not a movable joint of the URDF.

        ``hand``: an :class:`~ohra.original.hand.OriginalHand` (mimic joints may be mapped; the
        message says what a bad name is) or the names of its actuated joints.
        """
        actuated, joints = _joint_info(hand)
        mimic = [n for n, j in joints.items() if getattr(j, "mimic", None) is not None and n not in actuated]
        for fname, fs in self.forms.items():
            for slot, sm in fs.slots.items():
                if sm.name in actuated or sm.name in mimic:
                    if getattr(joints.get(sm.name), "type", None) == "prismatic":
                        # its limits are metres: read as a revolute slot's radians they made a hand of 1-2 m fingers
                        raise SpecError(f"{self.source}: forms.{fname} slot {slot!r} names joint {sm.name!r}, a prismatic "
                                        f"joint of {self.urdf}: canonical slots are revolute (radians); map a revolute "
                                        "or continuous joint, or leave the slot out")
                    continue
                j = joints.get(sm.name)
                why = "which is not a movable joint of" if j is None else f"which is a {j.type} joint (not movable) of"
                raise SpecError(
                    f"{self.source}: forms.{fname} slot {slot!r} names joint {sm.name!r}, {why} {self.urdf} "
                    f"(movable joints: {', '.join(actuated)}" + (f"; mimic joints: {', '.join(mimic)})" if mimic else ")")
                )

    def couplings_for(self, form: str, hand: Any = None) -> tuple[Coupling, ...]:
        """Canonical couplings of ``form``: from the URDF's ``<mimic>`` tags of mapped joints (when
        ``hand`` is an :class:`~ohra.original.hand.OriginalHand`) and declared in the spec; resolved."""
        return tuple(self.action_map(form, hand).couplings) if hasattr(hand, "mimic_root") else self.declared_couplings(form)

    def declared_couplings(self, form: str) -> tuple[Coupling, ...]:
        """The spec's own couplings that apply to ``form`` (both slots mapped there)."""
        fs = self.form(form)
        return tuple(c for c in self.couplings if c.slot in fs.slots and c.driver in fs.slots)

    def action_map(self, form: str, hand: Any) -> ActionMap:
        """The :class:`ohra.ActionMap` of ``form`` for an original hand (an
        :class:`~ohra.original.hand.OriginalHand`, or its actuated joint names in file order)."""
        self.check_joints(hand)
        fs = self.form(form)
        actuated, _ = _joint_info(hand)
        mimic = mimic_relations(fs.slots, hand) if hasattr(hand, "mimic_root") else {}
        try:
            return ActionMap(fs.slots, list(actuated), self.palm_origin, fs.fixed,
                             couplings=self.declared_couplings(form), mimic=mimic)
        except MappingError as exc:
            raise SpecError(f"{self.source}: forms.{form}: {exc}") from None

    def overrides_for(self, form: str) -> list[Override]:
        return [o for o in self.overrides if o.form in (None, form)]


def _joint_info(hand: Any) -> tuple[tuple[str, ...], dict[str, Any]]:
    """(actuated joint names, name -> joint) of an OriginalHand, or of a plain list of names."""
    if hasattr(hand, "joints") and hasattr(hand, "movable_joints"):
        return tuple(hand.movable_joints), dict(hand.joints)
    names = tuple(hand)
    return names, {n: None for n in names}


def spec_from_dict(d: Any, source: str = "<spec>", default_name: str = "hand", base_dir: Path | None = None) -> HandSpec:
    """Build and validate a :class:`HandSpec` from a parsed YAML mapping (see :mod:`ohra.original.spec_yaml`)."""
    from ohra.original.spec_yaml import spec_from_dict as build

    return build(d, source, default_name, base_dir)


def read_yaml(text: str, where: str) -> Any:
    """Parse YAML text; a syntax error or duplicate key is a one-line :class:`SpecError` with the line."""
    from ohra.original.spec_yaml import read_yaml as read

    return read(text, where)


def load_spec(source: str | Path) -> HandSpec:
    """Read a spec YAML file (or YAML text containing a newline)."""
    from ohra.original.spec_yaml import load_spec as load

    return load(source)


__all__ = ["HandSpec", "FormSpec", "Override", "load_spec", "spec_from_dict", "read_yaml", "FORMS"]
