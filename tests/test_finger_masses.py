"""Finger masses: the canonical hand can carry the original URDF's finger masses (geometry unchanged).

The template weighs capsules at 1000 kg/m^3; real hands' URDFs are 1.3-25x heavier per finger, and
that mass changes how a grasp resists the six-direction test (README, Table 4 analogue), so
``SimHand.with_finger_masses`` / ``--inertials original`` give the canonical hand the original's.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pybullet as pb
import pytest

from ohra.errors import GraspError, OhraError
from ohra.hands import get_hand
from ohra.sim import Protocol, SimHand
from ohra.sim.world import World

from sim_fixtures import pinch_box, pinch_hand


def _inertials(urdf: str) -> dict[str, tuple[float, np.ndarray, str]]:
    out = {}
    for link in ET.fromstring(urdf).iter("link"):
        i = link.find("inertial")
        if i is not None:
            I = i.find("inertia")
            out[link.get("name")] = (float(i.find("mass").get("value")),
                                     np.array([float(I.get(a, 0)) for a in ("ixx", "iyy", "izz")]),
                                     ET.tostring(i.find("origin"), encoding="unicode") if i.find("origin") is not None else "")
    return out


def test_each_finger_weighs_its_target_and_stays_one_rigid_body():
    hand = SimHand.from_params(pinch_hand(), name="pinch")
    before = hand.finger_masses
    present = before > 0
    target = np.where(present, before * np.array([3.0, 0.5, 7.0, 2.0, 1.5]), 0.0)
    heavy = hand.with_finger_masses(target)
    np.testing.assert_allclose(heavy.finger_masses, target, rtol=1e-12)
    a, b = _inertials(hand.urdf), _inertials(heavy.urdf)
    for name, (m, I, origin) in a.items():
        k = b[name][0] / m
        np.testing.assert_allclose(b[name][1], k * I, rtol=1e-12)  # inertia scales with the mass: same shape
        assert b[name][2] == origin  # centre of mass unchanged
        if hand.link_finger.get(name, -1) < 0:
            assert k == 1.0  # the palm keeps its mass
    strip = lambda u: [ET.tostring(c, encoding="unicode") for c in ET.fromstring(u).iter("collision")]
    assert strip(heavy.urdf) == strip(hand.urdf)  # geometry untouched


def test_pybullet_sees_the_scaled_masses():
    hand = SimHand.from_params(pinch_hand(), name="pinch")
    target = hand.finger_masses * 4.0
    w = World(hand.with_finger_masses(target), pinch_box(), Protocol())
    try:
        got = np.zeros(5)
        for j in range(pb.getNumJoints(w.body, physicsClientId=w.client)):
            f = w.link_finger.get(j, -1)
            if f >= 0:
                got[f] += pb.getDynamicsInfo(w.body, j, physicsClientId=w.client)[0]
    finally:
        w.close()
    np.testing.assert_allclose(got, target, rtol=1e-9)


def test_bad_masses_and_original_hands_are_refused():
    hand = SimHand.from_params(pinch_hand(), name="pinch")
    for bad in ([1.0, 2.0], [0.1, -0.1, 0.1, 0.1, 0.1], [np.nan] * 5):
        with pytest.raises(GraspError, match="finger masses"):
            hand.with_finger_masses(bad)


def test_original_finger_masses_of_registered_hands(hands_dir):
    """Barrett's URDF fingers weigh about 1 kg each (BH8: 1.2 kg in all); the capsules ~0.05 kg."""
    b = SimHand.registered_original("barrett_hand")
    m = b.finger_masses
    assert m[3] == 0 and m[4] == 0 and 0.3 < m[0] < 0.8 and 0.8 < m[1] < 1.3 and m[1] == pytest.approx(m[2], rel=1e-6)
    c = SimHand.from_params(get_hand("barrett_hand"), name="barrett_hand")
    assert np.all(c.finger_masses[:3] < 0.1)
    np.testing.assert_allclose(c.with_finger_masses(m).finger_masses, m, rtol=1e-12)
    with pytest.raises(GraspError, match="canonical hands"):
        b.with_finger_masses(m)


def test_cli_eval_inertials_original_needs_a_hand_with_an_original(tmp_path, capsys):
    from ohra.cli.main import main

    hand = tmp_path / "pinch.json"
    pinch_hand().to_json(hand)
    mesh = tmp_path / "box.stl"
    pinch_box().mesh.export(str(mesh))
    g = tmp_path / "g.npz"
    np.savez(g, grasps=np.zeros((1, 31)))
    rc = main(["eval", str(g), "--hand", str(hand), "--object", str(mesh), "--inertials", "original", "--quiet"])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and "Traceback" not in err
    assert "original finger masses (--inertials original) needs the original hand, which is unknown for 'pinch'" in err


def test_original_finger_masses_of_a_hand_given_by_its_spec_file(hands_dir):
    """`ohra eval --inertials original --hand my_hand.yaml` answered "needs a registered hand" although
    --original takes a spec."""
    from ohra.hands.registry import spec_path
    from ohra.sim.hands import original_finger_masses

    by_spec = original_finger_masses(str(spec_path("barrett_hand")), "base")
    np.testing.assert_array_equal(by_spec, original_finger_masses("barrett_hand", "base"))
    assert by_spec[1] > 0.8


def test_grasp_eval_replays_a_hand_given_by_its_spec_file_on_its_original_urdf(hands_dir):
    """`ohra grasp eval --original --hands my_hand.yaml` answered "needs a registered hand's original URDF" although
    `ohra eval --original` takes a spec; the pair is simulated on the spec's original URDF."""
    import warnings

    from ohra.hands.registry import spec_path
    from ohra.learn.grasp.evaluate import evaluate_model
    from ohra.learn.grasp.model import load_grasp_model
    from ohra.sim import GraspEvaluator, SimHand

    spec = str(spec_path("barrett_hand"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rep = evaluate_model(load_grasp_model(), [spec], ["builtin:box"], n=6, original=True, allow_seen=True, progress=False)
        pair = rep.pairs[0]
        with GraspEvaluator(SimHand.original_of(spec, "base"), "builtin:box") as ev:
            on_original = ev.evaluate(pair.grasps, progress=False).success
        with GraspEvaluator(SimHand.from_params(get_hand(spec), name="b"), "builtin:box") as ev:
            on_canonical = ev.evaluate(pair.grasps, progress=False).success
    assert pair.original and rep.meta["original"]
    np.testing.assert_array_equal(pair.success, on_original)
    assert (on_original != on_canonical).any()  # the two URDFs tell these grasps apart: the check above means something


def test_grasp_eval_with_original_masses_names_a_hand_without_an_original():
    from ohra.learn.grasp.evaluate import evaluate_model

    with pytest.raises(GraspError, match=r"needs the hand's original URDF: give the hand by name, spec YAML or params JSON"):
        evaluate_model(object(), [get_hand("barrett_hand")], ["builtin:box"], n=1, inertials="original", allow_seen=True)
    with pytest.raises(GraspError, match=r"inertials='original' \(--inertials original\): leap_3303 is a LEAP variant"):
        evaluate_model(object(), ["leap_3303"], ["builtin:box"], n=1, inertials="original", allow_seen=True)
    with pytest.raises(GraspError, match="inertials must be one of"):
        evaluate_model(object(), ["barrett_hand"], ["builtin:box"], n=1, inertials="steel")
