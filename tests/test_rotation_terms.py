"""Reward, observation and termination terms of the rotation task on analytic states."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from ohra.sim.rotation import observations as O
from ohra.sim.rotation import rewards as Rw
from ohra.sim.rotation import termination as T
from ohra.sim.rotation.config import RewardWeights
from ohra.sim.rotation.scene import yaw_quat


def test_delta_yaw_is_the_signed_turn_about_plus_z():
    assert Rw.delta_yaw(yaw_quat(0.2), yaw_quat(0.5)) == pytest.approx(0.3)
    assert Rw.delta_yaw(yaw_quat(0.5), yaw_quat(0.2)) == pytest.approx(-0.3)
    assert Rw.delta_yaw(yaw_quat(3.1), yaw_quat(-3.1)) == pytest.approx(2 * math.pi - 6.2)  # across +-pi
    tilt = np.array([math.sin(0.1), 0.0, 0.0, math.cos(0.1)])  # 0.2 rad about x: no turn about z
    assert Rw.delta_yaw(np.array([0, 0, 0, 1.0]), tilt) == pytest.approx(0.0)


def test_rotation_term_is_angular_velocity_clipped():
    assert Rw.rotation(0.01, 0.05, 0.5) == pytest.approx(0.2)
    assert Rw.rotation(0.1, 0.05, 0.5) == 0.5 and Rw.rotation(-0.1, 0.05, 0.5) == -0.5


def test_fall_term_counts_a_lost_object_not_a_diverged_simulation():
    assert Rw.fall("fell") == 1.0 and Rw.fall("left") == 1.0
    assert Rw.fall(None) == 0.0 and Rw.fall("broken") == 0.0
    assert RewardWeights().fall == 0.0  # off unless a run sets it: the paper's reward has no such term


def test_penalty_terms_on_analytic_states():
    assert Rw.drift(np.array([0.03, 0.04, 0.0]), np.zeros(3)) == pytest.approx(0.05)
    assert Rw.pose(np.array([0.1, -0.2]), np.zeros(2)) == pytest.approx(0.05)
    assert Rw.torque(np.array([0.3, -0.4])) == pytest.approx(0.25)
    assert Rw.work(np.array([1.0, 2.0]), np.array([0.5, -0.5])) == pytest.approx(0.25)  # (0.5 - 1.0)^2
    assert Rw.linvel(np.array([0.1, -0.2, 0.3])) == pytest.approx(0.6)


def test_total_is_the_weighted_sum_and_a_zero_weight_removes_a_term():
    terms = {"rotation": 0.4, "drift": 0.01, "pose": 0.2, "torque": 0.5, "work": 0.1, "linvel": 0.05, "fall": 1.0}
    w = RewardWeights()
    expected = 0.4 - 0.1 * 0.01 - 0.3 * 0.2 - 0.1 * 0.5 - 2.0 * 0.1 - 0.3 * 0.05
    assert Rw.total(terms, w) == pytest.approx(expected)
    assert Rw.total(terms, replace(w, work=0.0)) == pytest.approx(expected + 2.0 * 0.1)
    assert Rw.total(terms, replace(w, fall=-25.0)) == pytest.approx(expected - 25.0)


@pytest.mark.parametrize("weights, warned", [({"fall": 25.0}, True), ({"work": 0.001}, True), ({"fall": -25.0}, False),
                                             ({"work": 0.0}, False), ({"rotation": -1.0}, False)])
def test_a_penalty_weight_that_pays_a_reward_is_said_not_refused(weights, warned):
    import warnings

    from ohra.sim.rotation.config import RotationConfig, RotationConfigWarning

    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        cfg = RotationConfig(weights=weights)
    ours = [w for w in seen if issubclass(w.category, RotationConfigWarning)]
    assert len(ours) == int(warned)  # turning about -z (rotation < 0) is a task, not a slip
    assert cfg.weights.as_dict()[next(iter(weights))] == next(iter(weights.values()))
    if warned:
        assert next(iter(weights)) in str(ours[0].message)


@pytest.mark.parametrize("drop, fell", [(0.029, False), (0.031, True)])
def test_fell_on_both_sides_of_the_height_threshold(drop, fell):
    assert T.fell(np.array([0.0, 0.0, -drop]), np.zeros(3), 0.03) is fell


@pytest.mark.parametrize("dist, left", [(0.079, False), (0.081, True)])
def test_left_on_both_sides_of_the_distance_threshold(dist, left):
    assert T.left_hand(np.array([dist, 0.0, 0.0]), np.zeros(3), 0.08) is left


def test_termination_reason_prefers_broken_then_fell():
    z = np.zeros(3)
    assert T.reason(np.array([0, 0, -1.0]), z, 0.03, 0.08, np.array([np.nan])) == "broken"
    assert T.reason(np.array([0, 0, -1.0]), z, 0.03, 0.08) == "fell"
    assert T.reason(np.array([0.01, 0, 0]), z, 0.03, 0.08) is None


def test_joint_scaling_maps_limits_to_plus_minus_one_and_immovable_to_zero():
    lo, hi = np.array([-1.0, 0.0, 0.5]), np.array([1.0, 2.0, 0.5])
    assert np.allclose(O.scaled(np.array([-1.0, 2.0, 0.5]), lo, hi), [-1.0, 1.0, 0.0])
    assert np.allclose(O.scaled(np.array([0.0, 1.0, 0.5]), lo, hi), [0.0, 0.0, 0.0])


def test_fast_observer_equals_the_term_by_term_definition():
    rng = np.random.default_rng(0)
    n = 5
    lo, hi = -rng.uniform(0.1, 1, n), rng.uniform(0.1, 2, n)
    hi[2] = lo[2]  # an immovable joint
    q = rng.uniform(lo, hi)
    quat = rng.normal(size=4)
    o = O.ObsInput(q=q, target=np.clip(q + 0.1, lo, hi), dq=rng.normal(size=n), lower=lo, upper=hi,
                   obj_pos=rng.normal(size=3) * 0.01, obj_start=np.zeros(3), obj_quat=quat / np.linalg.norm(quat),
                   obj_linvel=rng.normal(size=3), obj_angvel=rng.normal(size=3), time=0.35, phase_period=1.0)
    ref = O.observe(o)
    assert np.allclose(O.Observer(lo, hi, 1.0)(o), ref, atol=1e-6)
    sl = O.slices(n)
    assert np.allclose(ref[sl["phase"]], [math.sin(0.7 * math.pi), math.cos(0.7 * math.pi)], atol=1e-6)
    assert ref.shape == (3 * n + 14,)
