"""q = 0 geometry of base-form hands and the plausibility rules, held to HandModel and Coal."""

from __future__ import annotations

import numpy as np
import pytest

from ohra.canonical.kinematics import HandModel
from ohra.canonical.params import BaseParams
from ohra.hands import hands_in_form
from ohra.learn import geometry as geo
from ohra.learn.encoding import decode_vectors as decode66
from ohra.learn.sampler import PALM, THUMB_RPY, XYZ, sample_vectors
from ohra.transforms import matrix_to_rpy


def _registered() -> np.ndarray:
    return np.array([p.to_vector() for p in hands_in_form("base").values()])


def _random_rotations(n: int, seed: int) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return Rotation.random(n, random_state=seed).as_matrix()


@pytest.mark.parametrize("order, kept", [("xy", 0), ("zx", 2)])
def test_rot6d_round_trip_and_any_six_numbers_give_a_rotation(order, kept):
    R = _random_rotations(500, 0)
    assert np.abs(geo.matrix_from_rot6d(geo.rot6d_from_matrix(R, order), order) - R).max() < 1e-12
    x = np.random.default_rng(1).normal(size=(500, 6))
    x[0] = 0.0  # degenerate: zero columns
    x[1, 3:] = 2.0 * x[1, :3]  # degenerate: parallel columns
    M = geo.matrix_from_rot6d(x, order)
    assert np.abs(M @ np.swapaxes(M, 1, 2) - np.eye(3)).max() < 1e-12
    assert np.allclose(np.linalg.det(M), 1.0)
    # Gram-Schmidt keeps the first given column's direction: x for "xy", z (the thumb direction) for "zx"
    assert np.allclose(M[2:, :, kept], x[2:, :3] / np.linalg.norm(x[2:, :3], axis=1, keepdims=True))


def test_geodesic_is_the_rotation_angle():
    R = _random_rotations(50, 2)
    ang = np.random.default_rng(3).uniform(0, np.pi, 50)
    axis = np.random.default_rng(4).normal(size=(50, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    assert np.allclose(geo.geodesic(R, geo.rotation_about(axis, ang) @ R), ang, atol=1e-7)


def test_q0_tips_match_hand_model_for_sampled_and_registered_hands():
    v = np.concatenate([sample_vectors(60, 2), _registered()])
    tips = geo.tips_q0(v)
    for row, t in zip(v, tips):
        ref = HandModel.from_params(BaseParams.from_vector(row)).fingertips(np.zeros(22))
        assert np.array_equal(np.isnan(ref), np.isnan(t))
        assert np.nanmax(np.abs(ref - t)) < 1e-10  # the URDF text carries 12 significant digits


def test_segment_distance_matches_dense_sampling():
    rng = np.random.default_rng(5)
    p0, p1, q0, q1 = (rng.normal(size=(300, 3)) for _ in range(4))
    q1[:20] = q0[:20]  # degenerate segments
    p1[20:40] = p0[20:40] + 1e-3 * (q1[20:40] - q0[20:40])  # nearly parallel
    d, cp, cq = geo.segment_distance(p0, p1, q0, q1)
    # dense points on the first segment, each to the second by clamped projection: within half a step
    # (|p1 - p0| / 4000 <= 1.5e-3 here) above the true distance, never below it
    A = p0[:, None] + np.linspace(0, 1, 2001)[None, :, None] * (p1 - p0)[:, None]
    ab = (q1 - q0)[:, None]
    s = np.clip(np.sum((A - q0[:, None]) * ab, axis=-1) / np.maximum(np.sum(ab * ab, axis=-1), 1e-300), 0.0, 1.0)
    brute = np.linalg.norm(A - (q0[:, None] + s[..., None] * ab), axis=-1).min(axis=1)
    assert np.all(d <= brute + 1e-12) and np.all(brute - d < 2e-3)
    assert np.allclose(np.linalg.norm(cp - cq, axis=1), d)


def test_core_clearance_is_conservative_against_coal():
    """Decoded random 66-D encodings intersect often; every Coal intersection at q = 0 must show as
    a negative core clearance (the converse need not hold)."""
    rng = np.random.default_rng(6)
    x = np.concatenate([rng.normal(0, 1, (300, 32)) * 0.05, rng.integers(0, 2, (300, 34))], axis=1)
    v = decode66(x)
    clear = geo.finger_clearance(v).min(axis=(1, 2))
    coal = np.array([HandModel.from_params(BaseParams.from_vector(r)).self_collision(np.zeros(22)) for r in v])
    assert coal.sum() >= 10, "the test needs intersecting hands"
    assert np.all(clear[coal] < 0)
    t = geo.thumb_clearance(v)
    assert np.allclose(t, geo.finger_clearance(v)[:, 0, 1:].min(axis=1))


def _one_hand(thumb_dir: np.ndarray, base=(0.01, 0.03, 0.02)) -> np.ndarray:
    v = sample_vectors(1, 0)[0].copy()
    z = np.asarray(thumb_dir, float) / np.linalg.norm(thumb_dir)
    x = np.cross([0.0, 1.0, 0.0], z) if abs(z[1]) < 0.9 else np.cross([1.0, 0.0, 0.0], z)
    x /= np.linalg.norm(x)
    v[THUMB_RPY] = matrix_to_rpy(np.column_stack([x, np.cross(z, x), z]))
    v[XYZ.start : XYZ.start + 3] = base
    return v


def test_thumb_into_palm_rule_on_both_sides_of_the_boundary():
    v = _one_hand([0, 0, 1])
    c = np.array([0.0, 0.0, v[PALM]])
    b = np.array([0.01, 0.03, 0.02])
    w = (c - b) / np.linalg.norm(c - b)
    perp = np.cross(w, [1.0, 0.0, 0.0])
    perp /= np.linalg.norm(perp)
    inward = _one_hand(w)
    slightly_in = _one_hand(perp + 0.02 * w)
    slightly_out = _one_hand(perp - 0.02 * w)
    assert geo.thumb_into_palm(np.stack([inward, slightly_in, slightly_out])).tolist() == [True, True, False]
    assert geo.thumb_inwardness(inward[None])[0] == pytest.approx(1.0)


def test_knuckle_inside_palm_rule_on_both_sides_of_the_threshold():
    v = sample_vectors(50, 1)
    _, fingers = geo.finger_reach(v)
    i = int(np.flatnonzero(fingers[:, 2])[0])
    lo, hi = v[i].copy(), v[i].copy()
    lo[XYZ.start + 3 * 2 + 2] = 0.49 * v[i, PALM]
    hi[XYZ.start + 3 * 2 + 2] = 0.51 * v[i, PALM]
    assert geo.knuckles_inside_palm(np.stack([lo, hi]))[:, 1].tolist() == [True, False]


def test_registered_and_sampled_hands_obey_every_rule():
    v = np.concatenate([_registered(), sample_vectors(200, 8)])
    assert not geo.knuckles_inside_palm(v).any()
    assert not geo.thumb_into_palm(v).any()
    assert (geo.finger_clearance(v) > 0).all()
    assert not any(HandModel.from_params(BaseParams.from_vector(r)).self_collision(np.zeros(22)) for r in v)
