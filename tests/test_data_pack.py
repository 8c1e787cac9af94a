"""Packed datasets (``ohra data pack``): one file per hand, lossless, checked, resumable."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from ohra.data.dataset import GraspDataset
from ohra.data.pack import pack, unpack
from ohra.errors import DatasetError, FolderInUseError
from ohra.hands import get_hand
from ohra.objects.model import ObjectModel
from ohra.synth.pipeline import SynthSettings, synthesize

HANDS = [("leap_2200", get_hand("leap_2200")), ("leap_3030", get_hand("leap_3030"))]
OBJECTS = [ObjectModel.builtin("box"), ObjectModel.procedural("capsule", 2)]
FAST = SynthSettings(grasps_per_object=2, filter=False)  # unfiltered: every pair keeps grasps, in seconds


@pytest.fixture(scope="module")
def built(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("ds")
    synthesize(HANDS, OBJECTS, root, FAST, progress=False)
    return root


@pytest.fixture
def ds(built, tmp_path) -> Path:
    shutil.copytree(built, tmp_path / "ds")
    return tmp_path / "ds"


def _manifest(root: Path) -> dict:
    return json.loads((root / "manifest.json").read_text())


def _shard_bytes(root: Path) -> dict[str, bytes]:
    return {str(f.relative_to(root)): f.read_bytes() for f in sorted(root.rglob("*.npz"))}


def test_packing_keeps_every_array_bit_for_bit_in_one_file_per_hand(ds):
    before = GraspDataset(ds)
    arrays = {p: before.load_shard(*p) for p in before.pairs}
    grasps, post = before.grasps(), GraspDataset(ds, which="post").grasps()
    report = pack(ds)
    assert (report.hands, report.packed, report.folded) == (2, 4, 4)
    assert sorted(f.name.split("-")[0] for f in ds.rglob("*.npz")) == ["pack", "pack"]
    after = GraspDataset(ds)
    assert after.pairs == before.pairs and len(after) == len(before) > 0
    for p, a in arrays.items():
        b = after.load_shard(*p)
        assert list(b) == list(a)
        for k in a:
            assert b[k].dtype == a[k].dtype and b[k].shape == a[k].shape and np.array_equal(b[k], a[k], equal_nan=True), (p, k)
    assert np.array_equal(after.grasps(), grasps) and np.array_equal(GraspDataset(ds, which="post").grasps(), post)


def test_the_report_line_gives_small_sizes_in_kilobytes_not_as_zero_megabytes():
    from ohra.data.pack import PackReport

    line = PackReport("d", 1, 2, 2, 14_200, 9_000).line()
    assert "14.2 kB -> 9.0 kB of shard files" in line
    assert "812 B -> 3.4 MB" in PackReport("d", 1, 2, 2, 812, 3_400_000).line()


def test_unpacking_restores_each_shard_byte_for_byte(ds):
    shards = _shard_bytes(ds)
    pack(ds)
    assert unpack(ds) == 4
    assert _shard_bytes(ds) == shards
    assert all("pack" not in sh for e in _manifest(ds)["hands"].values() for sh in e["shards"].values())


def test_resume_into_a_packed_directory_recomputes_nothing_and_a_damaged_pack_only_its_hand(ds):
    pack(ds)
    synthesize(HANDS, OBJECTS, ds, FAST, resume=True, progress=False)
    assert [f.name[:5] for f in ds.rglob("*.npz")] == ["pack-", "pack-"]  # no loose shard written
    [victim] = (ds / "leap_3030").glob("pack-*.npz")
    victim.write_bytes(victim.read_bytes()[:-10])
    synthesize(HANDS, OBJECTS, ds, FAST, resume=True, progress=False)
    loose = sorted(str(f.relative_to(ds)) for f in ds.rglob("*.npz") if not f.name.startswith("pack-"))
    assert len(loose) == 2 and all(f.startswith("leap_3030/") for f in loose)
    assert len(GraspDataset(ds, hands=["leap_3030"]).grasps()) > 0
    assert pack(ds).folded == 2  # packing again folds them in and drops the damaged pack
    assert len(list(ds.rglob("*.npz"))) == 2


def test_a_damaged_pack_is_an_error_naming_the_file(ds):
    pack(ds)
    [victim] = (ds / "leap_2200").glob("pack-*.npz")
    raw = bytearray(victim.read_bytes())
    raw[len(raw) // 2] ^= 0xFF
    victim.write_bytes(bytes(raw))
    with pytest.raises(DatasetError, match=rf"{victim.name}.*hash"):
        GraspDataset(ds, hands=["leap_2200"]).grasps()


def test_packing_refuses_a_damaged_shard_and_changes_nothing(ds):
    m = _manifest(ds)
    shard = ds / m["hands"]["leap_3030"]["shards"]["box"]["file"]
    shard.write_bytes(shard.read_bytes()[:-1])
    files = _shard_bytes(ds)
    with pytest.raises(DatasetError, match=r"leap_3030/box.*--resume"):
        pack(ds)
    assert _shard_bytes(ds) == files and _manifest(ds) == m


def test_packing_a_folder_a_build_is_writing_is_refused_and_changes_nothing(ds):
    """A build holds the dataset folder's lock (here another process holds it): pack and unpack fail at once."""
    hold = "import sys\nfrom ohra.io import folder_lock\nwith folder_lock(sys.argv[1], 'dataset'):\n    print('held', flush=True); sys.stdin.read()"
    p = subprocess.Popen([sys.executable, "-c", hold, str(ds)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert p.stdout.readline().strip() == "held"
        files, m = _shard_bytes(ds), _manifest(ds)
        for f in (pack, unpack):
            with pytest.raises(FolderInUseError, match=rf"another process \(pid {p.pid}\) is writing this dataset"):
                f(ds)
        assert _shard_bytes(ds) == files and _manifest(ds) == m
    finally:
        p.stdin.close()
        p.wait()
    assert pack(ds).packed == 4  # once the build is done


def test_packing_deletes_only_the_shards_it_folds_in_and_stale_packs_never_other_files(ds):
    """A user's own ``.npz`` in a hand's folder, or in the folder of a hand with no shards, survives packing;
    a pack no entry names any more (a build recomputed every pair of a packed hand) does not."""
    m = _manifest(ds)
    m["hands"]["leap_3030"]["shards"] = {}
    (ds / "manifest.json").write_text(json.dumps(m))
    unlisted = sorted(str(f.relative_to(ds)) for f in (ds / "leap_3030").glob("*.npz"))
    for hand in ("leap_2200", "leap_3030"):
        np.savez(ds / hand / "my_analysis.npz", a=np.arange(3))
    np.savez(ds / "leap_2200" / "pack-0123abcd.npz", a=np.arange(3))
    assert pack(ds).folded == 2
    left = sorted(str(f.relative_to(ds)) for f in ds.rglob("*.npz"))
    [packed] = [f for f in left if f.startswith("leap_2200/pack-")]
    assert left == sorted([packed, "leap_2200/my_analysis.npz", "leap_3030/my_analysis.npz"] + unlisted)


def test_cli_packs_and_reports_sizes_and_a_missing_manifest_is_one_line(ds, tmp_path):
    run = lambda *a: subprocess.run([sys.executable, "-m", "ohra.data", "pack", *a], capture_output=True, text=True)  # noqa: E731
    ok = run(str(ds))
    assert ok.returncode == 0, ok.stderr
    assert "4 pairs of 2 hands packed" in ok.stdout and "kB ->" in ok.stdout  # a tiny folder: not "0.0 MB"
    bad = run(str(tmp_path / "nothing"))
    lines = [ln for ln in bad.stderr.splitlines() if ln.strip()]
    assert bad.returncode == 2 and len(lines) == 1 and "dataset folder not found" in lines[0]


def test_the_studies_cache_key_ignores_packing_but_sees_a_changed_pair(ds):
    """A cached training run is reused on the same grasps in another layout, never on other grasps."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    try:
        from _study_cache import data_fingerprint
    finally:
        sys.path.pop(0)
    before = data_fingerprint([str(ds)])
    pack(ds)
    assert data_fingerprint([str(ds)]) == before
    m = _manifest(ds)
    m["hands"]["leap_2200"]["shards"]["box"]["sha256"] = "0" * 16  # a recomputed pair
    (ds / "manifest.json").write_text(json.dumps(m))
    assert data_fingerprint([str(ds)]) != before


def test_ohra_eval_of_a_pack_file_refuses_it_rather_than_mix_the_objects(ds, capsys):
    from ohra.cli.main import main

    pack(ds)
    (pack_file,) = (ds / "leap_2200").glob("pack-*.npz")
    assert main(["eval", str(pack_file), "--hand", "leap_2200", "--object", "builtin:box"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "is a packed dataset file" in err and "--unpack" in err
