"""What a notebook user sees when printing the library's main objects: one line saying what it is
(not every network layer or array, not a bare memory address)."""

from __future__ import annotations

import pytest

import ohra
from ohra.objects import ObjectModel


def _one_line(r: str) -> str:
    assert "\n" not in r and len(r) < 300 and " at 0x" not in r, r
    return r


def test_hand_model_names_its_dof_and_fingers():
    r = _one_line(repr(ohra.HandModel.from_params(ohra.get_hand("barrett_hand"))))
    assert r == "HandModel(dof=8, fingers=['thumb', 'index', 'middle'], form=BaseParams)"
    r = _one_line(repr(ohra.HandModel.from_params(ohra.get_hand("leap_3033"))))
    assert "fingers=['thumb', 'middle', 'little']" in r  # the variant without the index finger


def test_object_model_gives_its_size_from_the_mesh():
    r = _one_line(repr(ObjectModel.builtin("box")))
    assert r.startswith("ObjectModel('box', mesh extents (5, 6, 8) cm") and "watertight=True" in r


def test_grasp_model_and_vae_say_what_they_are():
    pytest.importorskip("torch", reason="the learned models need the learn extra (torch)")
    from ohra.learn import load_grasp_model, load_vae

    r = _one_line(repr(load_grasp_model()))
    assert r.startswith("GraspModel(condition='vae', encoder='pointnet', parameters=") and "barrett_hand" in r
    r = _one_line(repr(load_vae()))
    assert r.startswith("VAEBundle(encoding='rot6d70', latent_dim=32")


def test_grasp_evaluation_reports_give_success_not_arrays():
    import numpy as np

    from ohra.sim.evaluator import EvalReport, GraspResult
    from ohra.sim.protocol import Protocol

    results = [GraspResult(success=s, displacement=np.zeros(7), final_distance_from_origin=0.0, contacts=3,
                           initial_penetration=0.0, post_grasp=np.zeros(31), clamped=False, early_exit=False, steps=10)
               for s in (True, False, False, True)]
    r = _one_line(repr(EvalReport(results, mode="filter", protocol=Protocol())))
    assert r == "EvalReport(mode='filter', 4 grasps, success 50.0 %, 0 clamped)"


def test_model_evaluation_report_gives_each_hands_success():
    import numpy as np

    from ohra.learn.grasp.evaluate import GraspEvalReport, PairResult

    def pair(hand, obj, success):
        return PairResult(hand, obj, "h", False, 0, np.array(success, bool), np.zeros((len(success), 31)), 0.1, 1.0,
                          None, None)

    pairs = [pair("barrett_hand", "box", [1, 0]), pair("barrett_hand", "can", [1, 1]), pair("dex3_right", "box", [0, 0])]
    assert _one_line(repr(pairs[0])) == "PairResult('barrett_hand', 'box', 1/2 succeed)"
    r = _one_line(repr(GraspEvalReport(pairs, meta={"model": "x" * 500})))
    assert r == "GraspEvalReport(3 pairs: barrett_hand 75.0 % of 4; dex3_right 0.0 % of 2)"


def test_rotation_evaluation_gives_the_table3_metrics():
    pytest.importorskip("stable_baselines3", reason="the rotation policies need the rl extra")
    from ohra.learn.rl.evaluate import EvalResult

    res = EvalResult("runs/x", 2, 1000, [400, 200], [3.0, 1.0], [None, "fell"], 400,
                     returns={"rotation": [1.0] * 2})
    r = _one_line(repr(res))
    assert r == "EvalResult('runs/x', 2 episodes: Steps-to-Fall 300.0 +- 100.0, rotation 2.00 +- 1.00 rad, 50 % survive)"
