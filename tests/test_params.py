"""BaseParams / ExtendedParams: serialisation round trips, masks, conversions and validation."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import ohra
from ohra import ParamsError
from ohra.canonical.params import JOINT_NAMES, BaseParams, ExtendedParams, load_params
from ohra.canonical.urdfgen import render
from ohra.hands.registry import registered_forms


# -- round trips ------------------------------------------------------------------------------
def test_base_vector_dict_file_round_trip(shadow_base, tmp_path):
    v = shadow_base.to_vector()
    assert v.shape == (82,)
    assert BaseParams.from_vector(v) == shadow_base
    assert BaseParams.from_dict(shadow_base.to_dict()) == shadow_base
    path = tmp_path / "p.json"
    shadow_base.to_json(path)
    assert BaseParams.from_json(path) == shadow_base
    assert load_params(path) == shadow_base


def test_extended_vector_dict_file_round_trip(allegro_ext, tmp_path):
    v = allegro_ext.to_vector()
    assert v.shape == (173,)
    assert ExtendedParams.from_vector(v) == allegro_ext
    path = tmp_path / "p.json"
    allegro_ext.to_json(path)
    assert load_params(path) == allegro_ext


def test_json_is_written_in_canonical_key_order_and_read_in_any_order(shadow_base, tmp_path):
    keys = list(json.loads(shadow_base.to_json()))
    assert keys == [k for k, _ in BaseParams.KEYS]
    d = shadow_base.to_dict()
    shuffled = {k: d[k] for k in reversed(list(d))}
    (tmp_path / "s.json").write_text(json.dumps(shuffled))
    assert load_params(tmp_path / "s.json") == shadow_base


def test_json_uses_reference_shapes(shadow_base, allegro_ext):
    d = json.loads(shadow_base.to_json())
    assert [len(r) for r in d["joint_lowers"]] == [5, 4, 4, 4, 5]
    e = json.loads(allegro_ext.to_json())
    assert [len(r) for r in e["joint_origins"]] == [3, 2, 2, 2, 3]
    assert all(len(x) == 6 for r in e["joint_origins"] for x in r)


def test_json_is_deterministic_without_negative_zero(shadow_base):
    v = shadow_base.to_vector()
    v[v == 0.0] = -0.0
    p = BaseParams.from_vector(v)
    assert not re.search(r"-0\.0(?!\d)", p.to_json())
    assert p.to_json() == shadow_base.to_json()


def test_isclose_tolerance(shadow_base):
    v = shadow_base.to_vector()
    v[0] += 1e-7
    other = BaseParams.from_vector(v)
    assert shadow_base.isclose(other, atol=1e-6)
    assert not shadow_base.isclose(other, atol=1e-9)
    assert shadow_base != other


# -- masks and derived properties ------------------------------------------------------------------
def test_masks_and_counts(shadow_base, allegro_ext):
    assert shadow_base.present_joints.all() and shadow_base.num_fingers == 5
    assert shadow_base.handedness == "right"
    pattern = "".join("1" if x else "0" for x in allegro_ext.present_joints)
    assert pattern == "1101111111111000001111"
    assert allegro_ext.num_fingers == 4
    assert not allegro_ext.present_fingers[3]
    assert allegro_ext.movable_joints.sum() == 16


def test_frozen_joint_is_present_but_not_movable(shadow_base):
    lo, up = shadow_base.joint_lowers.copy(), shadow_base.joint_uppers.copy()
    lo[5] = up[5] = 0.088  # Allegro-style fixed tilt
    p = BaseParams.from_dict({**shadow_base.to_dict(), "joint_lowers": lo, "joint_uppers": up})
    assert p.present_joints[5] and not p.movable_joints[5]


def test_left_hand_is_detected(shadow_base):
    xyz = shadow_base.finger_xyz * np.array([1, -1, 1])
    p = BaseParams.from_dict({**shadow_base.to_dict(), "finger_xyz": xyz})
    assert p.handedness == "left"


def test_a_thumb_on_the_centre_line_leaves_the_side_to_the_fingers(shadow_base):
    """Parse round-off (Barrett's extended thumb at y = -1e-6 m) must not make a right hand left;
    10 um off the x-z plane is on it, 20 um is a side."""
    xyz = shadow_base.finger_xyz.copy()
    for thumb_y, side in ((-5e-6, "right"), (-2e-5, "left")):
        xyz[0, 1] = thumb_y
        assert BaseParams.from_dict({**shadow_base.to_dict(), "finger_xyz": xyz}).handedness == side


def test_every_registered_hand_has_one_side_in_both_forms():
    for name in ohra.list_hands():
        sides = {form: ohra.get_hand(name, form).handedness for form in registered_forms(name)}
        assert len(set(sides.values())) == 1, f"{name}: {sides}"
        assert sides[next(iter(sides))] == ("left" if name.endswith("_left") else "right"), f"{name}: {sides}"


# -- base <-> extended -------------------------------------------------------------------------------
def test_base_to_extended_and_back_is_exact(shadow_base):
    ext = shadow_base.to_extended()
    assert ext.to_base() == shadow_base


def test_extended_with_per_finger_radii_has_no_base_form(allegro_ext):
    with pytest.raises(ParamsError, match="not representable in base form"):
        allegro_ext.to_base()


def test_leap_flavour_has_no_base_form():
    from ohra.hands import get_hand

    with pytest.raises(ParamsError, match="template 'leap'"):
        get_hand("leap_3333").to_base()


# -- validation: each rule names key and index ---------------------------------------------------------
def _with(p, **changes):
    d = p.to_dict()
    d.update(changes)
    return d


def test_missing_key(shadow_base):
    d = shadow_base.to_dict()
    del d["thumb_rpy"]
    with pytest.raises(ParamsError, match="missing key 'thumb_rpy'"):
        BaseParams.from_dict(d)


def test_unknown_key(shadow_base):
    with pytest.raises(ParamsError, match="unknown key"):
        BaseParams.from_dict(_with(shadow_base, wrist=1.0))


def test_wrong_shape(shadow_base):
    with pytest.raises(ParamsError, match=r"'finger_xyz': expected shape \(5, 3\), got \(4, 3\)"):
        BaseParams.from_dict(_with(shadow_base, finger_xyz=shadow_base.finger_xyz[:4]))
    with pytest.raises(ParamsError, match=r"'joint_lowers': expected rows of lengths \[5, 4, 4, 4, 5\]"):
        BaseParams.from_dict(_with(shadow_base, joint_lowers=[[0] * 4] * 5))


def test_vector_of_wrong_length():
    with pytest.raises(ParamsError, match="length 82, got 81"):
        BaseParams.from_vector(np.zeros(81))


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_value_named_with_index(shadow_base, bad):
    xyz = shadow_base.finger_xyz.copy()
    xyz[2, 1] = bad
    with pytest.raises(ParamsError, match=r"'finger_xyz'\[2\]\[1\] is not finite"):  # the index as JSON writes it, not [7]
        BaseParams.from_dict(_with(shadow_base, finger_xyz=xyz))


def test_negative_radius_and_length(shadow_base, allegro_ext):
    with pytest.raises(ParamsError, match=r"'finger_radius'\[0\] = -0.01 is outside radius bounds"):
        BaseParams.from_dict(_with(shadow_base, finger_radius=-0.01))
    fl = shadow_base.finger_lengths.copy()
    fl[1, 2] = -0.02
    with pytest.raises(ParamsError, match=r"'finger_lengths'\[1\]\[2\] = -0.02 is outside length bounds"):
        BaseParams.from_dict(_with(shadow_base, finger_lengths=fl))
    radii = allegro_ext.finger_radii.copy()
    radii[1] = -0.001
    with pytest.raises(ParamsError, match=r"'finger_radii'\[1\]"):
        ExtendedParams.from_dict(_with(allegro_ext, finger_radii=radii))


def test_capsule_shorter_than_diameter(shadow_base):
    fl = shadow_base.finger_lengths.copy()
    fl[0, 1] = 0.01  # thumb middle, radius 0.0087 -> diameter 0.0174
    with pytest.raises(ParamsError, match=r"'finger_lengths'\[1\] = 0.01 m: capsule thumb_middle is shorter than its diameter"):
        BaseParams.from_dict(_with(shadow_base, finger_lengths=fl))


def test_lower_above_upper(shadow_base):
    lo = shadow_base.joint_lowers.copy()
    lo[9] = 2.0
    with pytest.raises(ParamsError, match=r"joint_lowers\[9\] = 2 > joint_uppers\[9\] = 0.3491 \(middle_joint1\)"):
        BaseParams.from_dict(_with(shadow_base, joint_lowers=lo))


def test_zero_or_non_unit_axis_on_present_joint(shadow_base, allegro_ext):
    ax = shadow_base.thumb_axes.copy()
    ax[1] = 0.0
    with pytest.raises(ParamsError, match=r"'thumb_axes'\[3\] is a zero axis but thumb_joint2 is present"):
        BaseParams.from_dict(_with(shadow_base, thumb_axes=ax))
    ax = allegro_ext.joint_axes.copy()
    ax[3] = (0.0, 0.5, 0.5)
    with pytest.raises(ParamsError, match=r"'joint_axes'\[9\] .* is not a unit axis .* for index_joint1"):
        ExtendedParams.from_dict(_with(allegro_ext, joint_axes=ax))


def test_zero_axis_allowed_on_absent_joint(allegro_ext):
    assert not allegro_ext.present_joints[2] and not np.any(allegro_ext.joint_axes[2])


def test_finger_with_links_but_no_base_joint(shadow_base, allegro_ext):
    xyz = shadow_base.finger_xyz.copy()
    xyz[3] = 0.0
    with pytest.raises(ParamsError, match="finger 'ring' has links but no base joint position"):
        BaseParams.from_dict(_with(shadow_base, finger_xyz=xyz))
    o = allegro_ext.joint_origins.copy()
    o[5] = 0.0  # middle j1 origin
    with pytest.raises(ParamsError, match="finger 'middle' has links but no base joint position"):
        ExtendedParams.from_dict(_with(allegro_ext, joint_origins=o))


def test_values_outside_physical_bounds(shadow_base):
    with pytest.raises(ParamsError, match=r"'palm_radius'\[0\] = 0.5 is outside radius bounds \(m\) \[0.0001, 0.2\]"):
        BaseParams.from_dict(_with(shadow_base, palm_radius=0.5))
    lo, up = shadow_base.joint_lowers.copy(), shadow_base.joint_uppers.copy()
    up[0] = 10.0
    with pytest.raises(ParamsError, match=r"'joint_uppers'\[0\] = 10 is outside joint angle bounds"):
        BaseParams.from_dict(_with(shadow_base, joint_uppers=up))


def test_non_numeric_value(shadow_base):
    with pytest.raises(ParamsError, match="'thumb_rpy'"):
        BaseParams.from_dict(_with(shadow_base, thumb_rpy=["a", "b", "c"]))


def test_malformed_json_text_and_file(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text("{ not json")
    with pytest.raises(ParamsError, match=r"bad.json: malformed JSON"):
        load_params(bad)
    with pytest.raises(ParamsError, match="cannot tell the form"):
        load_params({"palm_radius": 0.05})
    with pytest.raises(ParamsError, match="params file not found"):
        load_params(tmp_path / "missing.json")


# -- property-based: nothing but ParamsError escapes validation and rendering ---------------------------
_finite = st.floats(min_value=-1.0, max_value=1.0, allow_nan=False)
_any = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-5, 5))


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(_any, min_size=82, max_size=82))
def test_random_base_vectors_only_raise_params_error(values):
    try:
        p = BaseParams.from_vector(values)
    except ParamsError:
        return
    render(p)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(_finite, min_size=173, max_size=173), st.sampled_from(["extended", "leap"]))
def test_random_extended_vectors_only_raise_params_error(values, template):
    try:
        p = ExtendedParams.from_vector(values, template=template)
    except ParamsError:
        return
    render(p)


@settings(max_examples=100, deadline=None)
@given(st.data())
def test_perturbed_valid_params_only_raise_params_error(data):
    base = load_params(__import__("pathlib").Path(__file__).parent / "data" / "shadow_hand_right_base.json")
    v = base.to_vector()
    idx = data.draw(st.lists(st.integers(0, 81), min_size=1, max_size=5))
    for i in idx:
        v[i] = data.draw(st.one_of(st.floats(allow_nan=True), st.just(0.0), st.floats(-0.1, 0.1)))
    try:
        p = BaseParams.from_vector(v)
    except ParamsError:
        return
    render(p)


@settings(max_examples=60, deadline=None)
@given(st.recursive(st.one_of(st.none(), st.booleans(), st.floats(), st.text(max_size=3)), lambda c: st.lists(c, max_size=4), max_leaves=20))
def test_malformed_structures_only_raise_params_error(junk):
    """Junk under any key is either rejected with a ParamsError that names that key, or is a
    well-formed value that the params then hold exactly."""
    path = __import__("pathlib").Path(__file__).parent / "data" / "shadow_hand_right_base.json"
    for k, shape in BaseParams.KEYS:
        d = json.loads(path.read_text())
        d[k] = junk
        try:
            p = BaseParams.from_dict(d)
        except ParamsError as exc:
            assert repr(k) in str(exc), (k, junk, str(exc))
            continue
        assert np.asarray(getattr(p, k), dtype=float).reshape(shape).tolist() == np.asarray(junk, dtype=float).reshape(shape).tolist()


def test_joint_names_are_canonical():
    assert JOINT_NAMES[0] == "thumb_joint1" and JOINT_NAMES[17] == "little_joint0" and len(JOINT_NAMES) == 22


def test_segment_mask_is_the_one_rule_for_single_hands_and_batches():
    from ohra.canonical.params import link_presence, segment_mask
    from ohra.learn.encoding import segment_presence

    rng = np.random.default_rng(5)
    present = rng.random((64, 22)) < 0.5
    seg_t, seg_f, fingers = segment_presence(present)
    for template in ("standard", "leap"):
        batch = segment_mask(present, template)
        for row, mask in zip(present, batch):
            d = link_presence(row, template)
            assert [d[f] for f in ("thumb", "index", "middle", "ring", "little")] == [tuple(r) for r in mask.tolist()]
    # spot checks of the rules: little_joint0 alone carries no segment; index j3 alone is the middle link
    p = np.zeros(22, dtype=bool)
    p[17] = True
    assert not segment_mask(p).any()
    p[:] = False
    p[7] = True
    assert segment_mask(p)[1].tolist() == [False, True, False]
    assert segment_mask(p, "leap")[1].tolist() == [False, True, False]
    p[:] = False
    p[6] = True  # index j2: proximal in the standard template, middle in the LEAP flavour
    assert segment_mask(p)[1].tolist() == [True, False, False]
    assert segment_mask(p, "leap")[1].tolist() == [False, True, False]
    np.testing.assert_array_equal(seg_t, segment_mask(present)[:, 0])
    np.testing.assert_array_equal(fingers, segment_mask(present).any(axis=2))
