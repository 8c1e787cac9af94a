"""Plausible mistakes at the library API end in an ``ohra`` error naming the argument (and the way out), not a bare
TypeError / AttributeError / NaN from deep inside numpy, torch or PyBullet (a review of the public API found each)."""

from __future__ import annotations

import numpy as np
import pytest

from ohra.canonical.kinematics import HandModel
from ohra.errors import OhraError
from ohra.hands import couplings_of, get_hand
from ohra.objects.model import ObjectModel


@pytest.mark.parametrize("call, message", [
    (lambda: couplings_of("inspire_hand_right"), r"got str \(a hand name: get_couplings\('inspire_hand_right'\)\)"),
    (lambda: __import__("ohra.sim", fromlist=["SimHand"]).SimHand.from_params("barrett_hand"),
     r"got str \(a hand name: SimHand.from_params\(ohra.get_hand\('barrett_hand'\)"),
])
def test_a_hand_name_where_params_are_expected_is_named_with_the_call_that_takes_it(call, message):
    with pytest.raises(OhraError, match=message):
        call()


def test_the_evaluator_checks_its_protocol_and_worker_count():
    from ohra.sim import GraspEvaluator

    with pytest.raises(OhraError, match=r"protocol: expected a Protocol .* got dict"):
        GraspEvaluator("barrett_hand", ObjectModel.builtin("box"), {"friction": 1.0})
    ev = GraspEvaluator("barrett_hand", ObjectModel.builtin("box"))
    with pytest.raises(OhraError, match="workers must be a whole number >= 1, got 'a'"):
        ev.evaluate(np.zeros((1, 31)), workers="a")
    ev.close()


def test_drawing_params_instead_of_a_hand_model_names_the_conversion():
    from ohra import viz

    class Vis:  # no meshcat server needed: the check comes first
        pass

    with pytest.raises(OhraError, match=r"expected a HandModel \(HandModel.from_params\(params\)\), got BaseParams"):
        viz.add_hand(Vis(), get_hand("barrett_hand"), np.zeros(22))
    with pytest.raises(OhraError, match=r"T_world_palm must be a \(4, 4\) transform, got shape \(3, 3\)"):
        viz.add_hand(Vis(), HandModel.from_params(get_hand("barrett_hand")), np.zeros(22), np.eye(3))


def test_the_vae_refuses_a_vector_with_nan_instead_of_returning_a_nan_latent():
    pytest.importorskip("torch")
    from ohra.learn.encoding import LatentError
    from ohra.learn.morph import load_vae

    vae = load_vae()
    v = get_hand("barrett_hand").to_vector()
    v[7] = np.nan
    with pytest.raises(LatentError, match=r"has non-finite values \(NaN or infinity at row 0, entry 7\)"):
        vae.encoding.encode_vectors(v)


@pytest.mark.parametrize("kw, message", [({"epochs": 0}, "epochs must be a whole number >= 1, got 0"),
                                         ({"epochs": -1}, "epochs must be a whole number >= 1"),
                                         ({"lr": float("nan")}, "lr must be a finite number > 0")])
def test_vae_training_settings_that_train_nothing_are_refused(kw, message):
    from ohra.learn.config import TrainConfig

    with pytest.raises(OhraError, match=message):
        TrainConfig(**kw)


def test_a_vae_of_no_size_is_refused():
    pytest.importorskip("torch")
    from ohra.learn.vae import VAEConfig

    with pytest.raises(OhraError, match="latent_dim and hidden sizes must be whole numbers >= 1"):
        VAEConfig(latent_dim=-1)


def test_a_dataset_and_the_hand_list_take_what_they_say():
    from ohra.data.dataset import DatasetError, GraspDataset
    from ohra.hands import list_hands

    with pytest.raises(DatasetError, match="expected a dataset folder path or a list of them, got int"):
        GraspDataset(3)
    with pytest.raises(DatasetError, match="got int in the list"):
        GraspDataset(["datasets/a", 3])
    with pytest.raises(DatasetError, match="an empty list"):
        GraspDataset([])
    with pytest.raises(OhraError, match="include_variants must be True or False, got 'leap'"):
        list_hands("leap")
    assert len(list_hands(True)) == len(list_hands()) + 256


@pytest.mark.parametrize("call, message", [
    (lambda: HandModel.from_params(get_hand("leap_3303")).random_configurations(3, seed=-1),
     "random_configurations: seed must be a whole number >= 0, got -1"),
    (lambda: HandModel.from_params(get_hand("leap_3303")).fingertips(["a"] * 22), "22 joint angles"),
    (lambda: ObjectModel.builtin("box").sample_surface(5, seed=1.5), "sample_surface's seed must be a whole number"),
    (lambda: ObjectModel.builtin("box").sample_surface(2.5), "sample_surface's n: expected a whole number, got 2.5"),
    (lambda: ObjectModel.builtin("box").signed_distance(np.zeros((2, 2))), r"expected \(N, 3\) points \[m\], got shape \(2, 2\)"),
    (lambda: __import__("ohra.objects.model", fromlist=["x"]).farthest_point_sampling(np.zeros((4, 3)), 0), "k must be"),
    (lambda: ObjectModel.builtin("box", density="a"), "density must be a finite number > 0"),
])
def test_seeds_counts_points_and_densities_of_the_wrong_kind_are_named(call, message):
    with pytest.raises(OhraError, match=message):
        call()
