"""An original hand squeezes the way its canonical twin does (``SimHand.squeeze_reference``).

The reference controller decides per joint which way closes onto the object from the link's direction, read off
the link frame's +z: true of canonical links, not of many original URDFs. Allegro's thumb joint 13 squeezed open
in every replayed grasp, a fifth to nine tenths of LEAP's joints did, and DexHand's thumb opened until no finger
touched the object. The original now takes each joint's direction from its canonical slot on the twin, posed at
the same grasp, through the action map's sign."""

from __future__ import annotations

import numpy as np
import pytest

from ohra.hands import get_hand
from ohra.objects.model import ObjectModel
from ohra.paths import hands_root
from ohra.rotations import grasp_to_pose
from ohra.sim import Protocol
from ohra.sim.controller import closes_positive
from ohra.sim.hands import SimHand
from ohra.sim.world import World

from conftest import _require


def _grasps(name: str, n: int = 12, seed: int = 0) -> np.ndarray:
    """Palm poses around the origin facing it, random joints within the canonical limits (N, 31)."""
    from ohra.rotations import pose_to_grasp

    rng = np.random.default_rng(seed)
    p = get_hand(name)
    lo, up = np.asarray(p.joint_lowers), np.asarray(p.joint_uppers)
    out = []
    for _ in range(n):
        x = -rng.normal(size=3)
        x /= np.linalg.norm(x)  # palm normal toward the object at the origin
        z = np.cross(x, rng.normal(size=3))
        z /= np.linalg.norm(z)
        T = np.eye(4)
        T[:3, :3] = np.column_stack([x, np.cross(z, x), z])
        T[:3, 3] = -0.08 * x - 0.05 * z
        out.append(pose_to_grasp(T, lo + rng.random(22) * (up - lo)))
    return np.array(out)


@pytest.mark.assets
@pytest.mark.parametrize("name, flipped", [("allegro_hand_left", None), ("leap_hand_right", "13")])
def test_an_original_joint_closes_the_way_its_canonical_slot_does_through_the_sign(name, flipped):
    _require(hands_root())
    original = SimHand.registered_original(name)
    twin = original.squeeze_reference
    assert twin is not None and twin.canonical and twin.canon_lower.tolist() == original.canon_lower.tolist()
    idx, flip = original.squeeze_map()
    if flipped:  # LEAP's thumb flexion joint "13" maps to thumb_joint2 with sign -1
        k = original.joints.index(flipped)
        assert flip[k] and twin.joints[idx[k]] == "thumb_joint2"
    box = ObjectModel.builtin("box")
    wo, wt = World(original, box, Protocol()), World(twin, box, Protocol())
    own_disagrees = 0
    try:
        for g in _grasps(name):
            T, q = grasp_to_pose(g)
            wt.reset_hand(T @ twin.T_palm_root, twin.to_sim(q))
            expected = closes_positive(*wt.joint_frames())[idx] ^ flip
            np.testing.assert_array_equal(wo.closes_positive(T, q, None), expected)
            wo.reset_hand(T @ original.T_palm_root, original.to_sim(q))
            own_disagrees += int(np.any(closes_positive(*wo.joint_frames()) != expected))
    finally:
        wo.close()
        wt.close()
    assert own_disagrees > 0  # what the hand's own frames would have decided: the bug this replaces


@pytest.mark.assets
def test_a_replayed_allegro_grasp_closes_its_thumb_onto_the_object():
    """Joint 13 (Allegro's thumb flexion) squeezed open on the original URDF in every replayed grasp."""
    _require(hands_root())
    import ohra.sim.evaluator as ev

    original = SimHand.registered_original("allegro_hand_left")
    k = original.joints.index("joint_13.0")
    captured = []
    real = ev.squeeze_targets

    def spy(q, lo, up, closes, *a, **kw):
        captured.append(closes[k])
        return real(q, lo, up, closes, *a, **kw)

    box = ObjectModel.builtin("box")
    world = World(original, box, Protocol())
    try:
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(ev, "squeeze_targets", spy)
            for g in _grasps("allegro_hand_left", n=4, seed=1):
                ev.run_grasp(world, g)
    finally:
        world.close()
    twin = original.squeeze_reference
    box_twin = World(twin, box, Protocol())
    try:
        want = []
        for g in _grasps("allegro_hand_left", n=4, seed=1):
            T, q = grasp_to_pose(g)
            box_twin.reset_hand(T @ twin.T_palm_root, twin.to_sim(np.clip(q, twin.canon_lower, twin.canon_upper)))
            want.append(bool(closes_positive(*box_twin.joint_frames())[twin.joints.index("thumb_joint2")]))
    finally:
        box_twin.close()
    assert [bool(c) for c in captured] == want
