"""The synthetic hand sampler: valid, seeded, every registered hand in its support, plausible hands."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from ohra.canonical.kinematics import HandModel
from ohra.hands import hands_in_form
from ohra.learn import geometry as geo
from ohra.learn.encoding import segment_presence
from ohra.learn.sampler import (
    DEFAULT_CONFIG, EXTRA, LENGTHS, THUMB_AXES, THUMB_RPY, UPPERS, XYZ, SamplerConfig, in_support, mirror_vectors,
    sample_params, sample_vectors, support_violations,
)
from ohra.learn.sampler_reference import sample_reference_vectors
from ohra.transforms import rpy_to_matrix
from ohra.canonical.params import BaseParams
from ohra.canonical.urdfgen import render

N = 10_000


@pytest.fixture(scope="module")
def samples():
    v, right = sample_vectors(N, seed=7, return_handedness=True)
    return v, right


def _present(v):
    return (v[:, 38:60] != 0) | (v[:, UPPERS] != 0)


def test_same_seed_same_hands_and_different_seed_different_hands():
    a, b, c = sample_vectors(500, 3), sample_vectors(500, 3), sample_vectors(500, 4)
    assert np.array_equal(a, b)
    assert not np.allclose(a, c)
    # BaseParams objects carry exactly the sampled vectors, in canonical key order
    assert all(np.array_equal(p.to_vector(), row) for p, row in zip(sample_params(500, 3), a))


def test_every_one_of_10k_samples_validates(samples):
    v, _ = samples
    assert v.shape == (N, 82)
    for row in v:
        BaseParams.from_vector(row)  # raises ParamsError on any invalid value


def test_a_seeded_subset_renders_to_urdfs_that_load_in_pinocchio_and_pybullet(samples):
    import pybullet as pb

    from ohra.sim.bullet import load_urdf_text

    v, _ = samples
    idx = np.random.default_rng(0).choice(N, 300, replace=False)
    cid = pb.connect(pb.DIRECT)
    try:
        for k, i in enumerate(idx):
            p = BaseParams.from_vector(v[i])
            hm = HandModel.from_params(p)
            assert hm.nq == 22 and hm.present_fingers.sum() == p.num_fingers
            if k < 60:
                body = load_urdf_text(hm.urdf, cid)
                assert pb.getNumJoints(body, physicsClientId=cid) >= 22
                pb.removeBody(body, physicsClientId=cid)
    finally:
        pb.disconnect(cid)


@pytest.mark.slow
def test_all_10k_samples_render_and_load(samples):
    v, _ = samples
    for row in v:
        HandModel.from_params(BaseParams.from_vector(row))


def test_finger_and_joint_patterns_follow_the_reference(samples):
    v, right = samples
    present = _present(v)
    seg_t, seg_f, fingers = segment_presence(present)
    assert fingers[:, 0].all(), "the thumb is always present"
    assert set(np.unique(fingers[:, 1:].sum(axis=1))) == {2, 3, 4}
    # thumb patterns: the reference's six, all with joint 1, and Barrett's (joints 4 and 5 only)
    barrett = np.all(present[:, 0:5] == [0, 0, 0, 1, 1], axis=1)
    assert present[~barrett, 0].all() and abs(barrett.mean() - 1 / 9) < 0.02  # full thumb 3x as likely
    # one joint pattern shared by all present non-thumb fingers
    pats = [present[:, s : s + 4] for s in (5, 9, 13, 18)]
    for i in range(N)[:2000]:
        used = [p[i] for p, f in zip(pats, fingers[i, 1:]) if f]
        assert all(np.array_equal(u, used[0]) for u in used)
    assert (pats[0][:, 1:].sum(axis=1)[fingers[:, 1]] >= 2).all()
    # little_joint0 only on full hands (>= 20 joints before it), ~80 % of them
    full = present.sum(axis=1) - present[:, 17] >= 20
    assert not present[~full, 17].any()
    assert 0.7 < present[full, 17].mean() < 0.9
    assert present.sum(axis=1).min() >= 6  # Barrett's thumb (2) and two fingers of two joints
    assert 0.47 < right.mean() < 0.53


# Hands the sampler cannot draw, each with its reason; none since the support was widened for the Inspire
# hands (thumb 6 cm up the palm, a 23 mm thumb link, knuckles spread 4.6 mm in x).
OUTSIDE_SUPPORT: set[str] = set()


def test_every_registered_base_hand_is_inside_the_support():
    hands = hands_in_form("base")
    assert hands, "no registered base-form hands"
    assert {p.handedness for p in hands.values()} == {"left", "right"}
    bad = {n: support_violations(p) for n, p in hands.items() if support_violations(p)}
    assert set(bad) == OUTSIDE_SUPPORT, bad


def test_support_violations_name_the_parameter_and_its_range():
    p = BaseParams.from_vector(sample_vectors(1, 21)[0])
    assert support_violations(p) == []
    d = p.to_dict()
    d["palm_radius"] = 0.07
    msg = support_violations(BaseParams.from_dict(d))
    assert msg[0] == "palm_radius = 0.07 outside [0.04, 0.06]"
    narrow = SamplerConfig(palm_radius=(0.041, 0.042))
    assert any(m.startswith("palm_radius") for m in support_violations(p, narrow)) or 0.041 <= p.palm_radius <= 0.042
    # the reference sampler's hands are mostly outside: thumbs into the palm, Euler cube
    ref = [support_violations(BaseParams.from_vector(r)) for r in sample_reference_vectors(200, 1)]
    assert sum(any("into the palm" in m for m in r) for r in ref) > 60


def test_sampled_hands_are_plausible(samples):
    v, _ = samples
    assert not geo.thumb_into_palm(v).any()
    assert not geo.knuckles_inside_palm(v).any()
    assert (geo.thumb_clearance(v) >= DEFAULT_CONFIG.thumb_clearance).all()
    lo, hi = DEFAULT_CONFIG.knuckle_z_bounds(v[:, 0])
    z = v[:, XYZ].reshape(N, 5, 3)[:, 1:, 2]
    used = z != 0
    assert np.all((z >= lo[:, None] - 1e-12)[used]) and np.all((z <= hi[:, None] + 1e-12)[used])


def test_thumb_directions_are_uniform_over_the_outward_half(samples):
    """For a rotation uniform on the half of SO(3) whose z axis points away from the palm centre,
    the cosine between that axis and the outward direction is uniform on [0, 1], and the thumb's
    turn about its own axis is uniform."""
    v, right = samples
    r = v[right]
    R = rpy_to_matrix(r[:, THUMB_RPY])
    out = r[:, XYZ][:, 0:3] - geo.palm_centre(r)
    out /= np.linalg.norm(out, axis=1, keepdims=True)
    cos = np.sum(R[:, :, 2] * out, axis=1)
    assert stats.kstest(cos, "uniform").pvalue > 1e-3
    # roll: angle of the thumb's x axis around its z axis, against a reference perpendicular to z
    ref = np.cross(R[:, :, 2], [0.0, 0.0, 1.0])
    ref /= np.linalg.norm(ref, axis=1, keepdims=True)
    roll = np.arctan2(np.sum(np.cross(ref, R[:, :, 0]) * R[:, :, 2], 1), np.sum(ref * R[:, :, 0], 1))
    assert stats.kstest((roll + np.pi) / (2 * np.pi), "uniform").pvalue > 1e-3


def test_parts_without_geometry_are_zero(samples):
    v, _ = samples
    present = _present(v)
    seg_t, seg_f, fingers = segment_presence(present)
    xyz = v[:, XYZ].reshape(N, 5, 3)
    assert not xyz[~fingers].any() and np.all(np.any(xyz[fingers] != 0, axis=1))
    axes = v[:, THUMB_AXES].reshape(N, 2, 3)
    assert not axes[~present[:, :2]].any()
    assert np.allclose(np.abs(axes[present[:, :2]]).sum(axis=1), 1.0)
    assert not v[~present[:, 17]][:, EXTRA].any() and v[present[:, 17]][:, EXTRA][:, 3].all()
    lengths = v[:, LENGTHS].reshape(N, 2, 3)
    seg = np.stack([seg_t, seg_f.any(axis=1)], axis=1)
    assert not lengths[~seg].any() and (lengths[seg] > 0).all()


def test_knuckles_do_not_overlap_and_keep_their_order(samples):
    v, right = samples
    present = _present(v)
    _, _, fingers = segment_presence(present)
    R, r = v[:, 0], v[:, 1]
    y = v[:, XYZ].reshape(N, 5, 3)[:, 1:, 1]
    wmax = DEFAULT_CONFIG.knuckle_span[1] * (R - r)
    for i in range(N):
        yi = y[i, fingers[i, 1:]]
        # index -> little runs from the thumb side (+y on a right hand) to the other side
        d = -np.diff(yi) if right[i] else np.diff(yi)
        assert (d >= 2 * r[i] + DEFAULT_CONFIG.finger_gap - 1e-12).all()
        assert (np.abs(yi) <= max(wmax[i], (len(yi) - 1) * (2 * r[i] + DEFAULT_CONFIG.finger_gap)) + 1e-12).all()


def test_little_extra_joint_sits_on_the_little_fingers_side(samples):
    """Reference quirk fixed: right hands get the metacarpal frame at -y (like Shadow/Sharpa right)."""
    v, right = samples
    present = _present(v)
    e = v[present[:, 17]][:, EXTRA]
    rr = right[present[:, 17]]
    little_y = v[present[:, 17]][:, XYZ.start + 13]
    assert (np.sign(e[:, 1]) == np.sign(little_y)).all()
    assert (e[rr, 1] < 0).all() and (e[rr, 3] > 0).all()
    assert (e[~rr, 1] > 0).all() and (e[~rr, 3] < 0).all()
    thumb_y = v[:, XYZ.start + 1]
    assert (thumb_y[right] >= 0).all() and (thumb_y[~right] <= 0).all()


def test_right_and_mirrored_left_hands_have_the_same_distribution(samples):
    v, right = samples
    r, m = v[right], mirror_vectors(v[~right])
    assert np.array_equal(mirror_vectors(mirror_vectors(v[:50])), v[:50])
    for k in range(32):
        a, b = r[:, k], m[:, k]
        if np.ptp(a) == 0 and np.ptp(b) == 0:
            assert a[0] == b[0]
            continue
        assert stats.ks_2samp(a, b).pvalue > 1e-3, f"continuous value {k} differs between right and mirrored left"
    # joint presence patterns: same frequencies
    pr, pm = _present(r).mean(axis=0), _present(m).mean(axis=0)
    assert np.abs(pr - pm).max() < 0.03
    # and the mirror is not vacuous: unmirrored left hands differ from right hands
    assert stats.ks_2samp(r[:, XYZ.start + 1], v[~right][:, XYZ.start + 1]).pvalue < 1e-6


def test_sampled_hand_urdf_is_deterministic():
    p = sample_params(1, 11)[0]
    assert render(p) == render(BaseParams.from_json(p.to_json()))


def test_every_sampled_pattern_is_in_the_documented_support(samples):
    v, _ = samples
    flags = v[:, 38:60] != v[:, 60:82]
    assert all(in_support(f) for f in flags[:3000])
    off = flags[0].copy()
    off[0:5] = [False, True, False, False, True]  # a thumb with joints 2 and 5 only is never sampled
    assert not in_support(off)
