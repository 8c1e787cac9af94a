"""Couplings in synthesis and evaluation: NLP equality rows, projected starts, coupled squeeze targets."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from ohra.canonical.couplings import Coupling, residual
from ohra.canonical.kinematics import HandModel
from ohra.canonical.params import JOINT_INDEX
from ohra.errors import OhraError
from ohra.hands import resolve_hand
from ohra.objects.model import ObjectModel
from ohra.sim import SimHand, squeeze_targets
from ohra.synth.constraints.coupling import couplings as coupling_rows
from ohra.synth.init import initial_poses
from ohra.synth.nlp import GraspNLP, NLPSettings

I2, I3 = JOINT_INDEX["index_joint2"], JOINT_INDEX["index_joint3"]


def test_coupling_rows_give_the_closed_form_least_squares_point():
    """min (x - 1)^2 + y^2 s.t. y = 2 x + 0.1: substituting y, 10 x - 1.6 = 0, so x = 0.16, y = 0.42."""
    q = ca.SX.sym("q", 2)
    block = coupling_rows(q, np.array([I2, I3]), np.zeros(22), [Coupling("index_joint3", "index_joint2", 2.0, 0.1)])
    assert len(block) == 1 and block.lower[0] == block.upper[0] == 0.0
    solver = ca.nlpsol("s", "ipopt", {"x": q, "f": (q[0] - 1) ** 2 + q[1] ** 2, "g": ca.vertcat(*block.g)},
                       {"ipopt.print_level": 0, "print_time": 0, "ipopt.sb": "yes"})
    x = np.asarray(solver(x0=[0.0, 0.0], lbg=block.lower, ubg=block.upper)["x"]).ravel()
    np.testing.assert_allclose(x, [0.16, 0.42], atol=1e-8)


def test_coupling_rows_use_a_locked_driver_and_reject_two_locked_slots_that_disagree():
    q = ca.SX.sym("q", 1)
    fixed = np.zeros(22)
    fixed[I2] = 0.3
    block = coupling_rows(q, np.array([I3]), fixed, [Coupling("index_joint3", "index_joint2", 2.0, 0.1)])
    f = ca.Function("g", [q], [ca.vertcat(*block.g)])
    assert float(f(0.7)) == pytest.approx(0.0)  # 0.7 = 2 * 0.3 + 0.1
    with pytest.raises(OhraError, match="both slots are locked"):
        coupling_rows(ca.SX.sym("q", 0), np.zeros(0, dtype=int), fixed, [Coupling("index_joint3", "index_joint2", 2.0, 0.1)])


@pytest.fixture(scope="module")
def inspire():
    ref = resolve_hand("inspire_hand_right")
    assert ref.couplings, "the Inspire hand is the coupled test hand"
    return ref


def _solve(ref, couplings, n=3):
    hand, obj = HandModel.from_params(ref.params), ObjectModel.builtin("box")
    nlp = GraspNLP(hand, obj, NLPSettings(couplings=tuple(couplings)))
    return [nlp.solve(st["R0"], st["t0"], st["q0"], st["q_pref"])
            for st in initial_poses(hand, obj, n, np.random.default_rng(0), couplings)]


def test_synthesised_inspire_grasps_respect_the_couplings(inspire):
    sols = _solve(inspire, inspire.couplings)
    ok = [r for r in sols if r["success"]]
    assert len(ok) >= 2
    for r in ok:
        assert r["coupling_residual"] < 1e-6  # the equality rows themselves, before projection
        assert np.abs(residual(inspire.couplings, r["grasp"][9:])).max() < 1e-6
    # the couplings were active: the solutions flex the coupled fingers away from the start
    assert max(abs(r["grasp"][9 + I3] - r["grasp"][9 + I2]) for r in ok) > 1e-3


def test_without_the_rows_the_solver_breaks_the_couplings(inspire):
    """The same starts without coupling rows end off the manifold, so the test above can fail."""
    sols = _solve(inspire, ())
    assert max(np.abs(residual(inspire.couplings, r["grasp"][9:])).max() for r in sols) > 1e-3


def test_starts_are_projected_onto_the_couplings(inspire):
    hand, obj = HandModel.from_params(inspire.params), ObjectModel.builtin("sphere")
    for st in initial_poses(hand, obj, 4, np.random.default_rng(1), inspire.couplings):
        assert np.abs(residual(inspire.couplings, st["q0"])).max() < 1e-12
        assert np.abs(residual(inspire.couplings, st["q_pref"])).max() < 1e-12


def test_squeeze_targets_of_a_coupled_hand_drive_coupled_joints_with_their_drivers(inspire):
    sim = SimHand.from_params(inspire.params, "inspire", couplings=inspire.couplings)
    assert sim.coupled
    rng = np.random.default_rng(0)
    qs = sim.project_sim(sim.lower + rng.uniform(0.2, 0.8, len(sim.joints)) * (sim.upper - sim.lower))
    closes = rng.random(len(sim.joints)) < 0.5  # disagreeing directions would pull a coupled pair apart
    free_reset, free_target = squeeze_targets(qs, sim.lower, sim.upper, closes)
    assert np.abs(residual(inspire.couplings, sim.to_canonical(free_target))).max() > 1e-3
    reset, target = squeeze_targets(qs, sim.lower, sim.upper, closes, couple=sim.project_sim)
    for q in (reset, target):
        assert np.abs(residual(inspire.couplings, sim.to_canonical(q))).max() < 1e-12
    drivers = [sim.joints.index(c.driver) for c in inspire.couplings]
    np.testing.assert_array_equal(target[drivers], free_target[drivers])  # drivers keep their own squeeze


def test_evaluator_drives_and_reports_a_coupled_canonical_hand_on_its_couplings(inspire, monkeypatch):
    from ohra.sim import GraspEvaluator
    from ohra.sim.world import World

    sols = [r for r in _solve(inspire, inspire.couplings, n=2) if r["success"]]
    driven = []
    original = World.drive_joints
    monkeypatch.setattr(World, "drive_joints", lambda self, t: (driven.append(np.array(t)), original(self, t))[1])
    ev = GraspEvaluator("inspire_hand_right", ObjectModel.builtin("box"))  # a name brings its couplings
    rep = ev.evaluate(np.array([r["grasp"] for r in sols]))
    ev.close()
    assert driven and ev.hand.coupled
    for t in driven:
        assert np.abs(residual(inspire.couplings, ev.hand.to_canonical(t))).max() < 1e-9
    assert np.abs(residual(inspire.couplings, rep.post_grasps[:, 9:])).max() < 1e-9


def test_links_without_inertial_get_the_small_dummy_one_not_pybullets_1_kg():
    from ohra.canonical.urdfgen import DUMMY_MASS
    from ohra.sim.hands import prepare_urdf

    text = ('<robot name="r"><link name="a"><inertial><mass value="0.2"/><inertia ixx="1e-4" ixy="0" ixz="0" iyy="1e-4" '
            'iyz="0" izz="1e-4"/></inertial></link><link name="tip"/><joint name="j" type="fixed"><parent link="a"/>'
            '<child link="tip"/></joint></robot>')
    import xml.etree.ElementTree as ET

    root = ET.fromstring(prepare_urdf(text, {}))
    masses = {ln.get("name"): float(ln.find("inertial/mass").get("value")) for ln in root.iter("link")}
    assert masses == {"a": 0.2, "tip": DUMMY_MASS}


def test_original_inspire_links_are_light_and_swing_across_their_axes(inspire):
    """Inspire's links turn about their frame's z: the squeeze direction must come from the link's extent."""
    import pybullet as pb

    from ohra.sim import GraspEvaluator

    ev = GraspEvaluator.original("inspire_hand_right", ObjectModel.builtin("sphere"), form=inspire.form)
    w = ev.world
    masses = [pb.getDynamicsInfo(w.body, j, physicsClientId=w.client)[0] for j, _ in w.links if j >= 0]
    axis, direction, _ = w.joint_frames()
    ev.close()
    assert max(masses) < 0.05  # kg; a fingertip frame without <inertial> used to add 1 kg
    assert np.abs((axis * direction).sum(axis=1)).max() < 0.9
