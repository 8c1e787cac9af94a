"""A grasp model says when it is asked for a hand unlike the ones it trained on (``OutOfSupportWarning``)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("torch")

from ohra.canonical.params import ExtendedParams  # noqa: E402
from ohra.learn.encoding import OutOfSupportWarning  # noqa: E402
from ohra.learn.grasp.condition import params_vector  # noqa: E402
from ohra.learn.grasp.model import SUPPORT_MARGIN, load_grasp_model  # noqa: E402
from ohra.objects.model import ObjectModel  # noqa: E402

ABILITY = Path(__file__).parent / "data" / "ability_hand_right_base.json"


@pytest.fixture(scope="module")
def default_model():
    return load_grasp_model("default")


@pytest.fixture(scope="module")
def leap_model():
    return load_grasp_model("leap")


@pytest.fixture(scope="module")
def capsule():
    return ObjectModel.builtin("capsule")


def _support_warnings(model, hand, obj, calls=1):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for seed in range(calls):
            model.sample(hand, obj, 2, seed=seed)
    return [str(w.message) for w in caught if issubclass(w.category, OutOfSupportWarning)]


@pytest.mark.parametrize("hand", ["barrett_hand", "shadow_hand_right", "shadow_hand_left", "allegro_hand_right"])
def test_training_hands_and_their_mirror_twins_sample_without_a_warning(default_model, capsule, hand):
    assert _support_warnings(default_model, hand, capsule) == []


def test_an_unseen_hand_is_named_once_with_the_training_hands_and_how_far_out_it_lies(default_model, capsule):
    found = _support_warnings(default_model, str(ABILITY), capsule, calls=2)
    assert len(found) == 1, found
    msg = found[0]
    assert str(ABILITY) in msg and "allegro_hand_left, barrett_hand, shadow_hand_right" in msg
    worst, count = default_model.support(str(ABILITY))
    assert worst > 1.0 and count >= 3
    assert f"{count} of 32 condition entries" in msg and f"{worst:.2f} latent units" in msg


def test_held_out_leap_variants_lie_inside_the_leap_models_support_and_the_real_leap_hand_outside(leap_model, capsule):
    assert "leap_0000" not in leap_model.meta["hands"]
    assert _support_warnings(leap_model, "leap_0000", capsule) == []
    assert leap_model.support("leap_0000")[1] == 0
    found = _support_warnings(leap_model, "leap_hand_right", capsule)
    assert len(found) == 1 and "66 hands, leap_0233 ... leap_3333" in found[0] and "training spreads" in found[0]


@pytest.mark.parametrize("beyond, warns", [(SUPPORT_MARGIN - 0.1, False), (SUPPORT_MARGIN + 0.1, True)])
def test_the_margin_is_measured_in_training_spreads_beyond_the_largest_training_value(leap_model, capsule, beyond, warns):
    # a LEAP variant whose palm radius (condition entry 0) lies `beyond` spreads past the largest training value
    cond = leap_model.condition
    largest = max(params_vector(leap_model_hand)[0] for leap_model_hand in _training_params(leap_model))
    hand = ExtendedParams.from_vector(_training_params(leap_model)[0].to_vector(), template="leap")
    v = hand.to_vector()
    v[0] = largest + beyond * cond.scale[0]
    hand = ExtendedParams.from_vector(v, template="leap")
    worst, count = leap_model.support(hand)
    assert worst == pytest.approx(beyond, abs=1e-9) and count == int(warns)
    assert bool(_support_warnings(leap_model, hand, capsule)) == warns


def _training_params(model):
    from ohra.learn.grasp.condition import resolve_hand

    return [resolve_hand(h) for h in model.meta["hands"]]


def test_the_cli_names_the_hand_as_the_user_gave_it_on_one_line(tmp_path, capsys):
    from ohra.cli.main import main

    out = tmp_path / "g.npz"
    assert main(["grasp", "sample", "--hand", str(ABILITY), "--object", "builtin:box", "-n", "2", "-o", str(out)]) == 0
    lines = [ln for ln in capsys.readouterr().err.splitlines() if "outside the hands this grasp model trained on" in ln]
    assert len(lines) == 1 and lines[0].startswith(f"ohra: warning: hand '{ABILITY}'")
    assert main(["grasp", "sample", "--hand", "barrett_hand", "--object", "builtin:box", "-n", "2", "-o", str(out)]) == 0
    assert "outside the hands" not in capsys.readouterr().err


def _own_shadow_dataset(root: Path, scale_palm: float = 0.9):
    """The fixture dataset with Shadow replaced by a hand of one's own (longer fingers, smaller palm), as a params
    file would give it: named my_shadow, no registered name."""
    import dataclasses
    import json
    import shutil

    from grasp_fixtures import write_dataset

    from ohra.hands import get_hand

    write_dataset(root, hands=("allegro_hand_left", "shadow_hand_right"))
    shadow = get_hand("shadow_hand_right")
    mine = dataclasses.replace(shadow, finger_lengths=np.asarray(shadow.finger_lengths) * 1.15,
                               palm_radius=shadow.palm_radius * scale_palm)
    man = json.loads((root / "manifest.json").read_text())
    entry = man["hands"].pop("shadow_hand_right")
    entry["params"] = mine.to_dict()
    for sh in entry["shards"].values():
        sh["file"] = sh["file"].replace("shadow_hand_right/", "my_shadow/")
    man["hands"]["my_shadow"] = entry
    shutil.move(root / "shadow_hand_right", root / "my_shadow")
    (root / "manifest.json").write_text(json.dumps(man))
    return mine


def test_vae_conditioned_training_names_a_training_hand_outside_the_vaes_support(tmp_path):
    """`ohra vae encode` warned that the hand's palm radius lies outside the VAE's range; training a VAE-conditioned
    grasp model on the same hand said nothing."""
    from grasp_fixtures import tiny_model_config, tiny_train_config

    from ohra.learn.grasp.train import train_grasp

    _own_shadow_dataset(tmp_path / "d")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        train_grasp(tmp_path / "d", tiny_model_config(), tiny_train_config(steps=1), progress=False)
    said = [str(w.message) for w in caught if issubclass(w.category, OutOfSupportWarning)]
    assert len(said) == 1 and said[0].startswith("training hand 'my_shadow' lies outside the hands the VAE was trained on")
    assert "palm_radius" in said[0]


def test_a_hand_of_your_own_that_the_model_trained_on_is_not_called_unseen(tmp_path, capsule):
    """The training hands were looked up again by name, so a hand from a params file (no registered name) was
    dropped: the model called its own training hand unseen, and a model trained only on such hands never warned
    nor mirrored. Training now records the hands' condition vectors."""
    from grasp_fixtures import tiny_model_config, tiny_train_config

    from ohra.learn.grasp.train import train_grasp

    root = tmp_path / "d"
    mine = _own_shadow_dataset(root)
    model = train_grasp(root, tiny_model_config(condition="params"), tiny_train_config(steps=1), progress=False).model
    for own in (mine, "allegro_hand_left"):  # recorded in float32: within rounding of its own condition
        worst, count = model.support(own)
        assert count == 0 and worst < 1e-6
    assert model.support("shadow_hand_right")[1] > 0  # the registered Shadow is not the hand it trained on
    assert _support_warnings(model, mine, capsule) == []
