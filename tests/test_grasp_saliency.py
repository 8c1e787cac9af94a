"""Condition saliency (Fig. 8) and wrong-condition sampling (Table 9) of the grasp model."""

from __future__ import annotations

import copy

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from grasp_fixtures import tiny_model_config, tiny_train_config, write_dataset  # noqa: E402

from ohra.canonical.params import ExtendedParams  # noqa: E402
from ohra.hands import get_hand  # noqa: E402
from ohra.learn.grasp.condition import params_vector  # noqa: E402
from ohra.learn.grasp.saliency import FINGERS, condition_saliency, mean_condition_saliency, params_groups, saliency_figure  # noqa: E402
from ohra.learn.grasp.train import train_grasp  # noqa: E402


@pytest.fixture(scope="module")
def params_model(tmp_path_factory):
    data = write_dataset(tmp_path_factory.mktemp("sal"))
    return train_grasp(data, tiny_model_config(condition="params"), tiny_train_config(), progress=False).model


def _ext(name: str) -> ExtendedParams:
    p = get_hand(name)
    return p if isinstance(p, ExtendedParams) else p.to_extended()


@pytest.mark.parametrize("finger", range(5))
def test_groups_label_each_fingers_entries(finger):
    """Changing one finger's segment length and joint limits moves only entries of that finger's group."""
    d = _ext("shadow_hand_right").to_dict()
    d["finger_lengths"][finger][0] += 0.01
    d["joint_uppers"][finger][-1] -= 0.1
    d["joint_origins"][finger][-1][2] += 0.005
    moved = params_vector(ExtendedParams.from_dict(d)) != params_vector(_ext("shadow_hand_right"))
    groups = params_groups()
    assert moved.sum() >= 3 and set(groups[moved]) == {FINGERS[finger]}


def test_a_finger_the_networks_cannot_see_has_zero_saliency(params_model):
    """Zeroing the weights that read the thumb's entries makes its saliency exactly zero, and only its."""
    m = copy.deepcopy(params_model)
    thumb = torch.from_numpy(params_groups() == "thumb")
    off = m.net.cfg.object_dim
    with torch.no_grad():
        for layer in (m.net.denoiser.cond_in, m.net.joints.inp):
            layer.weight[:, off:off + len(thumb)][:, thumb] = 0.0
    r = condition_saliency(m, "leap_3333", "builtin:capsule", n=8, seed=1)
    assert r["groups"]["thumb"] == 0.0
    assert all(r["groups"][g] > 0 for g in ("palm", "index", "middle", "little"))
    full = condition_saliency(params_model, "leap_3333", "builtin:capsule", n=8, seed=1)
    assert full["groups"]["thumb"] > 0
    again = condition_saliency(params_model, "leap_3333", "builtin:capsule", n=8, seed=1)
    assert np.array_equal(full["entries"], again["entries"])


def test_saliency_over_objects_is_the_mean_of_each_objects(params_model):
    objs = ["builtin:capsule", "builtin:box"]
    each = [condition_saliency(params_model, "leap_3033", o, n=4, seed=2) for o in objs]
    mean = mean_condition_saliency(params_model, "leap_3033", objs, n=4, seed=2)
    assert np.allclose(mean["entries"], (each[0]["entries"] + each[1]["entries"]) / 2)
    assert mean["groups"]["index"] == pytest.approx((each[0]["groups"]["index"] + each[1]["groups"]["index"]) / 2)
    assert mean["n"] == 8 and mean["objects"] == 2


def test_saliency_figure_is_written(params_model, tmp_path):
    r = {h: condition_saliency(params_model, h, "builtin:capsule", n=4) for h in ("leap_3333", "leap_3033")}
    saliency_figure(r, str(tmp_path / "fig8.png"))
    assert (tmp_path / "fig8.png").stat().st_size > 1000


def test_wrong_condition_changes_the_grasps_not_the_limits(params_model):
    """Table 9: the model is told another hand; the joints still respect the true hand's limits."""
    hand = get_hand("leap_3033")
    right = params_model.sample("leap_3033", "builtin:capsule", 16, seed=3)
    wrong = params_model.sample("leap_3033", "builtin:capsule", 16, seed=3, condition_hand="leap_3333")
    same = params_model.sample("leap_3033", "builtin:capsule", 16, seed=3, condition_hand="leap_3033")
    assert np.array_equal(right, same) and not np.allclose(right, wrong)
    q = wrong[:, 9:]
    assert np.all(q >= np.asarray(hand.joint_lowers) - 1e-12) and np.all(q <= np.asarray(hand.joint_uppers) + 1e-12)


def test_evaluation_with_a_wrong_condition_runs_the_true_hand(params_model):
    """Table 9 through the evaluator: the wrong condition's grasps are those ``sample`` gives with the
    same pair seed, they run on the true hand, and the report names the condition it was told."""
    from ohra.learn.grasp.evaluate import evaluate_model, pair_seed
    from ohra.objects import ObjectModel

    obj = ObjectModel.builtin("capsule")
    rep = evaluate_model(params_model, ["leap_3033"], [obj], n=2, allow_seen=True, condition_hand="leap_3333")
    expect = params_model.sample("leap_3033", obj, 2, seed=pair_seed(0, "leap_3033", obj.mesh_hash), condition_hand="leap_3333")
    assert np.array_equal(rep.pairs[0].grasps, expect)
    assert rep.pairs[0].hand == "leap_3033" and rep.meta["condition_hand"] == "leap_3333"
    true = evaluate_model(params_model, ["leap_3033"], [obj], n=2, allow_seen=True)
    assert true.meta["condition_hand"] is None and not np.allclose(true.pairs[0].grasps, expect)
