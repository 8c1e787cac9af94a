"""Trust in the data engine: resume, manifests, object keys, bad objects, sizes, the no-filter text."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

from ohra.data.dataset import GraspDataset, file_digest
from ohra.errors import DatasetError, ObjectError
from ohra.hands import get_hand
from ohra.objects.model import ObjectModel
from ohra.objects.resolve import resolve_objects, size_problem
from ohra.synth.pipeline import SynthSettings, diagnose, synthesize

HAND = [("leap_2200", get_hand("leap_2200"))]
FAST = SynthSettings(grasps_per_object=1, filter=False)


def _cli(*args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "ohra.synth", *args, "--quiet"], capture_output=True, text=True, timeout=timeout)


def _error_lines(proc: subprocess.CompletedProcess) -> list[str]:
    return [line for line in proc.stderr.splitlines() if line.strip()]


def _box_file(path: Path, extents) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    trimesh.creation.box(extents=extents).export(str(path))
    return path


def test_resume_recomputes_a_truncated_shard(tmp_path):
    synthesize(HAND, [ObjectModel.builtin("box")], tmp_path, FAST, progress=False)
    man = json.loads((tmp_path / "manifest.json").read_text())
    shard = tmp_path / man["hands"]["leap_2200"]["shards"]["box"]["file"]
    good = shard.read_bytes()
    shard.write_bytes(good[: len(good) // 2])  # an interrupted copy, say
    synthesize(HAND, [ObjectModel.builtin("box")], tmp_path, FAST, resume=True, progress=False)
    assert shard.read_bytes() == good  # recomputed, byte for byte
    assert GraspDataset(tmp_path).grasps().shape[1] == 31


def test_resume_keeps_a_procedural_shard_made_on_another_cpu_but_not_a_changed_mesh(tmp_path):
    """Procedural vertices once differed in the last bit between CPUs (NumPy's AVX-512 power): a shard
    whose procedural object has another hash but the same geometry is kept on resume; a real mesh with
    another hash, or a procedural object of other geometry, is recomputed."""
    from ohra.data.manifest import shard_complete

    (tmp_path / "s.npz").write_bytes(b"grasps")
    sh = lambda obj, **over: {"file": "s.npz", "sha256": file_digest(tmp_path / "s.npz"), "object": {**obj, **over}}
    proc = ObjectModel.procedural("ellipsoid", 2).describe()
    other_cpu = dict(mesh_hash="0" * 16, body_hash="1" * 16)
    assert shard_complete(tmp_path, sh(proc), proc)
    assert shard_complete(tmp_path, sh(proc, **other_cpu), proc)
    assert not shard_complete(tmp_path, sh(proc, **other_cpu, volume_m3=proc["volume_m3"] * (1 + 1e-6)), proc)
    real = ObjectModel.builtin("box").describe()
    assert shard_complete(tmp_path, sh(real), real)
    assert not shard_complete(tmp_path, sh(real, **other_cpu), real)


def test_resume_with_other_settings_is_refused_and_overwrite_leaves_no_orphans(tmp_path):
    objs = [ObjectModel.builtin("box"), ObjectModel.builtin("sphere")]
    synthesize(HAND, objs, tmp_path, FAST, progress=False)
    other = SynthSettings(grasps_per_object=1, filter=False, seed=5)
    with pytest.raises(DatasetError, match=r"other settings \(seed: 0 -> 5"):
        synthesize(HAND, objs, tmp_path, other, resume=True, progress=False)
    with pytest.raises(DatasetError, match="other settings"):
        synthesize(HAND, objs[:1], tmp_path, other, progress=False)
    man = synthesize(HAND, objs[:1], tmp_path, other, overwrite=True, progress=False)
    listed = {sh["file"] for e in man["hands"].values() for sh in e["shards"].values()}
    on_disk = {str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*.npz")}
    assert on_disk == listed and len(listed) == 1


def test_a_folder_of_other_files_is_refused_but_an_interrupted_first_run_is_continued(tmp_path):
    """Without a manifest, only hidden entries and the run's own hand folders (shards of a first run killed before
    its manifest was written) may be there; anything else would be mixed into the dataset."""
    notes = tmp_path / "notes"
    notes.mkdir()
    (notes / "thesis.tex").write_text("mine")
    with pytest.raises(DatasetError, match=r"not empty and holds no grasp dataset \(no manifest.json; found thesis.tex\)"):
        synthesize(HAND, [ObjectModel.builtin("box")], notes, FAST, overwrite=True, progress=False)
    assert sorted(p.name for p in notes.iterdir() if p.name != ".ohra.lock") == ["thesis.tex"]
    other_hand = tmp_path / "other"
    (other_hand / "leap_3333").mkdir(parents=True)
    with pytest.raises(DatasetError, match="found leap_3333/"):
        synthesize(HAND, [ObjectModel.builtin("box")], other_hand, FAST, progress=False)
    first = tmp_path / "first"
    (first / "leap_2200").mkdir(parents=True)
    (first / ".ohra.lock").write_text("")
    man = synthesize(HAND, [ObjectModel.builtin("box")], first, FAST, progress=False)
    assert man["hands"]["leap_2200"]["counts"]["candidates"] == 1
    (notes / "thesis.tex").unlink()
    synthesize(HAND, [ObjectModel.builtin("box")], first, FAST, resume=True, progress=False)  # has a manifest now


def test_a_corrupt_manifest_is_one_line_and_exit_2(tmp_path):
    (tmp_path / "manifest.json").write_text('{"hands": {"leap_2200": ')
    proc = _cli("--hand", "leap_2200", "--objects", "builtin:box", "--out", str(tmp_path), "--resume", "--no-filter",
                "--grasps-per-object", "1")
    lines = _error_lines(proc)
    assert proc.returncode == 2 and len(lines) == 1 and "corrupt manifest" in lines[0], proc.stderr
    with pytest.raises(DatasetError, match="corrupt manifest"):
        GraspDataset(tmp_path)


def test_objects_sharing_a_file_name_get_their_own_manifest_entries(tmp_path):
    a = _box_file(tmp_path / "a" / "part.stl", (0.04, 0.05, 0.06))
    b = _box_file(tmp_path / "b" / "part.stl", (0.05, 0.05, 0.07))
    objs = resolve_objects([str(a), str(b)])
    assert [o.name for o in objs] == ["part", "part"]
    man = synthesize(HAND, objs, tmp_path / "out", FAST, progress=False)
    shards = man["hands"]["leap_2200"]["shards"]
    assert len(shards) == 2 and all(k.startswith("part-") for k in shards)
    assert man["hands"]["leap_2200"]["counts"]["candidates"] == 2
    ds = GraspDataset(tmp_path / "out")
    with pytest.raises(DatasetError, match="names 2 shards"):
        ds.load_shard("leap_2200", "part")
    assert len({ds.load_shard("leap_2200", k)["raw"].tobytes() for k in shards}) == 2


def test_resume_after_a_same_named_object_joins_lists_each_shard_once(tmp_path):
    """``part`` alone is keyed ``part``; resumed with a second ``part`` both become ``part-<hash>``: the first
    keeps its shard (not recomputed) under its new key only, and back again when the second leaves."""
    a = _box_file(tmp_path / "a" / "part.stl", (0.04, 0.05, 0.06))
    b = _box_file(tmp_path / "b" / "part.stl", (0.05, 0.05, 0.07))
    first = synthesize(HAND, resolve_objects([str(a)]), tmp_path / "out", FAST, progress=False)
    (old,) = first["hands"]["leap_2200"]["shards"].values()
    man = synthesize(HAND, resolve_objects([str(a), str(b)]), tmp_path / "out", FAST, resume=True, progress=False)
    shards = man["hands"]["leap_2200"]["shards"]
    assert len(shards) == 2 and all(k.startswith("part-") for k in shards)
    assert len({sh["file"] for sh in shards.values()}) == 2
    assert old in shards.values()  # the first object's shard, kept as it was
    assert man["hands"]["leap_2200"]["counts"]["candidates"] == 2
    back = synthesize(HAND, resolve_objects([str(a)]), tmp_path / "out", FAST, resume=True, progress=False)
    assert back["hands"]["leap_2200"]["shards"]["part"] == old
    assert len(GraspDataset(tmp_path / "out").entries) == 2  # 'part' and the second object's 'part-<hash>'


@pytest.mark.parametrize("faces, message", [([[0, 1, 2]], "span no volume"), ([[0, 1, 2], [0, 2, 3]], "is flat")])
def test_flat_and_one_triangle_meshes_are_refused_at_once(tmp_path, faces, message):
    m = trimesh.Trimesh(vertices=[[0, 0, 0], [0.1, 0, 0], [0.1, 0.1, 0], [0, 0.1, 0]], faces=faces, process=False)
    path = tmp_path / "flat.obj"
    m.export(str(path))
    proc = _cli("--hand", "leap_2200", "--objects", str(path), "--out", str(tmp_path / "out"), timeout=60)
    lines = _error_lines(proc)
    assert proc.returncode == 2 and len(lines) == 1 and message in lines[0], proc.stderr


@pytest.mark.e2e  # runs V-HACD (~15 s)
def test_vhacd_is_silent_bounded_and_leaves_only_its_result(tmp_path, monkeypatch, capfd):
    monkeypatch.setenv("OHRA_CACHE_DIR", str(tmp_path / "cache"))
    from ohra.objects.decompose import vhacd_pieces

    torus = trimesh.creation.torus(major_radius=0.04, minor_radius=0.012, major_sections=24, minor_sections=12)
    pieces = vhacd_pieces(torus, "torus-test", resolution=10_000)
    out, _ = capfd.readouterr()
    assert out == ""  # V-HACD's usage text used to reach stdout
    assert len(pieces) > 1
    assert [p.name for p in (tmp_path / "cache" / "vhacd").iterdir()] == ["torus-test.obj"]
    with pytest.raises(ObjectError, match="is flat"):
        vhacd_pieces(trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], [[0, 1, 2], [1, 3, 2]]), "flat-test")
    assert not (tmp_path / "cache" / "vhacd" / "flat-test.obj").exists()


@pytest.mark.parametrize("extents, expect", [((60.0, 70.0, 80.0), "--scale 0.001"), ((0.001,) * 3, "outside the graspable range"),
                                             ((1.0, 0.8, 0.6), "outside the graspable range")])
def test_objects_of_implausible_size_are_refused_with_a_hint(tmp_path, extents, expect):
    path = _box_file(tmp_path / "thing.stl", extents)
    problem = size_problem(ObjectModel.load(path))
    assert problem and expect in problem
    proc = _cli("--hand", "leap_2200", "--objects", str(path), "--out", str(tmp_path / "out"), "--no-filter")
    lines = _error_lines(proc)
    assert proc.returncode == 2 and len(lines) == 1 and expect in lines[0], proc.stderr


def test_scale_brings_a_millimetre_mesh_into_range(tmp_path):
    path = _box_file(tmp_path / "thing.stl", (60.0, 70.0, 80.0))
    (obj,) = resolve_objects([str(path)], scale=0.001)
    assert size_problem(obj) is None
    assert np.allclose(obj.extents, [0.06, 0.07, 0.08])


@pytest.mark.parametrize("extents, expect", [((0.06, 0.07, 0.08), "without --scale (0.1 now) it is 8 cm"),
                                             ((60.0, 70.0, 80.0), "--scale 0.001 makes it 8 cm")])
def test_the_scale_hint_accounts_for_a_scale_already_given(tmp_path, extents, expect):
    """--scale replaces the factor: on a metre mesh given --scale 0.1 the fix is to drop it, not to add 10."""
    (obj,) = resolve_objects([str(_box_file(tmp_path / "thing.stl", extents))], scale=0.1)
    assert expect in size_problem(obj)


def test_a_scale_that_is_not_positive_is_refused_for_every_object():
    for spec in ("builtin:box", "procedural:box:3"):
        with pytest.raises(ObjectError, match="scale must be a number > 0, got 0"):
            resolve_objects([spec], scale=0)


def test_a_pair_where_nothing_converges_says_why():
    from ohra.canonical.kinematics import HandModel

    hand = HandModel.from_params(get_hand("leap_2200"))
    big = ObjectModel(trimesh.creation.box(extents=(0.3, 0.3, 0.3)), "crate")
    msg = diagnose(hand, big, [2, 2, 3])
    assert "2 Maximum_Iterations_Exceeded, 1 Infeasible_Problem_Detected" in msg
    assert "exceeds the hand's largest fingertip span" in msg


def test_no_filter_output_does_not_claim_a_filter(tmp_path):
    proc = _cli("--hand", "leap_2200", "--objects", "builtin:box", "--out", str(tmp_path), "--no-filter", "--grasps-per-object", "1")
    assert proc.returncode == 0, proc.stderr
    assert "kept without the filter" in proc.stdout and "passed the filter" not in proc.stdout


def test_shards_are_byte_deterministic(tmp_path):
    for d in ("a", "b"):
        synthesize(HAND, [ObjectModel.builtin("box")], tmp_path / d, FAST, progress=False)
    fa, fb = (next((tmp_path / d).rglob("*.npz")) for d in ("a", "b"))
    assert fa.read_bytes() == fb.read_bytes()
    assert file_digest(fa) == json.loads((tmp_path / "a" / "manifest.json").read_text())["hands"]["leap_2200"]["shards"]["box"]["sha256"]


def test_two_pool_workers_write_the_same_shards_as_one(tmp_path):
    objs = [ObjectModel.builtin("box"), ObjectModel.procedural("capsule", 2)]  # both must pickle into the workers
    a = synthesize(HAND, objs, tmp_path / "one", FAST, progress=False)
    b = synthesize(HAND, objs, tmp_path / "two", FAST, workers=2, progress=False)
    sha = lambda m: {k: s["sha256"] for k, s in m["hands"]["leap_2200"]["shards"].items()}  # noqa: E731
    assert sha(a) == sha(b) and len(sha(a)) == 2


def test_the_ray_backend_without_ray_is_refused_before_the_output_folder_is_made(tmp_path, monkeypatch):
    import importlib.util

    from ohra.errors import OhraError

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "ray" else real(name, *a))
    with pytest.raises(OhraError, match=r"the ray backend needs Ray: pip install -e \"\.\[ray\]\""):
        synthesize(HAND, [ObjectModel.builtin("box")], tmp_path / "out", FAST, backend="ray", progress=False)
    assert not (tmp_path / "out").exists()  # it was left holding only its lock file


def test_a_ray_address_where_nothing_answers_fails_in_seconds_not_at_rays_timeout(monkeypatch):
    """``--address 10.x.x.x:6379`` of an unreachable host waited minutes for Ray's own timeout."""
    import socket
    import time

    from ohra.data.backends import probe_address
    from ohra.errors import OhraError

    with socket.socket() as s:  # a port nothing listens on: refused at once
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    with pytest.raises(OhraError, match=rf"--address ray://127.0.0.1:{port}: no Ray cluster reachable \(.* at 127.0.0.1:{port} within 5 s\)"):
        probe_address(f"ray://127.0.0.1:{port}")
    asked = []

    def silent(where, timeout):  # a host that never answers (sandboxes may accept any outside connection)
        asked.append((where, timeout))
        time.sleep(timeout)
        raise TimeoutError("timed out")

    monkeypatch.setattr(socket, "create_connection", silent)
    with pytest.raises(OhraError, match=r"10.255.255.1:6379: no Ray cluster reachable \(no answer at 10.255.255.1:6379 within 0.5 s\)"):
        probe_address("10.255.255.1:6379", timeout=0.5)
    assert asked == [(("10.255.255.1", 6379), 0.5)]
    monkeypatch.undo()
    with socket.socket() as s:  # something listening: passed on to Ray
        s.bind(("127.0.0.1", 0))
        s.listen()
        probe_address(f"127.0.0.1:{s.getsockname()[1]}")
    probe_address("auto")  # left to Ray


def test_an_unreachable_ray_address_is_refused_before_the_progress_bar_is_drawn(tmp_path):
    """The error line came after the bar's first frame (`pairs:   0%|...ohra: error: --address ...` on a terminal)."""
    pytest.importorskip("ray", reason="the ray extra is not installed")
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    proc = subprocess.run([sys.executable, "-m", "ohra.synth", "--hand", "leap_2200", "--objects", "builtin:box", "--backend",
                           "ray", "--address", f"127.0.0.1:{port}", "-o", str(tmp_path / "d")], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 2 and proc.stderr.startswith(f"ohra: error: --address 127.0.0.1:{port}: no Ray cluster reachable")
    assert len(_error_lines(proc)) == 1 and "pairs" not in proc.stderr and not (tmp_path / "d").exists()


def test_a_ray_address_without_a_cluster_is_one_line(monkeypatch):
    """``--address auto`` with no cluster running was Ray's ConnectionError traceback, exit 1."""
    ray = pytest.importorskip("ray", reason="the ray extra is not installed")
    from ohra.data import backends
    from ohra.errors import OhraError

    def no_cluster(*a, **k):
        raise ConnectionError("Could not find any running Ray instance.\nmore lines")

    monkeypatch.setattr(ray, "is_initialized", lambda: False)
    monkeypatch.setattr(ray, "init", no_cluster)
    with pytest.raises(OhraError, match=r"--address auto: no Ray cluster reachable \(Could not find any running Ray instance\.\)"):
        list(backends._ray(abs, [1], 1, "auto"))
    import socket

    with socket.socket() as s:  # a host:port address is probed before Ray is asked (Ray waits minutes on a silent host)
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    with pytest.raises(OhraError, match=rf"127.0.0.1:{port}: no Ray cluster reachable \(connection refused at"):
        list(backends._ray(abs, [1], 1, f"127.0.0.1:{port}"))


def test_converged_grasps_left_unsimulated_for_sinking_too_deep_are_counted_and_said(tmp_path, capsys):
    """A 1 cm pen: 3 of 10 converged grasps sank more than 1 mm into it and were dropped before the simulation, with no
    word in the summary line or in `ohra data info` (only the shard's arrays knew)."""
    from ohra.cli.synth import print_summary
    from ohra.data.build import format_summary, summary

    man = synthesize(HAND, [ObjectModel.builtin("box")], tmp_path, SynthSettings(grasps_per_object=2, filter=False),
                     progress=False)
    shard = man["hands"]["leap_2200"]["shards"]["box"]
    assert shard["n_prefiltered"] == 0  # no filter: nothing is left unsimulated for sinking in (all kept unsimulated)
    filtered = synthesize(HAND, [ObjectModel.builtin("box")], tmp_path / "f", SynthSettings(grasps_per_object=2,
                          max_penetration_m=0.0), progress=False)["hands"]["leap_2200"]["shards"]["box"]
    with np.load(tmp_path / "f" / filtered["file"]) as d:
        assert filtered["n_prefiltered"] == int(d["prefiltered"].sum()) >= 1  # max_penetration_m 0: any sunk finger
    man["hands"]["leap_2200"]["counts"]["prefiltered"] = 3  # as the pen's pair recorded it
    print_summary(man, tmp_path)
    assert "converged (3 sunk more than 1 mm into the object, not simulated)" in capsys.readouterr().out
    m = json.loads((tmp_path / "manifest.json").read_text())
    m["hands"]["leap_2200"]["shards"]["box"]["n_prefiltered"] = 3
    (tmp_path / "manifest.json").write_text(json.dumps(m))
    assert "  3 converged sank too deep into the object to simulate (max_penetration_m)" in format_summary(summary(tmp_path))
