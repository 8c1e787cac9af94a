"""HandSpec YAML: the registered specs load; malformed specs raise SpecError naming the problem."""

from __future__ import annotations

import re

import pytest

from ohra.errors import SpecError
from ohra.original.spec import load_spec
from ohra.hands import registry
from ohra.resources import leap_dir

MINIMAL = """
name: toy
urdf: toy.urdf
palm_origin: {xyz: [0, 0, 0], rpy: [0, 0, 0]}
joints:
  index_joint2: a
  index_joint3: {joint: b, sign: -1, offset: 0.5}
forms:
  base: {}
  extended:
    joints: {index_joint3: null}
    fixed: {index_joint3: 0.1}
"""


def test_every_registered_spec_loads_and_names_its_forms():
    names = registry.registered_hands()
    assert len(names) == 16
    for n in names:
        sp = registry.spec(n)
        assert sp.name == n
        assert set(sp.forms) == set(registry.registered_forms(n))
    assert registry.registered_forms("mano") == ["extended"]


def test_shorthand_sign_offset_and_per_form_changes():
    sp = load_spec(MINIMAL)
    base = sp.form("base")
    assert base.slots["index_joint2"].name == "a" and base.slots["index_joint2"].sign == 1.0
    assert base.slots["index_joint3"].sign == -1.0 and base.slots["index_joint3"].offset == 0.5
    ext = sp.form("extended")
    assert "index_joint3" not in ext.slots and ext.fixed == {"index_joint3": 0.1}
    am = sp.action_map("base", ["a", "b", "c"])
    assert am.to_canonical([0.0, 1.0, 0.0])[7] == pytest.approx(-0.5)


@pytest.mark.parametrize(
    "change, message",
    [
        (("  index_joint3: {joint: b, sign: -1, offset: 0.5}", "  index_joint3: a"), "duplicate mapping"),
        (("  index_joint2: a", "  index_joint2: a\n  index_joint2: b"), "duplicate key 'index_joint2'"),
        (("  index_joint2: a", "  pinky_joint2: a"), "unknown canonical slot 'pinky_joint2'"),
        (("sign: -1,", "sign: 2,"), "expected 1 or -1"),
        (("palm_origin: {xyz: [0, 0, 0], rpy: [0, 0, 0]}", "palm_origin: [0, 0]"), "palm_origin"),
        (("    fixed: {index_joint3: 0.1}", "    fixed: {index_joint2: 0.1}"), "both mapped and fixed"),
        (("name: toy", "name: toy\ncolour: red"), "unknown key(s) ['colour']"),
        (("urdf: toy.urdf\n", ""), "missing key 'urdf'"),
        (("{xyz: [0, 0, 0], rpy: [0, 0, 0]}", "{rpy: [0, 0, 0]}"), "palm_origin: missing 'xyz'"),
        (("xyz: [0, 0, 0]", "xyz: [0, 0, -95]"), "palm_origin: xyz [0.0, 0.0, -95.0] is 95 m from the root link"),
        (("xyz: [0, 0, 0]", "xyz: [0, 0.3, -0.41]"), "millimetres?"),  # 0.508 m: just past the bound
        (("rpy: [0, 0, 0]", "rpy: [0, 0, 90]"), "palm_origin: rpy [0.0, 0.0, 90.0] beyond +-2 pi"),
    ],
)
def test_malformed_specs_name_the_problem(change, message):
    text = MINIMAL.replace(*change)
    assert text != MINIMAL
    with pytest.raises(SpecError, match=re.escape(message)):
        load_spec(text)


def test_a_palm_origin_just_inside_the_bound_loads():
    sp = load_spec(MINIMAL.replace("xyz: [0, 0, 0], rpy: [0, 0, 0]", "xyz: [0, 0.3, -0.39], rpy: [0, 0, 6.28]"))
    assert sp.palm_origin.tolist() == [0, 0.3, -0.39, 0, 0, 6.28]


def test_override_needs_a_reason():
    text = MINIMAL + "overrides:\n  - {key: palm_radius, value: 0.05}\n"
    with pytest.raises(SpecError, match="missing 'reason'"):
        load_spec(text)
    ok = load_spec(MINIMAL + "overrides:\n  - {key: 'finger_lengths[0][2]', value: 0.05, reason: tip pad not modelled}\n")
    assert ok.overrides[0].name == "finger_lengths" and ok.overrides[0].index == (0, 2)


def test_an_override_of_a_key_no_form_has_is_refused_not_skipped():
    """A misspelt key was skipped as 'a key of the other form' and then reported as applied."""
    with pytest.raises(SpecError, match="no parameter 'finger_radiuz' in the base or extended form"):
        load_spec(MINIMAL + "overrides:\n  - {key: finger_radiuz, value: 0.01, reason: typo}\n")
    with pytest.raises(SpecError, match="no parameter 'finger_radii' in the base form"):  # an extended-only key
        load_spec(MINIMAL + "overrides:\n  - {key: finger_radii, value: 0.01, reason: r, form: base}\n")
    ext_only = load_spec(MINIMAL + "overrides:\n  - {key: finger_radii, value: 0.01, reason: r}\n")  # the other form's: fine
    assert ext_only.overrides[0].name == "finger_radii"


def test_check_joints_names_the_missing_joint():
    sp = load_spec(MINIMAL)
    with pytest.raises(SpecError, match="'b', which is not a movable joint"):
        sp.check_joints(["a", "c"])


def test_spec_files_are_not_confused_with_other_yaml():
    # leap_template.yaml is the LEAP-variant input, not a hand spec
    assert (leap_dir() / "template.yaml").is_file()
    assert "leap_template" not in registry.registered_hands()
