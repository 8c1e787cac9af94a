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
