"""The hybrid hand (ohra.sim.hybrid): an original URDF carrying the canonical collision shapes, each on the
original link that moves with it."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pytest

from ohra.errors import GraspError
from ohra.hands import get_hand
from ohra.paths import hands_root
from ohra.sim.hands import SimHand
from ohra.sim.hybrid import link_frames, with_canonical_collisions

from conftest import _require


def _shapes_in_palm(hand: SimHand, q: np.ndarray) -> np.ndarray:
    """(n, 3) centre of every collision shape of ``hand`` in the palm frame at canonical ``q``, document order."""
    from ohra.sim.hybrid import _origin

    frames = link_frames(hand, q)
    return np.array([(frames[link.get("name")] @ _origin(c))[:3, 3] for link in ET.fromstring(hand.urdf).iter("link")
                     for c in link.findall("collision")])


@pytest.fixture(scope="module")
def leap():
    _require(hands_root())  # skips (or fails under OHRA_REQUIRE_ASSETS) without the shared hands
    original = SimHand.registered_original("leap_hand_right", "extended")
    canonical = SimHand.from_params(get_hand("leap_hand_right", "extended"), name="leap:canonical")
    return original, canonical, *with_canonical_collisions(original, canonical)


def test_hybrid_keeps_the_original_and_swaps_only_the_collision_shapes(leap):
    original, canonical, hybrid, fit = leap
    assert hybrid.joints == original.joints and hybrid.mimic == original.mimic
    np.testing.assert_array_equal(hybrid.lower, original.lower)
    np.testing.assert_array_equal(hybrid.T_palm_root, original.T_palm_root)
    o, h = ET.fromstring(original.urdf), ET.fromstring(hybrid.urdf)
    assert [link.get("name") for link in o.iter("link")] == [link.get("name") for link in h.iter("link")]
    assert [ET.tostring(i) for i in o.iter("inertial")] == [ET.tostring(i) for i in h.iter("inertial")]
    assert len(h.findall(".//collision")) == len(ET.fromstring(canonical.urdf).findall(".//collision")) == len(fit) == 13
    assert not h.findall(".//collision/geometry/mesh") and not h.findall(".//collision/geometry/box")


def test_each_shape_rides_on_a_link_of_its_own_finger_within_a_few_millimetres(leap):
    original, canonical, _, fit = leap
    for lc, (lo, drift) in fit.items():
        assert original.link_finger[lo] == canonical.link_finger[lc], (lc, lo)
        assert drift < 0.004, (lc, lo, drift)  # LEAP's parse: fingertips within ~3 mm of the original's
    assert fit["index_distal"][0] == "fingertip" and fit["palm"][0] == "base"


def test_shapes_sit_where_the_canonical_hand_has_them(leap):
    """At q = 0 (where each transform was taken) the hybrid's shapes coincide with the canonical hand's;
    at another configuration they move with the original links, within the drift."""
    original, canonical, hybrid, fit = leap
    zero = np.zeros(22)
    h0, c0 = _shapes_in_palm(hybrid, zero), _shapes_in_palm(canonical, zero)
    pair = np.linalg.norm(h0[:, None] - c0[None], axis=2).argmin(axis=1)  # hybrid shape -> canonical shape
    assert sorted(pair) == list(range(len(c0)))
    assert np.abs(h0 - c0[pair]).max() < 1e-9
    q = 0.5 * (canonical.canon_lower + canonical.canon_upper)
    moved = np.linalg.norm(_shapes_in_palm(hybrid, q) - _shapes_in_palm(canonical, q)[pair], axis=1)
    assert moved.max() < 0.004


def test_hands_of_the_wrong_kind_are_refused(leap):
    original, canonical, _, _ = leap
    with pytest.raises(GraspError, match="an original and a canonical hand"):
        with_canonical_collisions(canonical, original)


def test_model_evaluation_replays_on_the_hybrid_on_request(tmp_path, monkeypatch):
    """``evaluate_model(original=True, collisions="canonical")`` runs the same grasps on the hybrid of the
    hand's original URDF: original joints and masses, the canonical capsules; refused without ``original``."""
    pytest.importorskip("torch")
    _require(hands_root())
    import ohra.sim
    from grasp_fixtures import tiny_model_config, tiny_train_config, write_dataset

    from ohra.learn.grasp.evaluate import evaluate_model
    from ohra.learn.grasp.train import train_grasp
    from ohra.objects import ObjectModel

    model = train_grasp(write_dataset(tmp_path), tiny_model_config(condition="params"), tiny_train_config(),
                        progress=False).model
    seen: list[SimHand] = []
    real = ohra.sim.GraspEvaluator

    class Spy(real):
        def __init__(self, hand, *a, **kw):
            seen.append(hand)
            super().__init__(hand, *a, **kw)

    monkeypatch.setattr(ohra.sim, "GraspEvaluator", Spy)
    obj = ObjectModel.builtin("cylinder")
    hyb = evaluate_model(model, ["barrett_hand"], [obj], n=2, original=True, collisions="canonical", allow_seen=True)
    own = evaluate_model(model, ["barrett_hand"], [obj], n=2, original=True, allow_seen=True)
    hybrid, original = seen
    assert hybrid.name.endswith(":hybrid") and hybrid.joints == original.joints
    np.testing.assert_array_equal(hybrid.finger_masses, original.finger_masses)

    def shapes(hand: SimHand) -> set[str]:
        return {g.tag for c in ET.fromstring(hand.urdf).iter("collision") for g in c.find("geometry")}

    assert shapes(hybrid) == {"capsule", "cylinder"}  # finger capsules, palm disc
    assert "mesh" in shapes(original) and "capsule" not in shapes(original)
    np.testing.assert_array_equal(hyb.pairs[0].grasps, own.pairs[0].grasps)
    assert hyb.meta["collisions"] == "canonical" and own.meta["collisions"] == "own"
    with pytest.raises(GraspError, match="needs original=True"):
        evaluate_model(model, ["barrett_hand"], [obj], n=1, collisions="canonical", allow_seen=True)
    with pytest.raises(GraspError, match="collisions must be one of"):
        evaluate_model(model, ["barrett_hand"], [obj], n=1, original=True, collisions="boxes", allow_seen=True)
