"""The rotation scene (motor caps, inertials, object placement) and the starting-grasp generator."""

from __future__ import annotations

import numpy as np
import pybullet as pb
import pytest

from ohra.canonical.urdfgen import DUMMY_MASS
from ohra.sim.rotation import grasps as G
from ohra.sim.rotation.config import RotationConfig
from ohra.sim.rotation.scene import RotationScene, fill_inertials
from ohra.sim.rotation.task import resolve

CFG = RotationConfig(grasp_count=6)


def _scene(cfg: RotationConfig) -> RotationScene:
    t = resolve(cfg)
    return RotationScene(t.hand, t.obj, cfg, t.palm_radius)


@pytest.mark.parametrize("force, holds", [(0.005, False), (0.05, True)])
def test_motor_cap_is_the_configured_torque_per_sub_step(force, holds):
    """A palm-up LEAP finger flexed to 1.2 rad needs ~0.025 N m against gravity. PyBullet's own
    ``numSubSteps`` would let a 0.005 N m motor hold it (its cap scales with the sub-step count)."""
    cfg = CFG.with_overrides(motor_force=force, self_collision=False)
    sc = _scene(cfg)
    try:
        k = sc.hand.joints.index("index_joint1")  # extended LEAP: flexion at the palm
        q = np.clip(0.0, sc.hand.lower, sc.hand.upper)
        q[k] = 1.2
        sc.set_hand(q)
        sc.new_object(np.array([0.0, 0.0, 2.0]), np.array([0.0, 0.0, 0.0, 1.0]), fixed=True)
        for _ in range(40):
            sc.step()
        assert bool(abs(sc.read().q[k] - 1.2) < 0.05) == holds
    finally:
        sc.close()


def test_links_without_inertial_get_the_dummy_mass_not_pybullets_one_kilogram(tmp_path):
    urdf = ('<robot name="r"><link name="a"><inertial><mass value="0.1"/><inertia ixx="1e-4" iyy="1e-4" izz="1e-4" '
            'ixy="0" ixz="0" iyz="0"/></inertial></link><link name="b"/><joint name="j" type="revolute">'
            '<parent link="a"/><child link="b"/><axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/>'
            '</joint></robot>')
    c = pb.connect(pb.DIRECT)
    try:
        for name, text, mass in (("raw", urdf, 1.0), ("filled", fill_inertials(urdf), DUMMY_MASS)):
            path = tmp_path / f"{name}.urdf"
            path.write_text(text)
            body = pb.loadURDF(str(path), physicsClientId=c)
            assert pb.getDynamicsInfo(body, 0, physicsClientId=c)[0] == pytest.approx(mass)
    finally:
        pb.disconnect(c)


def test_original_leap_has_no_one_kilogram_links(hands_dir):
    sc = _scene(CFG.with_overrides(urdf="original"))
    try:
        masses = [pb.getDynamicsInfo(sc.body, j, physicsClientId=sc.client)[0] for j, _ in sc.links[1:]]
        assert max(masses) < 0.2  # LEAP's heaviest finger link is ~50 g
    finally:
        sc.close()


def test_nominal_object_pose_rests_just_above_the_palm_surface():
    sc = _scene(CFG)
    try:
        pos, quat = G.nominal_pose(sc)
        assert pos[2] == pytest.approx(sc.palm_top + sc.obj.half_height + G.CLEARANCE)
        assert np.allclose(pos[:2], sc.palm_centre_world()[:2])
        assert 0.0 < sc.palm_top < 0.03  # the canonical LEAP palm is 2 finger radii thick about z = 0
    finally:
        sc.close()


def test_a_mesh_whose_frame_origin_is_off_the_object_still_rests_on_the_palm_centre(tmp_path):
    """A mesh file in scene coordinates (its origin 10 cm from the object) is placed by its centre of
    mass, exactly as the same mesh centred on its origin: not off the palm edge, not into the palm."""
    import trimesh

    centred, offset = tmp_path / "centred.obj", tmp_path / "offset.obj"
    trimesh.creation.box(extents=(0.05, 0.05, 0.05)).export(centred)
    trimesh.creation.box(extents=(0.05, 0.05, 0.05)).apply_translation([0.08, 0.05, 0.03]).export(offset)
    placed = {}
    for path in (centred, offset):
        sc = _scene(CFG.with_overrides(object=str(path), object_size=0.06))
        try:
            pos, quat = G.nominal_pose(sc)
            sc.new_object(pos, quat, fixed=True)
            placed[path.stem] = np.array(pb.getBasePositionAndOrientation(sc.obj_body, physicsClientId=sc.client)[0])
            assert np.allclose(placed[path.stem][:2], sc.palm_centre_world()[:2], atol=1e-9)
            assert placed[path.stem][2] == pytest.approx(sc.palm_top + 0.03 + G.CLEARANCE)  # lowest point on the palm
        finally:
            sc.close()
    assert np.allclose(placed["centred"], placed["offset"], atol=1e-9)


def test_holding_pose_closes_fingers_onto_the_pinned_object():
    sc = _scene(CFG)
    try:
        hold = G.holding_pose(sc)
        assert sc.hand_contacts() >= 2
        assert np.all(hold >= sc.hand.lower - 0.05) and np.all(hold <= sc.hand.upper + 0.05)
    finally:
        sc.close()


@pytest.fixture(scope="module")
def grasp_set():
    return G.generate(resolve(CFG))


def test_starting_states_touch_the_object_and_sit_at_height(grasp_set):
    assert len(grasp_set) == CFG.grasp_count and grasp_set.attempts >= CFG.grasp_count
    sc = _scene(CFG)
    try:
        start, _ = G.nominal_pose(sc)
        for i in range(len(grasp_set)):
            sc.set_hand(grasp_set.q[i])
            sc.drive(grasp_set.target[i])
            sc.new_object(grasp_set.obj_pos[i], grasp_set.obj_quat[i])
            pb.performCollisionDetection(physicsClientId=sc.client)
            assert sc.hand_contacts() >= CFG.min_contacts
            assert grasp_set.obj_pos[i][2] >= start[2] - CFG.fall_height / 2
    finally:
        sc.close()


def test_generator_is_seeded(grasp_set):
    again = G.generate(resolve(CFG))
    assert np.array_equal(again.q, grasp_set.q) and np.array_equal(again.obj_quat, grasp_set.obj_quat)
    other = G.generate(resolve(CFG.with_overrides(grasp_seed=1)))
    assert not np.array_equal(other.q, grasp_set.q)


def test_grasp_cache_round_trips_and_is_keyed_by_the_settings(grasp_set, tmp_path):
    path = grasp_set.save(tmp_path / "g.npz")
    back = G.GraspSet.load(path)
    assert np.array_equal(back.target, grasp_set.target) and back.key == grasp_set.key
    assert G.cache_key(resolve(CFG)) != G.cache_key(resolve(CFG.with_overrides(friction=2.0)))


def test_original_urdf_starts_from_the_canonical_holding_pose_through_its_action_map(hands_dir):
    """grasp_hold='canonical' (default): the original LEAP perturbs the canonical hand's holding pose,
    mapped joint for joint; 'own' closes the original's own fingers (a different pose)."""
    cfg = CFG.with_overrides(urdf="original")
    task = resolve(cfg)
    canon = G.canonical_holding_pose(task)
    sc_c = _scene(CFG)
    try:
        assert np.allclose(canon, sc_c.hand.to_canonical(G.holding_pose(sc_c)))  # the canonical URDF's own hold
    finally:
        sc_c.close()
    sc = RotationScene(task.hand, task.obj, cfg, task.palm_radius)
    try:
        hold = G._hold(task, sc)
        assert np.allclose(hold, np.clip(task.hand.to_sim(canon), task.hand.lower, task.hand.upper))
        driven = task.hand.to_canonical(hold)
        moved = np.abs(task.hand.to_canonical(hold + 0.1) - driven) > 0  # canonical slots the original drives
        inside = (canon >= task.hand.canon_lower) & (canon <= task.hand.canon_upper)
        assert np.allclose(driven[moved & inside], canon[moved & inside], atol=1e-9)
        own_task = resolve(cfg.with_overrides(grasp_hold="own"))
        sc_own = RotationScene(own_task.hand, own_task.obj, own_task.cfg, own_task.palm_radius)
        try:
            own = G._hold(own_task, sc_own)
        finally:
            sc_own.close()
        assert np.abs(own - hold).max() > 0.3  # the original closing its own fingers ends elsewhere
    finally:
        sc.close()


def test_grasp_hold_keys_the_cache_of_original_urdfs_only(hands_dir):
    orig = CFG.with_overrides(urdf="original")
    assert G.cache_key(resolve(orig)) != G.cache_key(resolve(orig.with_overrides(grasp_hold="own")))
    assert G.cache_key(resolve(CFG)) == G.cache_key(resolve(CFG.with_overrides(grasp_hold="own")))
