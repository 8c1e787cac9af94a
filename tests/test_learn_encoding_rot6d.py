"""The 70-D rot6d encoding: layout, exact round trips, stand-ins for absent parts, plausible decoding."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import ohra
from ohra.canonical.kinematics import HandModel
from ohra.canonical.params import BaseParams
from ohra.errors import OhraError
from ohra.hands import hands_in_form
from ohra.learn import encoding_rot6d as E
from ohra.learn import geometry as geo
from ohra.learn.encoding import LatentError, project_vectors
from ohra.learn.encodings import ENCODINGS, get_encoding
from ohra.learn.sampler import EXTRA, LENGTHS, LOWERS, THUMB_RPY, UPPERS, XYZ, mirror_vectors, sample_vectors
from ohra.transforms import rpy_to_matrix


def _limits(v):
    return (v[:, LOWERS], v[:, UPPERS])


def test_layout_of_sampled_right_and_left_hands():
    v, right = sample_vectors(40, 3, return_handedness=True)
    x = E.encode_vectors(v)
    assert x.shape == (40, 70) and E.CONT_DIM + 12 + 22 + 1 == 70
    assert np.array_equal(x[:, E.LEFT.start], (~right).astype(float))
    assert np.array_equal(E.is_left(v), ~right)
    i = int(np.flatnonzero(right)[0])
    R = rpy_to_matrix(v[i, THUMB_RPY])
    assert np.allclose(x[i, E.ROT6D], np.r_[R[:, 2], R[:, 0]])  # the thumb's direction first
    assert np.array_equal(x[i, 0:29][[8, 9, 10]], v[i, XYZ][:3])
    # a left hand encodes as its mirror image, a right hand, plus the flag
    j = int(np.flatnonzero(~right)[0])
    assert np.array_equal(x[j, :69], E.encode_vectors(mirror_vectors(v[j : j + 1]))[0, :69])
    assert np.all(x[:, E.AXIS1].sum(1) == 1) and np.all(x[:, E.AXIS2].sum(1) == 1)
    assert np.array_equal(x[:, E.FLAGS], (v[:, LOWERS] != v[:, UPPERS]).astype(float))
    assert get_encoding("rot6d70").dim == 70 and set(ENCODINGS) == {"reference66", "rot6d70"}
    with pytest.raises(OhraError, match="known: reference66, rot6d70"):
        get_encoding("euler")


def test_handedness_follows_base_params():
    hands = list(hands_in_form("base").values()) + [BaseParams.from_vector(r) for r in sample_vectors(30, 12)]
    v = np.stack([p.to_vector() for p in hands])
    assert E.is_left(v).tolist() == [p.handedness == "left" for p in hands]


def test_round_trip_is_exact_for_sampled_hands_with_their_limits():
    v = sample_vectors(3000, 4)
    w = E.decode_vectors(E.encode_vectors(v), limits=_limits(v))
    assert np.abs(w - v).max() < 1e-12


def test_registered_hands_round_trip_up_to_equivalent_rpy_and_snapped_axes():
    for p in hands_in_form("base").values():
        v = p.to_vector()[None]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            w = E.decode_vectors(E.encode_vectors(v), limits=p)
        keep = np.ones(82, bool)
        keep[THUMB_RPY] = False
        keep[32:38] = False  # axes: snapped to signed basis axes
        assert np.abs(w[:, keep] - v[:, keep]).max() < 1e-12, p
        assert np.abs(rpy_to_matrix(v[:, THUMB_RPY]) - rpy_to_matrix(w[:, THUMB_RPY])).max() < 1e-12


def test_stand_ins_for_absent_parts_are_plausible_and_decoding_removes_them():
    v = sample_vectors(4000, 5)
    f = E.fill_absent(v)
    present = (v[:, LOWERS] != 0) | (v[:, UPPERS] != 0)
    _, fingers = geo.finger_reach(v)
    k, kf = v[:, XYZ].reshape(-1, 5, 3), f[:, XYZ].reshape(-1, 5, 3)
    # present parts unchanged; every absent knuckle gets a place in the row, none at the origin
    assert np.array_equal(kf[fingers], k[fingers])
    assert np.all(np.any(kf[:, 1:] != 0, axis=2))
    assert np.all(kf[:, 1:, 2] > 0.5 * v[:, :1])
    # an absent finger between two present ones sits on the segment between them
    rows = np.flatnonzero(fingers[:, 1] & ~fingers[:, 2] & fingers[:, 3])
    assert rows.size > 50
    assert np.allclose(kf[rows, 2], (k[rows, 1] + k[rows, 3]) / 2)
    # index -> little order kept in y (right hands: decreasing)
    right = k[:, 0, 1] > 0
    assert np.all(np.diff(kf[right, 1:, 1], axis=1) < 0)
    assert np.all(f[:, LENGTHS] > 0) and np.all(f[~present[:, 17]][:, EXTRA][:, 3] != 0)
    x = E.encode_vectors(v)
    r = ~E.is_left(v)
    assert np.array_equal(x[r, 0:29], f[r, 0:29])
    assert np.abs(E.decode_vectors(x, limits=_limits(v)) - v).max() < 1e-12


@pytest.mark.parametrize("scale", [0.03, 1.0, 1e3])
def test_decoding_any_encoding_gives_valid_plausible_hands(scale):
    rng = np.random.default_rng(int(100 * scale))
    cont = rng.normal(0.0, scale, (300, 35)) + np.r_[0.05, 0.01, [0.04] * 6, [0, 0.02, 0.08] * 5, [0.0] * 12]
    x = np.concatenate([cont, rng.normal(size=(300, 12)), rng.random((300, 23))], axis=1)
    v = E.decode_vectors(x)
    for row in v:
        BaseParams.from_vector(row)
    assert not geo.knuckles_inside_palm(v).any()
    assert not geo.thumb_into_palm(v).any()
    assert (geo.finger_clearance(v) >= 0).all()
    coal = [HandModel.from_params(BaseParams.from_vector(r)).self_collision(np.zeros(22)) for r in v[:80]]
    assert not any(coal)
    left = x[:, E.LEFT.start] > 0.5
    again = v.copy()
    again[left] = mirror_vectors(v[left])
    again = E.project_plausible(project_vectors(again))
    again[left] = mirror_vectors(again[left])
    assert np.array_equal(again, v), "projection is idempotent"


def test_projection_is_continuous_along_a_path():
    """A fine straight path between two random encodings moves no fingertip by a jump."""
    rng = np.random.default_rng(9)
    a, b = (np.concatenate([rng.normal(0, 0.03, 35) + 0.03, rng.normal(size=12), np.ones(22), [0.0]]) for _ in range(2))
    t = np.linspace(0, 1, 401)[:, None]
    v = E.decode_vectors((1 - t) * a + t * b)
    tips = geo.tips_q0(v)
    step = np.nanmax(np.linalg.norm(np.diff(tips, axis=0), axis=-1), axis=1)
    assert np.max(step) < 20 * np.median(step) + 1e-6


def test_projection_turns_an_inward_thumb_out_by_the_smallest_rotation():
    v = sample_vectors(50, 11)
    R = rpy_to_matrix(v[:, THUMB_RPY])
    flipped = v.copy()
    # reflect each thumb direction through the plane facing the palm centre: now it points inwards
    w = geo.palm_centre(v) - v[:, XYZ][:, 0:3]
    w /= np.linalg.norm(w, axis=1, keepdims=True)
    d = R[:, :, 2]
    mirrored = d - 2 * np.sum(d * w, 1, keepdims=True) * w
    axis = np.cross(d, mirrored)
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    angle = np.arccos(np.clip(np.sum(d * mirrored, 1), -1, 1))
    from ohra.transforms import matrix_to_rpy

    flipped[:, THUMB_RPY] = matrix_to_rpy(geo.rotation_about(axis, angle) @ R)
    assert geo.thumb_into_palm(flipped).all()
    fixed = E.project_plausible(flipped)
    assert not geo.thumb_into_palm(fixed).any()
    # just outside the half-space (the smallest turn), and nothing else moved
    assert np.abs(geo.thumb_inwardness(fixed) + E.THUMB_OUTWARD_EPS).max() < 2e-7  # rpy storage near pitch +-pi/2
    keep = np.ones(82, bool)
    keep[THUMB_RPY] = False
    keep[XYZ.start : XYZ.start + 3] = False  # a turned thumb that then touches a finger is moved off it
    assert np.array_equal(fixed[:, keep], flipped[:, keep])
    assert np.mean(np.all(fixed[:, XYZ.start : XYZ.start + 3] == flipped[:, XYZ.start : XYZ.start + 3], axis=1)) > 0.8


def test_decoded_handedness_follows_the_left_flag_when_the_thumb_sits_at_y_0():
    """Barrett's thumb base sits at y = 0; a decoder output a hair below it must not turn a hand
    flagged left into a "right" one (BaseParams.handedness reads the thumb base's side first)."""
    x = E.encode_vectors(ohra.get_hand("barrett_hand", "base").to_vector())
    x[E.CONT.start + XYZ.start + 1] = -1e-4  # thumb base y, right-hand form
    for flag, hand in ((0.0, "right"), (1.0, "left")):
        x[E.LEFT.start] = flag
        v = E.decode_vectors(x)
        assert BaseParams.from_vector(v).handedness == hand and E.is_left(v[None])[0] == (hand == "left")
        assert v[XYZ.start + 1] == 0.0


def test_bad_inputs_raise_latent_errors():
    with pytest.raises(LatentError, match=r"\(70,\)"):
        E.decode_vectors(np.zeros(66))
    with pytest.raises(LatentError, match="non-finite"):
        E.decode_vectors(np.full(70, np.inf))
    with pytest.raises(LatentError, match=r"\(82,\)"):
        E.encode_vectors(np.zeros((2, 80)))
