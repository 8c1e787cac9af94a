"""Six-direction evaluator: hand-made grasps with known outcomes, determinism, protocol values."""

from __future__ import annotations

import math

import xml.etree.ElementTree as ET

import numpy as np
import pybullet as pb
import pytest

from ohra import ActionMap, GraspError, HandModel, JOINT_NAMES
from ohra.sim import GraspEvaluator, Protocol, SimHand, closes_positive, squeeze_targets
from ohra.canonical.urdfgen import DUMMY_MASS, render
from ohra.errors import ObjectWarning
from ohra.objects.model import ObjectModel

from sim_fixtures import L, R_F, pinch_box, pinch_grasp, pinch_hand


@pytest.fixture(scope="module")
def evaluator():
    ev = GraspEvaluator(pinch_hand(), pinch_box())
    yield ev
    ev.close()


def test_box_pinched_between_two_opposing_fingers_passes(evaluator):
    r = evaluator.evaluate(pinch_grasp()).results[0]
    assert r.success and r.contacts >= 2
    assert r.displacement[-1] <= 0.02


def test_hand_three_cm_away_fails(evaluator):
    r = evaluator.evaluate(pinch_grasp(dx=0.03)).results[0]
    assert not r.success and r.contacts == 0


def test_single_fingertip_contact_fails(evaluator):
    r = evaluator.evaluate(pinch_grasp(dy=0.02)).results[0]
    assert not r.success


def test_a_hand_given_as_params_is_named_by_its_content():
    """Reports of two unnamed hands were both 'canonical_hand'; a name given is kept."""
    from dataclasses import replace

    wider = replace(pinch_hand(), finger_xyz=[[x, 1.1 * y, z] for x, y, z in pinch_hand().finger_xyz])
    names = []
    for params in (pinch_hand(), pinch_hand(), wider):
        with GraspEvaluator(params, pinch_box()) as ev:
            names.append(ev.evaluate(pinch_grasp()).meta["hand"])
    assert names[0] == names[1] != names[2] and names[0].startswith("canonical_") and len(names[0]) == len("canonical_") + 8
    assert GraspEvaluator(SimHand.from_params(pinch_hand(), name="pinch"), pinch_box()).hand.name == "pinch"


def test_deep_penetration_is_reported():
    ev = GraspEvaluator(pinch_hand(), pinch_box(gap=-0.006))
    r = ev.evaluate(pinch_grasp()).results[0]
    assert r.initial_penetration == pytest.approx(0.006, abs=1e-4)  # exact: no collision margin on the object
    ev.close()


def test_outcomes_do_not_depend_on_order_batch_or_workers(evaluator):
    G = np.array([pinch_grasp(), pinch_grasp(dx=0.03), pinch_grasp(dy=0.02), pinch_grasp(dx=0.004, dy=-0.003)])
    a = evaluator.evaluate(G)
    b = evaluator.evaluate(G[::-1])
    c = GraspEvaluator(pinch_hand(), pinch_box()).evaluate(G, workers=2)
    single = [evaluator.evaluate(g).results[0] for g in G]
    for k in range(len(G)):
        for other in (b.results[len(G) - 1 - k], c.results[k], single[k]):
            assert other.success == a.results[k].success
            assert np.array_equal(other.post_grasp, a.results[k].post_grasp)
            assert np.array_equal(other.displacement, a.results[k].displacement, equal_nan=True)


def test_early_exit_changes_no_outcome():
    G = np.array([pinch_grasp(), pinch_grasp(dx=0.03), pinch_grasp(dy=0.02)])
    on = GraspEvaluator(pinch_hand(), pinch_box()).evaluate(G)
    off = GraspEvaluator(pinch_hand(), pinch_box(), Protocol(early_exit=False)).evaluate(G)
    assert on.success.tolist() == off.success.tolist()
    assert any(r.early_exit for r in on.results)


def test_loaded_bodies_carry_protocol_mass_and_friction(evaluator):
    evaluator.evaluate(pinch_grasp())  # the object body exists after a grasp
    w = evaluator.world
    c = w.client
    box = pinch_box()
    obj = pb.getDynamicsInfo(w.obj_body, -1, physicsClientId=c)
    assert obj[0] == pytest.approx(box.volume * 500.0)
    mu = math.sqrt(3.0)  # PyBullet multiplies the two coefficients: effective 3.0
    assert obj[1] == pytest.approx(mu)
    # the object's inertia is the mesh's (a 3 x 4 cm face box: principal moments m (b^2 + c^2) / 12)
    m, (a, b, cc) = box.volume * 500.0, box.mesh.extents
    expected = sorted(m * np.array([b * b + cc * cc, a * a + cc * cc, a * a + b * b]) / 12)
    assert sorted(obj[2]) == pytest.approx(expected, rel=1e-6)
    for j, _ in w.links:  # every hand link, the palm (base, -1) included
        assert pb.getDynamicsInfo(w.body, j, physicsClientId=c)[1] == pytest.approx(mu)


def _declared_masses(urdf: str) -> tuple[dict[str, float], dict[str, str]]:
    root = ET.fromstring(urdf)
    mass = {l.get("name"): float(l.find("inertial/mass").get("value")) for l in root.iter("link")}
    fixed_parent = {j.find("child").get("link"): j.find("parent").get("link") for j in root.iter("joint") if j.get("type") == "fixed"}
    return mass, fixed_parent


def test_dummy_links_carry_their_small_declared_mass(evaluator):
    """No link gets PyBullet's 1 kg default: every loaded link weighs what the URDF declares for it
    plus the links merged into it through fixed joints (tip frames, locked joints)."""
    w = evaluator.world
    mass, fixed_parent = _declared_masses(w.hand.urdf)

    def survivor(link: str) -> str:
        while link in fixed_parent:
            link = fixed_parent[link]
        return link

    expected: dict[str, float] = {}
    for link, m in mass.items():
        expected[survivor(link)] = expected.get(survivor(link), 0.0) + m
    dummies = 0
    for j, name in w.links[1:]:  # the fixed base reports mass 0 in PyBullet
        got = pb.getDynamicsInfo(w.body, j, physicsClientId=w.client)[0]
        assert got == pytest.approx(expected[name], rel=1e-9), name
        if name.endswith("_knuckle"):
            assert got == pytest.approx(DUMMY_MASS)
            dummies += 1
    assert dummies == 2


def test_capsule_links_keep_their_exact_shape(evaluator):
    """The cylinder + two spheres of a canonical link load as one native capsule of the same size."""
    w = evaluator.world
    hm = HandModel.from_params(pinch_hand())
    q = np.zeros(22)
    q[[6, 19]] = 0.4
    w.reset_hand(np.eye(4), w.hand.to_sim(q))
    link = dict((n, j) for j, n in w.links)["index_distal"]
    T = hm.frame_pose(q, "index_distal")
    probe = pb.createCollisionShape(pb.GEOM_SPHERE, radius=1e-3, physicsClientId=w.client)
    for local in ([0.0, 0.0, L[2] + 0.004], [R_F + 0.004, 0.0, L[2] / 2]):  # probe surface 3 mm off the tip / side
        p = T[:3, :3] @ np.array(local) + T[:3, 3]
        b = pb.createMultiBody(0, probe, -1, p.tolist(), physicsClientId=w.client)
        d = min(cp[8] for cp in pb.getClosestPoints(w.body, b, 0.05, linkIndexA=link, physicsClientId=w.client))
        pb.removeBody(b, physicsClientId=w.client)
        assert d == pytest.approx(0.003, abs=1e-6)


def test_strict_preset():
    p = Protocol.strict()
    assert p.friction == 1.0 and p.gravity_in_evaluation == pytest.approx(9.81)
    assert Protocol().friction == 3.0 and Protocol().gravity_in_evaluation == 0.0
    assert p.total_steps == 7 * 240 and Protocol.preset("strict") == p


def test_default_step_is_240_hz_and_the_isaac_step_is_a_preset():
    p = Protocol()
    assert p.dt == pytest.approx(1 / 240) and p.substeps == 1 and p.solver_iterations == 100
    isaac = Protocol.preset("isaac-step")
    assert (isaac.dt, isaac.substeps, isaac.total_steps) == (0.01, 2, 700)
    with pytest.raises(ValueError, match="isaac-step"):
        Protocol.preset("nope")


def test_strict_preset_is_harder_on_the_same_grasp():
    """Friction 1 with gravity moves the squeezed box further than the reference's friction 3 without
    gravity; with gravity and no friction at all the box falls out of the pinch."""
    runs = {}
    for name, prot in {"reference": Protocol(), "strict": Protocol.strict(),
                       "frictionless": Protocol.strict(friction=0.0)}.items():
        with GraspEvaluator(pinch_hand(), pinch_box(), prot) as ev:
            runs[name] = ev.evaluate(pinch_grasp()).results[0]
    assert runs["reference"].success and not runs["frictionless"].success
    worst = {k: np.nanmax(r.displacement[1:]) for k, r in runs.items()}
    assert worst["reference"] < worst["strict"] < worst["frictionless"]


def test_squeeze_controller_opens_then_closes_past_the_grasp():
    """A joint whose positive rotation moves its link toward the object resets toward its lower limit
    and targets past the grasp toward its upper limit (reference controller.py), and vice versa."""
    # joint at (0, 0.05, 0), axis +x, link along +z: +q moves the link toward -y, i.e. toward the origin
    closes = closes_positive(np.array([[1.0, 0, 0], [-1.0, 0, 0]]), np.array([[0, 0, 1.0], [0, 0, 1.0]]),
                             np.array([[0, 0.05, 0], [0, 0.05, 0]]))
    assert closes.tolist() == [True, False]
    reset, target = squeeze_targets(np.array([0.5, 0.5]), np.zeros(2), np.ones(2), closes)
    assert reset == pytest.approx([0.45, 0.55]) and target == pytest.approx([0.55, 0.45])


def test_post_simulation_grasp_is_relative_to_the_settled_object(evaluator):
    r = evaluator.evaluate(pinch_grasp()).results[0]
    assert r.post_grasp.shape == (31,)
    # the object may spin but its origin moved <= 2 cm, so the palm's distance to it is kept to 2 cm
    assert abs(np.linalg.norm(r.post_grasp[:3]) - np.linalg.norm(pinch_grasp()[:3])) <= 0.02
    q = r.post_grasp[9:]
    assert np.all(q[[5, 18]] != 0) and np.all(q[:5] == 0)  # settled joints; absent ones stay 0


def test_bad_grasp_input_is_a_clear_error(evaluator):
    with pytest.raises(GraspError, match=r"shape \(N, 31\)"):
        evaluator.evaluate(np.zeros((2, 30)))
    g = pinch_grasp()
    g[5] = np.nan
    with pytest.raises(GraspError, match="grasp 0 contains NaN"):
        evaluator.evaluate(g)
    g = pinch_grasp()
    g[3:9] = 0.0
    with pytest.raises(GraspError, match="not a rotation"):
        evaluator.evaluate(g)


def test_joints_outside_limits_are_clamped_with_a_warning(evaluator):
    g = pinch_grasp()
    g[9 + 6] = 3.0  # index flexion beyond its 1.5 rad limit
    with pytest.warns(UserWarning, match="clamped"):
        rep = evaluator.evaluate(g)
    assert rep.clamped_count == 1


def _as_original(params, palm_origin=np.zeros(6)) -> tuple[str, ActionMap]:
    """The canonical URDF as if it were an original hand: identity joint map, root ``palm_origin`` away."""
    text = render(params)
    root = ET.fromstring(text)
    j = next(j for j in root.iter("joint") if j.get("name") == "world_to_palm")
    j.find("origin").set("xyz", " ".join(str(x) for x in palm_origin[:3]))
    j.find("origin").set("rpy", " ".join(str(x) for x in palm_origin[3:]))
    present = [n for n, lo, up in zip(JOINT_NAMES, params.joint_lowers, params.joint_uppers) if up > lo]
    am = ActionMap.from_urdf(ET.tostring(root, encoding="unicode"), {n: n for n in present}, palm_origin=palm_origin)
    return ET.tostring(root, encoding="unicode"), am


def test_original_hand_path_reproduces_the_canonical_hand_exactly():
    G = np.array([pinch_grasp(), pinch_grasp(dx=0.03), pinch_grasp(dy=0.02)])
    canon = GraspEvaluator(pinch_hand(), pinch_box()).evaluate(G)
    urdf, am = _as_original(pinch_hand())
    orig = GraspEvaluator.from_urdf(urdf, am, pinch_box()).evaluate(G)
    for a, b in zip(canon.results, orig.results):
        assert a.success == b.success
        assert np.array_equal(a.post_grasp, b.post_grasp)


def test_original_hand_with_offset_root_is_placed_by_its_palm_origin():
    """A root frame 5 cm and 0.3 rad away from the palm: the palm still lands at the grasp pose."""
    po = np.array([0.0, 0.02, -0.05, 0.0, 0.0, 0.3])
    urdf, am = _as_original(pinch_hand(), po)
    ev = GraspEvaluator.from_urdf(urdf, am, pinch_box())
    assert not ev.hand.canonical
    r = ev.evaluate(np.array([pinch_grasp(), pinch_grasp(dx=0.03)]))
    assert r.success.tolist() == [True, False]
    # the pinched box may spin about the line between the fingertips; the palm's distance to the box
    # origin changes by at most how far that origin moved (squeeze + perturbations)
    r0 = r.results[0]
    moved = r0.displacement[0] + r0.displacement[-1]
    assert abs(np.linalg.norm(r0.post_grasp[:3]) - np.linalg.norm(pinch_grasp()[:3])) <= moved + 1e-9


def test_report_is_json_with_null_for_phases_not_run(evaluator):
    import json

    rep = evaluator.evaluate(np.array([pinch_grasp(), pinch_grasp(dx=0.03)]))
    d = json.loads(rep.to_json())
    assert d["n"] == 2 and d["successes"] == 1 and d["hand"] and d["object"] == "pinch_box"
    assert set(d["grasps"][0]["displacement_m"]) == {"squeeze", "+x", "+y", "+z", "-x", "-y", "-z"}
    assert None not in d["grasps"][0]["displacement_m"].values()
    # the hand 3 cm away never touches the box: it flies off and the run stops early, so the phases
    # after the stop are null (NaN in the result)
    assert d["grasps"][1]["early_exit"] and not d["grasps"][1]["success"]
    assert None in d["grasps"][1]["displacement_m"].values()
    assert sum(v is None for v in d["grasps"][1]["displacement_m"].values()) == int(np.isnan(rep.results[1].displacement).sum())


def test_compound_ycb_object_loads_its_convex_pieces_with_protocol_mass(objects_dir):
    from ohra.objects.model import ObjectModel

    obj = ObjectModel.load(objects_dir / "ycb" / "MustardBottle" / "model.urdf")
    ev = GraspEvaluator(pinch_hand(), obj)
    w = ev.world
    b = w.new_object()
    assert len(pb.getCollisionShapeData(b, -1, physicsClientId=w.client)) == len(obj.convex_pieces()) > 1
    assert pb.getDynamicsInfo(b, -1, physicsClientId=w.client)[0] == pytest.approx(obj.volume * 500.0)
    # the object's mesh frame sits at the world origin (PyBullet reports the inertial frame)
    assert np.allclose(w.object_frame(), np.eye(4), atol=1e-6)
    ev.close()


def test_heuristic_benchmark_grasps_are_seeded_and_valid():
    from ohra.objects.model import ObjectModel
    from ohra.rotations import check_grasps
    from ohra.sim.heuristic import heuristic_grasps

    hm = HandModel.from_params(pinch_hand())
    obj = ObjectModel.builtin("box")
    a = heuristic_grasps(hm, obj, 3, seed=5, samples=32)
    assert np.array_equal(a, heuristic_grasps(hm, obj, 3, seed=5, samples=32))
    check_grasps(a)
    assert np.all((a[:, 9:] >= hm.lower) & (a[:, 9:] <= hm.upper))


def test_a_stored_float32_grasp_at_a_locked_joint_is_not_clamped():
    """Allegro holds its finger twist at 0.0873 rad (lower == upper): float32 cannot store that value
    exactly, and the stored grasp must not count as outside the limits."""
    import warnings

    from ohra.hands import get_hand
    from ohra.objects.model import ObjectModel
    from ohra.sim import GraspEvaluator, SimHand
    from ohra.synth.robust import as_stored

    p = get_hand("allegro_hand_left")
    lo, up = np.asarray(p.joint_lowers), np.asarray(p.joint_uppers)
    locked = np.flatnonzero((lo == up) & (lo != 0))
    assert locked.size and np.any(np.float32(lo[locked]).astype(float) != lo[locked])
    g = np.zeros(31)
    g[:3] = (0.0, 0.0, 0.3)
    g[3:9] = (1, 0, 0, 0, 1, 0)
    g[9:] = np.clip(0.2, lo, up)
    stored = as_stored(g, lo, up)
    ev = GraspEvaluator(SimHand.from_params(p, "allegro_hand_left"), ObjectModel.builtin("sphere"))
    _, out = ev.check(stored[None])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rep = ev.evaluate(stored[None])
    ev.close()
    assert not out.any() and rep.clamped_count == 0


def test_the_evaluator_drops_urdf_joint_damping_unless_the_protocol_keeps_it(hands_dir):
    """PyBullet applies a URDF's <dynamics damping> explicitly; on the original Shadow's light links it
    diverges (a free fingertip joint flies off), so the evaluator drops it by default."""
    from ohra.sim.bullet import urdf_joint_damping
    from ohra.sim.world import World

    hand = SimHand.registered_original("shadow_hand_right")
    assert urdf_joint_damping(hand.urdf) and not urdf_joint_damping(SimHand.from_params(pinch_hand()).urdf)

    def speed_after_a_free_step(protocol, joint="FFJ1"):
        """Speed of a fingertip joint one step after it starts at 1 rad/s (motors off, no gravity)."""
        world = World(hand, pinch_box(), protocol)
        c, b = world.client, world.body
        try:
            pb.setGravity(0, 0, 0, physicsClientId=c)
            pb.setJointMotorControlArray(b, world.jidx, pb.VELOCITY_CONTROL, forces=[0.0] * len(world.jidx),
                                         physicsClientId=c)
            for k, j in enumerate(world.jidx):
                pb.resetJointState(b, int(j), 0.5 * (hand.lower[k] + hand.upper[k]), float(hand.joints[k] == joint),
                                   physicsClientId=c)
            pb.stepSimulation(physicsClientId=c)
            return pb.getJointState(b, int(world.jidx[hand.joints.index(joint)]), physicsClientId=c)[1]
        finally:
            world.close()

    assert Protocol().urdf_joint_damping is False
    assert abs(speed_after_a_free_step(Protocol(urdf_joint_damping=True))) > 10.0  # explicit damping overshoots
    assert speed_after_a_free_step(Protocol()) == pytest.approx(1.0, abs=0.2)  # dropped: the joint keeps turning


def _shifted(shift) -> tuple:
    box = pinch_box()
    mesh = box.mesh.copy()
    mesh.apply_translation(shift)
    g = pinch_grasp()
    g[:3] += shift
    return ObjectModel(mesh, "pinch_box_moved", repair=False), g


@pytest.mark.parametrize("shift", [(0.0, 0.15, 0.0), (0.08, 0.0, 0.08)])
def test_under_object_point_com_a_mesh_whose_origin_lies_beside_it_holds_as_when_centred(shift):
    """The same box and grasp, the mesh's frame origin moved off the box: with ``object_point="com"`` the
    fingers close toward the box and its displacement is measured at its centre of mass, so nothing
    changes; the reference's ``"frame"`` closes toward the origin beside the box, and says so."""
    com = Protocol(object_point="com")
    centred = GraspEvaluator(pinch_hand(), pinch_box(), com).evaluate(pinch_grasp()).results[0]
    obj, g = _shifted(shift)
    moved = GraspEvaluator(pinch_hand(), obj, com).evaluate(g).results[0]
    assert centred.success and moved.success
    np.testing.assert_allclose(moved.displacement, centred.displacement, atol=2e-4)
    assert moved.final_distance_from_origin == pytest.approx(centred.final_distance_from_origin, abs=2e-4)
    with pytest.warns(ObjectWarning, match=r"origin lies .* cm from its centre of mass.*object_point='com'"):
        GraspEvaluator(pinch_hand(), obj, Protocol())


def test_object_point_com_changes_nothing_for_a_centred_object_and_unknown_points_are_refused(evaluator):
    g = np.stack([pinch_grasp(), pinch_grasp(dx=0.004), pinch_grasp(dy=0.02)])
    a = evaluator.evaluate(g)
    b = GraspEvaluator(pinch_hand(), pinch_box(), Protocol(object_point="com")).evaluate(g)
    assert [r.success for r in a.results] == [r.success for r in b.results]
    np.testing.assert_allclose([r.displacement for r in a.results], [r.displacement for r in b.results], atol=1e-9)
    with pytest.raises(ValueError, match="object_point"):
        Protocol(object_point="centre")


def test_the_evaluator_names_a_millimetre_mesh_once_per_object():
    """`ObjectModel.load("can_mm.stl")` from Python is an 80 m can; the evaluator simulated it without a word (the CLI,
    the grasp model and synthesis all warned with the --scale hint)."""
    import warnings

    import trimesh

    from ohra.objects.model import ObjectModel

    obj = ObjectModel(trimesh.creation.box(extents=(50.0, 70.0, 90.0)), "box_mm")  # 5 x 7 x 9 cm written in mm
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        GraspEvaluator("barrett_hand", obj).close()
        GraspEvaluator("barrett_hand", obj).close()
    said = [str(w.message) for w in caught if issubclass(w.category, ObjectWarning) and "graspable range" in str(w.message)]
    assert len(said) == 1 and "box_mm" in said[0] and "--scale 0.001" in said[0]


def test_an_objects_own_density_is_named_when_the_protocols_replaces_it():
    import warnings

    from ohra.objects.model import ObjectModel

    heavy = ObjectModel.builtin("box", density=2000.0)
    with pytest.warns(ObjectWarning, match=r"density 2000 kg/m\^3; the six-direction test simulates it at the protocol's "
                                           r"500 kg/m\^3 .*Protocol\(density=2000\)"):
        ev = GraspEvaluator("barrett_hand", heavy)
    assert ev.world.mass == pytest.approx(heavy.volume * 500.0)
    ev.close()
    with warnings.catch_warnings():
        warnings.simplefilter("error", ObjectWarning)
        ev = GraspEvaluator("barrett_hand", heavy, Protocol(density=2000.0))
        assert ev.world.mass == pytest.approx(heavy.mass)
        ev.close()
        GraspEvaluator("barrett_hand", ObjectModel.builtin("box")).close()
