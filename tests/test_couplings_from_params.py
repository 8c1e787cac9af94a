"""A coupled hand given by its params alone (``get_hand(name)``, as the notebooks do) keeps its couplings in every API
that takes bare params: the evaluator, synthesis, heuristic grasps, and contact sheets (which show the simulated pose)."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from ohra.canonical.couplings import project, residual
from ohra.canonical.kinematics import HandModel
from ohra.canonical.params import ExtendedParams
from ohra.hands import couplings_of, get_couplings, get_hand
from ohra.objects.model import ObjectModel
from ohra.sim import GraspEvaluator, SimHand
from ohra.sim.heuristic import heuristic_grasps

HAND = "inspire_hand_right"  # the registered hand with mimic couplings (six)


@pytest.fixture(scope="module")
def box():
    return ObjectModel.builtin("box")


@pytest.mark.parametrize("form", ["base", "extended"])
def test_params_of_a_registered_coupled_hand_bring_its_couplings_and_no_other_params_do(form):
    params = get_hand(HAND, form)
    assert couplings_of(params) == get_couplings(HAND, form) and len(couplings_of(params)) == 6
    edited = params.to_vector()
    edited[0] += 1e-4  # palm radius 0.1 mm larger: another hand
    assert couplings_of(type(params).from_vector(edited)) == ()
    assert couplings_of(get_hand("shadow_hand_right", form)) == ()
    assert couplings_of(get_hand("leap_3303")) == ()
    assert isinstance(get_hand("leap_3303"), ExtendedParams)


def test_the_evaluator_given_params_drives_the_hands_couplings(box):
    with GraspEvaluator(get_hand(HAND), box) as ev:
        assert ev.hand.couplings == get_couplings(HAND) and ev.hand.coupled


def test_heuristic_grasps_keep_the_couplings_simulation_will_impose(box):
    hm = HandModel.from_params(get_hand(HAND))
    kept = heuristic_grasps(hm, box, 4, seed=0)
    assert np.abs(residual(get_couplings(HAND), kept[:, 9:])).max() < 1e-12
    broken = heuristic_grasps(hm, box, 4, seed=0, couplings=())  # what they were before: up to ~0.8 rad off
    assert np.abs(residual(get_couplings(HAND), broken[:, 9:])).max() > 0.1


def test_a_contact_sheet_shows_the_pose_the_evaluator_starts_from(box):
    from ohra.sim.render import render_grasps

    hm = HandModel.from_params(get_hand(HAND))
    g = heuristic_grasps(hm, box, 1, seed=0, couplings=())
    fixed = g.copy()
    fixed[:, 9:] = project(get_couplings(HAND), g[:, 9:])
    assert not np.allclose(g, fixed)
    hand = SimHand.from_params(get_hand(HAND), couplings=get_couplings(HAND))
    shown, simulated = render_grasps(hand, box, np.vstack([g, fixed]), size=96)
    np.testing.assert_array_equal(shown, simulated)


def test_synthesis_given_name_and_params_records_and_uses_the_couplings(box, tmp_path):
    from ohra.synth.pipeline import SynthSettings, synthesize

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        synthesize([(HAND, get_hand(HAND))], [box], tmp_path / "d", SynthSettings(grasps_per_object=1, filter=False, seed=0),
                   progress=False)
    entry = json.loads((tmp_path / "d" / "manifest.json").read_text())["hands"][HAND]
    assert len(entry["couplings"]) == 6


def test_ohra_eval_says_when_it_sets_coupled_joints_from_their_drivers(box, tmp_path, capsys):
    from ohra.cli.main import main

    hm = HandModel.from_params(get_hand(HAND))
    path = tmp_path / "g.npy"
    np.save(path, heuristic_grasps(hm, box, 1, seed=0, couplings=()))
    assert main(["eval", str(path), "--hand", HAND, "--object", "builtin:box", "--quiet"]) == 0
    assert f"1 of 1 grasp(s) hold coupled joints of {HAND} off their drivers' values" in capsys.readouterr().err
    np.save(path, heuristic_grasps(hm, box, 1, seed=0))
    assert main(["eval", str(path), "--hand", HAND, "--object", "builtin:box", "--quiet"]) == 0
    assert "coupled joints" not in capsys.readouterr().err
