"""HandModel: FK against published golden values, batch vs single, Jacobians, capsules, collision."""

from __future__ import annotations

import coal
import numpy as np
import pytest

from ohra import OhraError
from ohra.hands import get_hand
from ohra.canonical.kinematics import HandModel


def test_fingertips_match_published_golden_values(shadow_base, allegro_ext):
    tips = HandModel.from_params(shadow_base).fingertips(np.zeros(22))
    golden = [(0.0086, 0.1082, 0.1032), (0, 0.033, 0.200), (0, 0.011, 0.204), (0, -0.011, 0.200), (0, -0.033, 0.1916)]
    assert np.allclose(tips, golden, atol=1e-4)
    tips = HandModel.from_params(allegro_ext).fingertips(np.zeros(22))
    assert np.allclose(tips[[0, 1, 2, 4]], [(-0.0134, 0.1784, 0.008), (0, 0.0563, 0.2404), (0, 0, 0.2432), (0, -0.0563, 0.2404)], atol=1e-4)
    assert np.isnan(tips[3]).all()


def test_shadow_mid_limit_fingertips_curl_toward_palm_normal(shadow_base):
    hm = HandModel.from_params(shadow_base)
    q = (hm.lower + hm.upper) / 2
    tips = hm.fingertips(q)
    golden = [(0.0647, 0.0756, 0.1007), (0.0799, 0.033, 0.1127), (0.0799, 0.011, 0.1167), (0.0799, -0.011, 0.1127), (0.0922, -0.0049, 0.0846)]
    assert np.allclose(tips, golden, atol=2e-4)


def test_leap_variant_matches_published_link_positions():
    hm = HandModel.from_params(get_hand("leap_3333"))
    P = hm.frame_poses(np.zeros(22), ["index_middle", "index_distal"])[:, :3, 3]
    assert P[0, 2] == pytest.approx(0.1441, abs=2e-4)
    assert np.allclose(P[1], (0, 0.0465, 0.1802), atol=2e-4)


def test_batch_fk_equals_looped_pinocchio_fk(allegro_ext):
    hm = HandModel.from_params(allegro_ext)
    Q = hm.random_configurations(20, seed=1)
    batch = hm.frame_poses(Q)
    for i, q in enumerate(Q):
        for k, f in enumerate(hm.frame_names):
            assert np.allclose(batch[i, k], hm.frame_pose(q, f), atol=1e-12)
    assert np.allclose(hm.frame_poses(Q[0]), batch[0])


def test_jacobian_matches_finite_differences(shadow_base):
    hm = HandModel.from_params(shadow_base)
    q = hm.random_configurations(1, seed=7)[0]
    for frame in ("thumb_tip", "index_tip", "little_tip"):
        J = hm.jacobian(q, frame)
        eps = 1e-6
        Jfd = np.zeros((3, 22))
        for k in range(22):
            dq = np.zeros(22)
            dq[k] = eps
            Jfd[:, k] = (hm.frame_pose(q + dq, frame)[:3, 3] - hm.frame_pose(q - dq, frame)[:3, 3]) / (2 * eps)
        assert np.allclose(J[:3], Jfd, atol=1e-7), frame


def test_random_configurations_are_seeded_and_within_limits(allegro_ext):
    hm = HandModel.from_params(allegro_ext)
    a, b = hm.random_configurations(100, seed=5), hm.random_configurations(100, seed=5)
    assert np.array_equal(a, b)
    assert np.all(a >= hm.lower) and np.all(a <= hm.upper)
    assert np.all(a[:, ~hm.present_joints] == 0.0)


def test_capsule_endpoints_lie_on_link_frames(shadow_base):
    hm = HandModel.from_params(shadow_base)
    q = hm.random_configurations(1, seed=2)[0]
    caps = hm.capsules(q)
    r = shadow_base.finger_radius
    for k, link in enumerate(caps.link):
        T = hm.frame_pose(q, link)
        L = np.linalg.norm(caps.p1[k] - caps.p0[k]) + 2 * r
        assert np.allclose(caps.p0[k], T[:3, 3] + r * T[:3, 2], atol=1e-12)
        assert np.allclose(caps.p1[k], T[:3, 3] + (L - r) * T[:3, 2], atol=1e-12)
    # the distal capsule ends at the tip frame
    tip = hm.frame_pose(q, "index_tip")[:3, 3]
    k = caps.link.index("index_distal")
    assert np.allclose(caps.p1[k] + r * (caps.p1[k] - caps.p0[k]) / np.linalg.norm(caps.p1[k] - caps.p0[k]), tip)


def test_capsules_batch_shape(allegro_ext):
    hm = HandModel.from_params(allegro_ext)
    caps = hm.capsules(hm.random_configurations(7, seed=0))
    assert caps.p0.shape == (7, 12, 3) and caps.radius.shape == (12,)


def test_no_self_collision_at_rest_for_full_leap():
    hm = HandModel.from_params(get_hand("leap_3333"))
    assert not hm.self_collision(np.zeros(22))


def test_self_collision_when_two_fingers_fold_into_each_other():
    hm = HandModel.from_params(get_hand("leap_3333"))
    q = np.zeros(22)
    q[6] = 0.4  # index abducts toward the middle finger (LEAP: abduction is j2, axis +x)
    q[10] = -0.4  # middle abducts toward the index finger
    pairs = hm.self_collision_pairs(q)
    assert any({a.split("_")[0], b.split("_")[0]} == {"index", "middle"} for a, b in pairs)
    q[10] = 0.4  # both lean the same way: they stay apart
    assert not any({a.split("_")[0], b.split("_")[0]} == {"index", "middle"} for a, b in hm.self_collision_pairs(q))


def test_object_distance_is_signed_for_convex_objects(shadow_base):
    hm = HandModel.from_params(shadow_base)
    tip = hm.frame_pose(np.zeros(22), "index_distal")
    ball = coal.Sphere(0.02)
    T = np.eye(4)
    T[:3, 3] = tip[:3, 3] + np.array([0.05, 0, 0.02])  # 5 cm in front of the finger
    d = hm.object_distances(np.zeros(22), ball, T)
    expected = 0.05 - 0.02 - shadow_base.finger_radius
    assert d["index_distal"] == pytest.approx(expected, abs=1e-6)
    T[:3, 3] = tip[:3, 3] + np.array([0.02, 0, 0.02])  # overlapping by 8.7 mm
    assert hm.penetration_depth(np.zeros(22), ball, T) == pytest.approx(0.02 + shadow_base.finger_radius - 0.02, abs=1e-6)


def test_bad_configuration_raises(shadow_base):
    hm = HandModel.from_params(shadow_base)
    with pytest.raises(OhraError, match=r"shape \(22,\) or \(N, 22\)"):
        hm.fingertips(np.zeros(16))
    with pytest.raises(OhraError, match="NaN"):
        hm.fingertips(np.full(22, np.nan))
    with pytest.raises(OhraError, match="unknown frame"):
        hm.frame_pose(np.zeros(22), "wrist")


@pytest.mark.parametrize("method, args", [
    ("frame_pose", ("index_tip",)), ("jacobian", ("index_tip",)), ("self_collision_pairs", ()), ("self_collision", ()),
    ("object_distances", (coal.Sphere(0.02),)), ("min_distance", (coal.Sphere(0.02),)),
    ("penetration_depth", (coal.Sphere(0.02),)),
])
def test_one_configuration_methods_given_a_batch_raise_naming_both_shapes(shadow_base, method, args):
    hm = HandModel.from_params(shadow_base)
    getattr(hm, method)(np.zeros(22), *args)  # one configuration works
    with pytest.raises(OhraError, match=rf"{method} takes one configuration of shape \(22,\), got \(3, 22\)"):
        getattr(hm, method)(np.zeros((3, 22)), *args)


def test_collision_queries_refuse_a_pose_or_margin_that_is_not_a_number():
    """A NaN object pose gave a made-up 3 cm penetration, a NaN margin "no collision", a (3,) pose an IndexError."""
    h = HandModel.from_params(get_hand("leap_3303"))
    q = h.neutral()
    sphere = coal.Sphere(0.03)
    far = np.eye(4)
    far[:3, 3] = (0.5, 0.0, 0.0)
    assert h.min_distance(q, sphere, far) > 0.3
    with pytest.raises(OhraError, match="T_palm_object contains NaN"):
        h.min_distance(q, sphere, np.full((4, 4), np.nan))
    with pytest.raises(OhraError, match=r"T_palm_object: expected a \(4, 4\) homogeneous transform, got shape \(3,\)"):
        h.object_distances(q, sphere, np.zeros(3))
    with pytest.raises(OhraError, match="margin must be a finite distance"):
        h.self_collision(q, margin=float("nan"))
    with pytest.raises(OhraError, match=r"T_world_palm: expected a \(4, 4\)"):
        h.collision_objects(q, np.eye(3))


def test_frame_poses_names_a_single_string_instead_of_reading_its_letters():
    h = HandModel.from_params(get_hand("leap_3303"))
    with pytest.raises(OhraError, match=r"got the string 'index_tip'; frame_poses\(q, \['index_tip'\]\)"):
        h.frame_poses(h.neutral(), "index_tip")
    assert h.frame_poses(h.neutral(), ["index_tip"]).shape == (1, 4, 4)
