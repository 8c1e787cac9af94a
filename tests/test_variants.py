"""LEAP variants: naming, the derivation rules, and the template derived from the real LEAP URDF."""

from __future__ import annotations

import numpy as np
import pytest

from ohra import HandNotFoundError
from ohra.hands import get_hand, variant_names
from ohra.hands.leap.template import derive_leap_template, load_leap_template
from ohra.canonical.params import FINGER_SLICES


def test_there_are_256_variants():
    names = variant_names()
    assert len(names) == 256 and len(set(names)) == 256
    assert names[0] == "leap_0000" and names[-1] == "leap_3333"


@pytest.mark.parametrize(
    "name, fingers, dof",
    [("leap_3333", 4, 16), ("leap_3303", 3, 12), ("leap_2203", 3, 10), ("leap_1000", 1, 2), ("leap_0000", 0, 0)],
)
def test_variant_structure(name, fingers, dof):
    p = get_hand(name)
    assert p.template == "leap" and p.num_fingers == fingers and p.dof == dof
    assert not p.present_joints[FINGER_SLICES["ring"]].any()
    assert not p.present_joints[17]  # little_joint0 never


def test_link_rules_of_a_two_link_finger():
    p = get_hand("leap_2203")
    links = p.link_presence()
    assert links["thumb"] == (True, True, False)
    assert links["index"] == (True, True, False)  # flexion + abduction + middle link
    assert p.present_joints[5:9].tolist() == [True, True, True, False]
    assert p.finger_lengths[1, 2] == 0.0


def test_unknown_variant_is_a_clear_error():
    with pytest.raises(HandNotFoundError, match="leap_4444"):
        get_hand("leap_4444")


def test_committed_template_matches_the_published_values():
    t = load_leap_template()
    assert t.palm_radius == 0.057
    assert np.allclose(t.finger_lengths[1], (0.0531, 0.0361, 0.052), atol=1e-4)
    assert np.allclose(t.finger_lengths[0], (0.0313, 0.0466, 0.06), atol=1e-4)
    assert np.allclose(t.joint_origins[3, :3], (0, 0.0465, 0.091), atol=2e-4)
    assert np.allclose(t.joint_origins[5, :3], (0, 0.0011, 0.091), atol=2e-4)
    assert np.allclose(t.joint_origins[10, :3], (0, -0.0443, 0.091), atol=2e-4)
    assert np.allclose(t.joint_origins[0], (0.0029, 0.0368, 0.0157, -1.5708, -1.5708, 0), atol=5e-3)
    assert np.allclose(t.joint_lowers[5:9], (-0.314, -1.047, -0.506, -0.366))


def test_template_is_derived_from_the_leap_urdf(hands_dir):
    derived = derive_leap_template(hands_dir / "leap_hand" / "leap_hand_right.urdf")
    assert derived.isclose(load_leap_template(), atol=1e-9)
