"""The manifest file: plain JSON, one shard entry per line, each entry encoded once per run."""

from __future__ import annotations

import difflib
import json

import pytest

from ohra.data.dataset import read_manifest
from ohra.errors import DatasetError
from ohra.data.manifest import ManifestWriter, manifest_json


def _shard(i: int, n: int = 2) -> dict:
    return {"file": f"leap_3333/box-{i}-0123abcd.npz", "object": {"name": f"box-{i}", "extents_m": [0.1, 0.05, 0.04]},
            "n_grasps": n, "timing": {"cpu_s": 1.5 + i}, "sha256": f"{i:016x}"}


def _manifest(pairs: int) -> dict:
    return {"ohra_version": "0.1.0", "format": "ohra-grasps/2", "settings": {"seed": 0, "nlp": {"mu": 0.5}},
            "hands": {"leap_3333": {"params": {"palm_radius": 0.057}, "params_hash": "ab",
                                    "shards": {f"box-{i}": _shard(i) for i in range(pairs)}},
                      "leap_0303": {"params": {"palm_radius": 0.057}, "params_hash": "cd", "shards": {}}},
            "split": {"train": ["box-0"], "test": []}}


def test_the_manifest_reads_back_equal_with_one_shard_entry_per_line(tmp_path):
    man = _manifest(3)
    ManifestWriter(tmp_path / "manifest.json").write(man)
    assert read_manifest(tmp_path / "manifest.json") == man
    lines = (tmp_path / "manifest.json").read_text().splitlines()
    for i in range(3):  # a shard line names its object, described once in the objects table
        [line] = [ln for ln in lines if ln.startswith(f'    "box-{i}": {{')]
        assert json.loads("{" + line.rstrip(",") + "}")[f"box-{i}"] == {**_shard(i), "object": f"box-{i}"}


def test_a_new_pair_changes_at_most_two_lines_of_the_file():
    man = _manifest(5)
    before = manifest_json(man).splitlines()
    man["hands"]["leap_3333"]["shards"]["box-5"] = _shard(5)
    after = manifest_json(man).splitlines()
    changed = [d for d in difflib.ndiff(before, after) if d[:2] in ("- ", "+ ")]
    # the new entry and its object, each with a comma now on the line before
    assert len([d for d in changed if d.startswith("+ ")]) == 4
    assert len([d for d in changed if d.startswith("- ")]) == 2


def test_the_writer_encodes_a_replaced_entry_again(tmp_path):
    """A pair recomputed in the same run (a new entry under the same key) must not be written stale."""
    man = _manifest(2)
    writer = ManifestWriter(tmp_path / "manifest.json")
    writer.write(man)
    man["hands"]["leap_3333"]["shards"]["box-1"] = _shard(1, n=7)
    writer.write(man)
    assert read_manifest(tmp_path / "manifest.json")["hands"]["leap_3333"]["shards"]["box-1"]["n_grasps"] == 7


def test_an_empty_manifest_and_odd_values_are_valid_json():
    man = {"format": "ohra-grasps/2", "hands": {}, "path": __import__("pathlib").Path("x"), "none": None}
    assert json.loads(manifest_json(man)) == {**man, "path": "x"}


def test_each_object_description_is_stored_once_and_read_back_in_every_shard(tmp_path):
    man = _manifest(3)
    man["hands"]["leap_0303"]["shards"] = {f"box-{i}": _shard(i) for i in range(3)}  # the same objects
    ManifestWriter(tmp_path / "manifest.json").write(man)
    text = (tmp_path / "manifest.json").read_text()
    assert text.count('"extents_m"') == 3  # once per object, not once per (hand, object)
    back = read_manifest(tmp_path / "manifest.json")
    assert back == man and "objects" not in back


def test_a_shard_whose_object_differs_from_its_keys_keeps_its_own_description(tmp_path):
    man = _manifest(2)
    man["hands"]["leap_0303"]["shards"] = {"box-1": {**_shard(1), "object": {"name": "box-1", "mesh_hash": "other"}}}
    ManifestWriter(tmp_path / "manifest.json").write(man)
    assert read_manifest(tmp_path / "manifest.json") == man


def test_a_shard_naming_an_object_the_table_lacks_is_an_error_naming_it(tmp_path):
    man = _manifest(1)
    text = manifest_json(man).replace('"objects": {', '"objects": {"unused": {},', 1).replace('"object": "box-0"', '"object": "box-9"')
    (tmp_path / "manifest.json").write_text(text)
    with pytest.raises(DatasetError, match=r"leap_3333/box-0 names object 'box-9'"):
        read_manifest(tmp_path / "manifest.json")


def test_replacing_the_shard_that_describes_an_object_keeps_the_other_hands_descriptions(tmp_path):
    """The table takes each key's description from its first shard; when that shard is recomputed on
    a changed object, the other hands' shards (cached as references) must keep their own description."""
    man = _manifest(1)
    man["hands"]["leap_0303"]["shards"] = {"box-0": _shard(0)}
    writer = ManifestWriter(tmp_path / "manifest.json")
    writer.write(man)
    man["hands"]["leap_3333"]["shards"]["box-0"] = {**_shard(0), "object": {"name": "box-0", "mesh_hash": "changed"}}
    writer.write(man)
    back = read_manifest(tmp_path / "manifest.json")
    assert back["hands"]["leap_0303"]["shards"]["box-0"]["object"] == _shard(0)["object"]
    assert back["hands"]["leap_3333"]["shards"]["box-0"]["object"]["mesh_hash"] == "changed"


def test_merged_datasets_must_be_read_alike(tmp_path):
    """Merging a post-test reading into a pre-test one read every shard as pre-test, silently."""
    import pytest

    from ohra.data.dataset import GraspDataset
    from ohra.errors import DatasetError
    from grasp_fixtures import write_dataset

    root = write_dataset(tmp_path / "d", hands=("barrett_hand", "shadow_hand_right"), objects=("box",), per_pair=3)
    a, b = GraspDataset(root, hands=["barrett_hand"]), GraspDataset(root, hands=["shadow_hand_right"])
    both = GraspDataset.merge(a, b)
    assert both.which == "pre" and len(both.grasps()) == 6
    with pytest.raises(DatasetError, match=r"different which \(\['pre', 'post'\]\)"):
        GraspDataset.merge(a, GraspDataset(root, hands=["shadow_hand_right"], which="post"))
    with pytest.raises(DatasetError, match="different max_per_pair"):
        GraspDataset.merge(a, GraspDataset(root, hands=["shadow_hand_right"], max_per_pair=1))
    with pytest.raises(DatasetError, match="at least one"):
        GraspDataset.merge()
