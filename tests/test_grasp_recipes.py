"""The committed recipes of the grasp-model studies: what they select, and a clean object split."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from ohra.data.recipe import Recipe

RECIPES = Path(__file__).parents[1] / "recipes"
TRAINING = ("grasp_unified.yaml", "leap_zeroshot.yaml")


def _eval_objects():
    d = yaml.safe_load((RECIPES / "grasp_eval_objects.yaml").read_text())
    return Recipe.from_dict({"hands": ["leap_3333"], "objects": d["objects"]}, RECIPES / "grasp_eval_objects.yaml").resolve_objects()


@pytest.mark.parametrize("recipe", TRAINING)
def test_no_evaluation_object_is_in_a_training_recipe(recipe, objects_dir):
    train = Recipe.load(RECIPES / recipe).resolve_objects()
    test = _eval_objects()
    assert len(test) == 13 and len(train) == 45
    assert not {o.name for o in train} & {o.name for o in test}
    assert not {o.mesh_hash for o in train} & {o.mesh_hash for o in test}  # a renamed copy counts too


def test_the_unified_recipe_has_the_papers_three_hands():
    assert [n for n, _ in Recipe.load(RECIPES / "grasp_unified.yaml").resolve_hands()] == [
        "allegro_hand_left", "barrett_hand", "shadow_hand_right"]


def test_the_zero_shot_recipe_has_the_66_variants_and_the_five_low_sum_ones():
    names = [n for n, _ in Recipe.load(RECIPES / "leap_zeroshot.yaml").resolve_hands()]
    high = [n for n in names if sum(int(c) for c in n[-4:]) >= 8]
    assert len(high) == 66 and len(names) == 71
    assert {"leap_3033", "leap_3303", "leap_3330"} <= set(high)
    assert set(names) - set(high) == {"leap_0303", "leap_0312", "leap_2203", "leap_3030", "leap_3103"}


def test_another_data_seed_keeps_the_object_split():
    r = Recipe.from_dict({"hands": ["leap_3333"], "objects": ["builtin"], "seed": 4, "split": {"test_fraction": 0.34}})
    keys = [f"o{i}" for i in range(9)]
    s1 = r.with_seed(11)
    assert s1.seed == 11 and s1.synth_settings().seed == 11
    assert s1.split_objects(keys)["test"] == r.split_objects(keys)["test"]


def test_no_committed_dataset_holds_an_evaluation_object(objects_dir):
    """The committed training data itself, not only its recipes: no shard's object is an evaluation
    object, by name or by mesh hash."""
    from ohra.data.dataset import read_manifest

    test = _eval_objects()
    names, hashes = {o.name for o in test}, {o.mesh_hash for o in test}
    manifests = sorted((RECIPES.parent / "datasets").glob("*/manifest.json"))
    assert manifests
    for path in manifests:
        for hand, entry in read_manifest(path)["hands"].items():
            for key, shard in entry["shards"].items():
                obj = shard["object"]
                assert obj["name"] not in names and obj["mesh_hash"] not in hashes, f"{path.parent.name}: {hand}/{key}"
