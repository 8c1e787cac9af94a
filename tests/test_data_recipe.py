"""Dataset recipes: parsing, hand and object selection, split, build, resume and the info table."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from ohra.data.build import build, format_summary, summary
from ohra.data.dataset import GraspDataset
from ohra.data.recipe import Recipe, RecipeError
from ohra.errors import DatasetError, HandNotFoundError, ObjectError

TINY = """
name: tiny
seed: 3
hands: [leap_2200]
objects:
  - builtin:box
  - {procedural: box, count: 2, seed: 5}
grasps_per_pair: 1
split: {test: [box-6]}
filter: false
"""


def _data(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "ohra.data", *args], capture_output=True, text=True, timeout=600)


def test_the_digit_sum_rule_selects_leap_variants_of_that_complexity():
    r = Recipe.from_dict({"hands": [{"pattern": "leap_*", "digit_sum": [11, 12]}], "objects": ["builtin"]})
    names = [n for n, _ in r.resolve_hands()]
    assert names == ["leap_2333", "leap_3233", "leap_3323", "leap_3332", "leap_3333"]
    r = Recipe.from_dict({"hands": ["leap_3333", "leap_3*33", "leap_3333"], "objects": ["builtin"]})
    assert [n for n, _ in r.resolve_hands()] == ["leap_3333", "leap_3033", "leap_3133", "leap_3233"]


def test_a_hand_file_is_found_beside_the_recipe_like_an_object_file(tmp_path, monkeypatch):
    import json

    from ohra.hands import get_hand

    folder = tmp_path / "recipes"
    folder.mkdir()
    (folder / "my_hand.json").write_text(json.dumps(get_hand("allegro_hand_left").to_dict()))
    (folder / "r.yaml").write_text("hands: [my_hand.json, {params: my_hand.json}]\nobjects: [builtin:box]\n")
    monkeypatch.chdir(tmp_path)  # not the recipe's folder
    hands = Recipe.load(folder / "r.yaml").resolve_hands()
    assert [n for n, _ in hands] == ["my_hand"]  # one hand, named by the file's stem either way
    assert hands[0][1].to_vector().tolist() == get_hand("allegro_hand_left").to_vector().tolist()


@pytest.mark.parametrize("recipe, message", [
    ({"hands": ["leap_3333"], "objects": ["builtin"], "grasp_per_pair": 3}, "unknown key.*grasp_per_pair"),
    ({"hands": [], "objects": ["builtin"]}, "'hands' must be a non-empty list"),
    ({"hands": [{"pattern": "nohand_*"}], "objects": ["builtin"]}, "matches no hand"),
    ({"hands": ["leap_3333"], "objects": [{"glob": "/nonexistent/*.obj"}]}, "matches nothing"),
    ({"hands": ["leap_3333"], "objects": ["builtin"], "cap": 0}, "'cap' must be an integer >= 1"),
    ({"hands": ["leap_3333"], "objects": ["builtin"], "protocol": {"preset": "reference", "frction": 1}},
     r"r.yaml: protocol: unknown key\(s\) \['frction'\]; known: dt, "),
    # wrong types inside protocol and robustness (stop 49's sweep: Python's own messages, no key named)
    ({"hands": ["leap_3333"], "objects": ["builtin"], "protocol": {"friction": "high"}}, "protocol.friction must be a finite number, got 'high'"),
    ({"hands": ["leap_3333"], "objects": ["builtin"], "protocol": {"preset": "fast"}}, "protocol.preset: unknown protocol preset 'fast'"),
    ({"hands": ["leap_3333"], "objects": ["builtin"], "robustness": {"trials": "two"}}, "robustness.trials must be a whole number, got 'two'"),
    ({"hands": ["leap_3333"], "objects": ["builtin"], "robustness": {"trails": 2}}, r"robustness: unknown key\(s\) \['trails'\]"),
    ({"hands": ["leap_3333"], "objects": [{"procedural": "box", "count": -1}]}, r"objects\[0\]: 'count' must be an integer >= 1"),
    ({"hands": ["leap_3333"], "objects": [{"procedural": "box", "seed": -5}]}, r"objects\[0\]: 'seed' must be an integer >= 0"),
    ({"hands": ["leap_3333"], "objects": ["builtin"], "name": "../../escape"}, "'name' is a folder name under out/"),
    # misspelt or mistyped keys inside entries and the split (stop 47's new-user sweep: silently ignored before)
    ({"hands": [{"pattern": "leap_*", "digitsum": 12}], "objects": ["builtin"]},
     r"hands\[0\]: unknown key\(s\) digitsum for a 'pattern' entry; known: pattern, digit_sum"),
    ({"hands": [{"pattern": "leap_*", "digit_sum": [12, 10]}], "objects": ["builtin"]}, "min > max"),
    ({"hands": [{"spec": "h.yaml", "from": "base"}], "objects": ["builtin"]}, r"unknown key\(s\) from"),
    ({"hands": [{"spec": "h.yaml", "form": "basic"}], "objects": ["builtin"]}, "'form' must be base or extended"),
    ({"hands": [{"params": "a.json", "pattern": "leap_*"}], "objects": ["builtin"]}, "exactly one of pattern, params, spec"),
    ({"hands": ["leap_3333"], "objects": [{"procedural": "box", "cuont": 3}]}, r"objects\[0\]: unknown key\(s\) cuont"),
    ({"hands": ["leap_3333"], "objects": [{"path": "mug.obj", "scael": 0.5}]}, r"unknown key\(s\) scael"),
    ({"hands": ["leap_3333"], "objects": [{"path": "mug.obj", "scale": 0}]}, "'scale' must be a number > 0"),
    ({"hands": ["leap_3333"], "objects": [{"path": "mug.obj", "body": "convex"}]}, "'body' must be one of auto, hull, provided, vhacd"),
    ({"hands": ["leap_3333"], "objects": ["builtin"], "filter": "no"}, "'filter' must be true or false"),
    ({"hands": ["leap_3333"], "objects": ["builtin"], "cap": True}, "'cap' must be an integer >= 1"),
    ({"hands": ["leap_3333"], "objects": ["builtin"], "split": {"test_fraction": "half"}}, "split.test_fraction must be a number"),
    ({"hands": ["leap_3333"], "objects": ["builtin"], "split": {"test_fraction": 1.0}}, r"split.test_fraction .* \[0, 1\)"),
    ({"hands": ["leap_3333"], "objects": ["builtin"], "split": {"test_fraction": 0.5, "seed": "abc"}}, "split.seed must be"),
    ({"hands": ["leap_3333"], "objects": ["builtin"], "split": ["box"]}, "'split' is a mapping"),
    ({"hands": ["leap_3333"], "objects": ["builtin"], "split": {"test": [1, 2]}}, "split.test must be an object name"),
    # stop 57's recipe sweep: a traceback, a silent default, and a message blaming the pattern
    ({"hands": ["leap_3333"], "objects": ["builtin"], "robustness": 2}, "'robustness' is a mapping of RobustnessSettings"),
    ({"hands": ["leap_3333"], "objects": ["builtin"], "robustness": False}, r"\{trials: 0\}: no robustness trials\), got False"),
    ({"hands": [{"pattern": "leap_*", "digit_sum": 99}], "objects": ["builtin"]}, r"digit sum lies in 0..12"),
    ({"hands": [{"pattern": "leap_*", "digit_sum": [-1, 4]}], "objects": ["builtin"]}, r"digit sum lies in 0..12"),
    ({"hands": [{"pattern": "shadow*", "digit_sum": 11}], "objects": ["builtin"]}, "applies to LEAP variants only"),
])
def test_bad_recipes_name_the_problem(recipe, message):
    with pytest.raises(RecipeError, match=message):
        r = Recipe.from_dict(recipe, "r.yaml")
        r.resolve_hands(), r.resolve_objects(), r.synth_settings()


@pytest.mark.parametrize("recipe,error,message", [
    ({"hands": ["leap_3333", "allegro_hand_lft"], "objects": ["builtin:box"]}, HandNotFoundError,
     r"^r.yaml: hands\[1\]: unknown hand 'allegro_hand_lft'"),
    ({"hands": ["leap_3333"], "objects": ["builtin:box", "no_such_mug.obj"]}, ObjectError,
     r"^r.yaml: objects\[1\]: object file or folder not found: .*no_such_mug.obj"),
    ({"hands": ["leap_3333"], "objects": [{"procedural": "blob"}]}, ObjectError, r"^r.yaml: objects\[0\]: unknown procedural family 'blob'"),
])
def test_errors_from_a_recipe_entry_name_the_entry_and_keep_their_type(recipe, error, message):
    """An unknown hand or a missing mesh is raised by the registry or the object loader; the recipe line it came from
    is put in front, and the error's type is kept so a caller catching HandNotFoundError still does."""
    r = Recipe.from_dict(recipe, "r.yaml")
    with pytest.raises(error, match=message):
        r.resolve_hands(), r.resolve_objects()


def test_the_seeded_split_is_stable_and_disjoint():
    r = Recipe.from_dict({"hands": ["leap_3333"], "objects": ["builtin"], "split": {"test_fraction": 0.34, "seed": 1}})
    keys = [f"o{i}" for i in range(9)]
    a, b = r.split_objects(keys), r.split_objects(keys)
    assert a == b and len(a["test"]) == 3 and set(a["train"]) | set(a["test"]) == set(keys) and not set(a["train"]) & set(a["test"])


def test_a_recipe_builds_resumes_and_summarises(tmp_path):
    path = tmp_path / "tiny.yaml"
    path.write_text(TINY)
    man = build(path, tmp_path / "ds", progress=False)
    assert man["recipe"]["name"] == "tiny" and man["split"]["test"] == ["box-6"] and man["split"]["train"] == ["box", "box-5"]
    shards = man["hands"]["leap_2200"]["shards"]
    assert set(shards) == {"box", "box-5", "box-6"} and all(s["n_candidates"] == 1 for s in shards.values())
    assert man["core_hours"] > 0
    before = {k: s["sha256"] for k, s in shards.items()}
    again = build(path, tmp_path / "ds", resume=True, progress=False)
    assert {k: s["sha256"] for k, s in again["hands"]["leap_2200"]["shards"].items()} == before
    assert again["hands"]["leap_2200"]["shards"]["box"]["timing"] == shards["box"]["timing"]  # kept, not recomputed
    s = summary(tmp_path / "ds")
    assert s["total"]["pairs"] == 3 and s["split"] == {"train": 2, "test": 1}
    assert "leap_2200" in format_summary(s) and "incomplete" not in format_summary(s)
    # an interrupted build (a pair's shard not yet written) said nothing of it: it looked like a small finished one
    import json

    m = json.loads((tmp_path / "ds" / "manifest.json").read_text())
    del m["hands"]["leap_2200"]["shards"]["box-5"]
    cut = tmp_path / "cut"
    cut.mkdir()
    (cut / "manifest.json").write_text(json.dumps(m))
    assert "incomplete: leap_2200 2 of 3 objects (the same build with --resume finishes it)" in format_summary(summary(cut))
    assert len(GraspDataset(tmp_path / "ds", split="test").pairs) == 1
    assert len(GraspDataset(tmp_path / "ds", split="train").pairs) == 2
    train = GraspDataset(tmp_path / "ds", split="train")
    assert repr(train).endswith(f": 1 hands, 2 pairs, {len(train.grasps())} grasps, which='pre')")
    proc = _data("info", str(tmp_path / "ds"))
    assert proc.returncode == 0 and "leap_2200" in proc.stdout and "1 test" in proc.stdout, proc.stderr


@pytest.mark.e2e  # ~8 s of CLI subprocesses: moved out of the default suite (stop 56) to keep it near 5 min
def test_data_commands_report_bad_input_in_one_line(tmp_path):
    (tmp_path / "binary.yaml").write_bytes(b"\xff\xfe\x00PK")
    with pytest.raises(RecipeError, match="not a text file"):
        Recipe.load(tmp_path / "binary.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("hands: [leap_3333]\nobjects: [builtin]\ncolour: red\n")
    for args, msg in [(["build", str(bad)], "unknown key(s) colour"), (["info", str(tmp_path)], "no manifest.json"),
                      (["build", str(tmp_path / "none.yaml")], "recipe not found"),
                      (["build", str(tmp_path)], "is a folder; give the recipe's YAML file")]:
        proc = _data(*args)
        lines = [l for l in proc.stderr.splitlines() if l.strip()]
        assert proc.returncode == 2 and len(lines) == 1 and msg in lines[0], proc.stderr


def test_the_example_recipe_resolves(objects_dir):
    from pathlib import Path

    r = Recipe.load(Path(__file__).parents[1] / "recipes" / "leap_small.yaml")
    assert len(r.resolve_hands()) == 5
    assert len(r.resolve_objects()) == 21


def test_a_build_can_top_up_some_hands_and_resume_completes_the_rest(tmp_path):
    path = tmp_path / "two.yaml"
    path.write_text(TINY.replace("hands: [leap_2200]", "hands: [leap_2200, leap_0202]"))
    man = build(path, tmp_path / "ds", progress=False, hands=["leap_0202"])
    assert list(man["hands"]) == ["leap_0202"] and len(man["hands"]["leap_0202"]["shards"]) == 3
    first = {k: s["sha256"] for k, s in man["hands"]["leap_0202"]["shards"].items()}
    full = build(path, tmp_path / "ds", progress=False, resume=True)
    assert sorted(full["hands"]) == ["leap_0202", "leap_2200"] and len(full["hands"]["leap_2200"]["shards"]) == 3
    assert {k: s["sha256"] for k, s in full["hands"]["leap_0202"]["shards"].items()} == first  # kept, not rebuilt
    with pytest.raises(RecipeError, match="leap_3333 not in the recipe.*leap_2200, leap_0202"):
        build(path, tmp_path / "ds2", progress=False, hands=["leap_3333"])


def _manifest(path, shards: dict, split: dict) -> None:
    import json

    path.mkdir()
    hands = {h: {"shards": {k: {"n_candidates": 4, "n_solved": 3, "n_sim_passed": 2, "n_grasps": n,
                                "timing": {"total_s": 36.0, "cpu_s": 18.0}} for k, n in per.items()}}
             for h, per in shards.items()}
    (path / "manifest.json").write_text(json.dumps({"format": "ohra-grasps/2", "hands": hands, "split": split}))


def test_info_over_several_folders_adds_up_per_hand(tmp_path):
    from ohra.data.build import combined_summary

    _manifest(tmp_path / "s0", {"a": {"box": 2, "can": 1}, "b": {"box": 5}}, {"train": ["box", "can"], "test": []})
    _manifest(tmp_path / "s1", {"a": {"box": 3}}, {"train": ["box", "mug"], "test": ["cup"]})
    s = combined_summary([tmp_path / "s0", tmp_path / "s1"])
    rows = {r["hand"]: r for r in s["rows"]}
    assert rows["a"]["grasps"] == 6 and rows["a"]["pairs"] == 3 and rows["b"]["grasps"] == 5
    assert s["total"]["grasps"] == 11 and abs(s["cpu_hours"] - 4 * 18.0 / 3600) < 1e-12
    assert s["split"] == {"train": 3, "test": 1}  # distinct object keys, not a sum
    proc = _data("info", str(tmp_path / "s0"), str(tmp_path / "s1"))
    assert proc.returncode == 0, proc.stderr
    total_table = proc.stdout.split("2 folders")[1]
    assert [ln.split()[5] for ln in total_table.splitlines() if ln.startswith(("a ", "b ", "total"))] == ["6", "5", "11"]


def test_dataset_arguments_a_new_user_gets_wrong_are_named_or_read_as_meant(tmp_path, capsys):
    """A lone name is one hand / object; a folder given twice counts once; a negative cap is refused; a
    manifest file in place of its folder is named."""
    from ohra.cli.data import main as data_main

    path = tmp_path / "tiny.yaml"
    path.write_text(TINY)
    build(path, tmp_path / "ds", progress=False)
    ds = tmp_path / "ds"
    one = GraspDataset(ds)
    assert GraspDataset(ds, hands="leap_2200").pairs == one.pairs
    assert GraspDataset(ds, objects="box").pairs == [("leap_2200", "box")]  # the object 'box', not every name holding it
    assert len(GraspDataset([ds, tmp_path / "." / "ds"]).grasps()) == len(one.grasps())
    for bad in (-1, 2.5, True):
        with pytest.raises(DatasetError, match=r"max_per_pair must be a whole number >= 0 \(0 or None: no cap\)"):
            GraspDataset(ds, max_per_pair=bad)
    assert len(GraspDataset(ds, max_per_pair=0).grasps()) == len(one.grasps())  # 0 is no cap, as in training
    with pytest.raises(DatasetError, match="manifest.json is a file; give the dataset's folder"):
        GraspDataset(ds / "manifest.json")
    capsys.readouterr()
    assert data_main(["info", str(ds), str(tmp_path / "." / "ds") + "/", "--json"]) == 0
    out = capsys.readouterr()
    assert json.loads(out.out)["total"]["pairs"] == 3 and "given twice, counted once" in out.err


def test_a_recipe_name_may_be_a_number_or_empty():
    assert Recipe.from_dict({"hands": ["leap_3333"], "objects": ["builtin"], "name": 2024}, "r.yaml").name == "2024"
    assert Recipe.from_dict({"hands": ["leap_3333"], "objects": ["builtin"], "name": None}, "r.yaml").name == "r"


def test_a_split_names_its_test_objects_from_the_recipe_and_leaves_some_to_train_on():
    r = Recipe.from_dict({"hands": ["leap_3333"], "objects": ["builtin"], "split": {"test": "box"}})
    assert r.split_objects(["box", "sphere"])["test"] == ["box"]  # one name, not its letters
    with pytest.raises(RecipeError, match="unknown object.*thing; the recipe's objects are thing-2c96, box"):
        Recipe.from_dict({"hands": ["leap_3333"], "objects": ["builtin"], "split": {"test": ["thing"]}}).split_objects(
            ["thing-2c96", "box"])
    with pytest.raises(RecipeError, match="leaves no training object"):
        Recipe.from_dict({"hands": ["leap_3333"], "objects": ["builtin"], "split": {"test": ["a", "b"]}}).split_objects(["a", "b"])
    with pytest.raises(RecipeError, match="leaves no training object"):  # 0.25 of one object rounds up to it
        Recipe.from_dict({"hands": ["leap_3333"], "objects": ["builtin"], "split": {"test_fraction": 0.25}}).split_objects(["a"])
    assert Recipe.from_dict({"hands": ["leap_3333"], "objects": ["builtin"]}).split_objects(["a"])["train"] == ["a"]


def test_two_different_hands_under_one_name_are_refused_and_the_same_hand_twice_counts_once(tmp_path):
    """Two files called grip.json in different folders (a dataset keys hands by name): the second was dropped."""
    import dataclasses

    from ohra.hands import get_hand

    p = get_hand("allegro_hand_left")
    for sub, params in (("h1", p), ("h2", dataclasses.replace(p, palm_radius=p.palm_radius * 1.2))):
        (tmp_path / sub).mkdir()
        (tmp_path / sub / "grip.json").write_text(json.dumps(params.to_dict()))
    (tmp_path / "h3").mkdir()
    (tmp_path / "h3" / "grip.json").write_text(json.dumps(p.to_dict()))
    with pytest.raises(RecipeError, match=r"hands\[0\] and hands\[1\] are two different hands named 'grip'"):
        Recipe.from_dict({"hands": [str(tmp_path / "h1/grip.json"), str(tmp_path / "h2/grip.json")],
                          "objects": ["builtin"]}).resolve_hands()
    same = Recipe.from_dict({"hands": [str(tmp_path / "h1/grip.json"), str(tmp_path / "h3/grip.json")],
                             "objects": ["builtin"]}).resolve_hands()
    assert [n for n, _ in same] == ["grip"]
    named = Recipe.from_dict({"hands": [str(tmp_path / "h1/grip.json"), {"params": str(tmp_path / "h2/grip.json"), "name": "grip_big"}],
                              "objects": ["builtin"]}).resolve_hands()
    assert [n for n, _ in named] == ["grip", "grip_big"] and named[1][1].palm_radius == pytest.approx(p.palm_radius * 1.2)


def test_both_forms_of_one_spec_are_two_hands_when_one_is_given_a_name(hands_dir):
    """The base and extended forms of one spec were refused as two hands under the spec's name; `name:` tells them apart."""
    from ohra.canonical.params import BaseParams, ExtendedParams
    from ohra.hands.registry import spec_path

    spec = str(spec_path("barrett_hand"))
    both = [{"spec": spec, "form": "base"}, {"spec": spec}]
    with pytest.raises(RecipeError, match=r"hands\[0\] and hands\[1\] are two different hands named 'barrett_hand'.*"
                                          r"name: barrett_hand_2"):
        Recipe.from_dict({"hands": both, "objects": ["builtin"]}).resolve_hands()
    both[1]["name"] = "barrett_ext"
    hands = Recipe.from_dict({"hands": both, "objects": ["builtin"]}).resolve_hands()
    assert [n for n, _ in hands] == ["barrett_hand", "barrett_ext"]
    assert isinstance(hands[0][1], BaseParams) and isinstance(hands[1][1], ExtendedParams)
    for bad in ("", "a/b", 3, "..", ".hidden", "manifest.json", "-x", "a b"):
        with pytest.raises(RecipeError, match=r"hands\[0\]: 'name' is the hand's folder name"):
            Recipe.from_dict({"hands": [{"spec": spec, "name": bad}], "objects": ["builtin"]})


def test_a_yaml_syntax_error_names_its_line(tmp_path):
    path = tmp_path / "r.yaml"
    path.write_text("hands: [leap_3333]\nobjects: [builtin\ncap: 2\n")
    with pytest.raises(RecipeError, match="not valid YAML at line 3"):
        Recipe.load(path)


def test_a_key_given_twice_in_a_recipe_file_is_named(tmp_path):
    """PyYAML keeps the last of two equal keys silently: `grasps_per_pair: 1` then `: 2` built with 2."""
    f = tmp_path / "r.yaml"
    f.write_text("hands: [leap_3333]\nobjects: [builtin:sphere]\ngrasps_per_pair: 1\ngrasps_per_pair: 2\n")
    with pytest.raises(RecipeError, match=r"r.yaml: duplicate key 'grasps_per_pair' \(line 4; first on line 3\)"):
        Recipe.load(f)
    f.write_text("hands: [{pattern: 'leap_*', digit_sum: 11}]\nobjects: [builtin:sphere]\n")  # nested mappings still load
    assert Recipe.load(f).hands == [{"pattern": "leap_*", "digit_sum": 11}]


def test_info_names_recipe_hands_with_no_pairs_yet(tmp_path):
    """A build of some hands (--hands) or one interrupted before it reached a hand said nothing of the others: only
    hands with pairs were compared with the plan."""
    path = tmp_path / "two.yaml"
    path.write_text(TINY.replace("hands: [leap_2200]", "hands: [leap_2200, leap_2020]"))
    build(path, tmp_path / "ds", progress=False, hands=["leap_2200"])
    text = format_summary(summary(tmp_path / "ds"))
    assert "incomplete: leap_2020 0 of 3 objects" in text and "leap_2200 " in text
    build(path, tmp_path / "ds", progress=False, resume=True)
    assert "incomplete" not in format_summary(summary(tmp_path / "ds"))


def test_a_file_hand_under_a_registered_name_must_be_that_hand(tmp_path):
    """hands2/shadow_hand_right.json holding other parameters built a dataset hand called shadow_hand_right, which
    every later use of the name read as the registered Shadow hand."""
    import dataclasses

    from ohra.hands import get_hand

    shadow = get_hand("shadow_hand_right")
    (tmp_path / "same").mkdir()
    (tmp_path / "same" / "shadow_hand_right.json").write_text(shadow.to_json())
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "shadow_hand_right.json").write_text(dataclasses.replace(shadow, palm_radius=shadow.palm_radius * 0.9).to_json())
    ok = Recipe.from_dict({"hands": [str(tmp_path / "same" / "shadow_hand_right.json")], "objects": ["builtin"]}, "r.yaml")
    assert [n for n, _ in ok.resolve_hands()] == ["shadow_hand_right"]
    mine = str(tmp_path / "mine" / "shadow_hand_right.json")
    with pytest.raises(RecipeError, match=r"r.yaml: hands\[0\]: the hand is named 'shadow_hand_right', a registered hand, but "
                                          r"holds other parameters; give it its own name \(name: my_shadow_hand_right\)"):
        Recipe.from_dict({"hands": [mine], "objects": ["builtin"]}, "r.yaml").resolve_hands()
    named = Recipe.from_dict({"hands": [{"params": mine, "name": "my_shadow"}], "objects": ["builtin"]}, "r.yaml")
    assert [n for n, _ in named.resolve_hands()] == ["my_shadow"]
