"""The manifest file: plain JSON, one shard entry per line, each entry encoded once per run."""

from __future__ import annotations

import difflib
import json

from ohra.data.dataset import read_manifest
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
    for i in range(3):
        [line] = [ln for ln in lines if f'"box-{i}": {{' in ln]
        assert json.loads("{" + line.rstrip(",") + "}")[f"box-{i}"] == _shard(i)


def test_a_new_pair_changes_at_most_two_lines_of_the_file():
    man = _manifest(5)
    before = manifest_json(man).splitlines()
    man["hands"]["leap_3333"]["shards"]["box-5"] = _shard(5)
    after = manifest_json(man).splitlines()
    changed = [d for d in difflib.ndiff(before, after) if d[:2] in ("- ", "+ ")]
    assert len([d for d in changed if d.startswith("+ ")]) == 2  # the new entry, and a comma on the one before
    assert len([d for d in changed if d.startswith("- ")]) == 1


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
