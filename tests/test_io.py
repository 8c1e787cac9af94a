"""Files written by ohra honour the umask and appear whole or not at all (``ohra.io``)."""

from __future__ import annotations

import contextlib
import io
import json
import os
import stat

import numpy as np
import pytest

import ohra
from ohra import viz
from ohra.canonical.kinematics import HandModel
from ohra.cli.main import main
from ohra.data import atomic_write_json, atomic_write_npz
from ohra.io import atomic_path, atomic_write, umask_mode, write_json, write_npz, write_text


@pytest.fixture(params=[(0o022, 0o644), (0o077, 0o600), (0o002, 0o664)], ids=["umask022", "umask077", "umask002"])
def umask(request):
    """Run the test under a umask; yields the mode a new file must get."""
    mask, mode = request.param
    old = os.umask(mask)
    try:
        yield mode
    finally:
        os.umask(old)


@pytest.fixture(scope="module")
def scene():
    """A meshcat scene with a canonical hand in it; the server it starts is stopped afterwards."""
    with contextlib.redirect_stdout(io.StringIO()):  # meshcat prints its URL
        vis = viz.new_visualizer()
    viz.add_hand(vis, HandModel.from_params(ohra.get_hand("leap_3303")), np.zeros(22))
    yield vis
    proc = vis.window.server_proc
    proc.kill()
    proc.wait()


def _mode(path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


def _leftovers(folder, keep: set[str]) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name not in keep)


def test_umask_mode_is_what_open_gives(tmp_path, umask):
    assert umask_mode() == umask
    with open(tmp_path / "plain", "w"):
        pass
    assert _mode(tmp_path / "plain") == umask


def test_dataset_shard_and_manifest_honour_the_umask(tmp_path, umask):
    shard = tmp_path / "ds" / "leap_3303" / "box-0123abcd.npz"
    atomic_write_npz(shard, {"grasps": np.zeros((2, 31), np.float32)})
    atomic_write_json(tmp_path / "ds" / "manifest.json", {"version": 1, "hands": {}})
    assert _mode(shard) == umask and _mode(tmp_path / "ds" / "manifest.json") == umask
    assert np.load(shard)["grasps"].shape == (2, 31)
    assert json.loads((tmp_path / "ds" / "manifest.json").read_text())["version"] == 1
    assert _leftovers(tmp_path / "ds", {"leap_3303", "manifest.json"}) == []


def test_urdf_from_api_and_cli_honour_the_umask(tmp_path, umask):
    api = ohra.write(ohra.get_hand("leap_3303"), tmp_path / "api.urdf")
    assert main(["hand", "render", "leap_3303", "-o", str(tmp_path / "cli.urdf")]) == 0
    assert _mode(api) == umask and _mode(tmp_path / "cli.urdf") == umask
    assert (tmp_path / "cli.urdf").read_text() == ohra.render(ohra.get_hand("leap_3303"), robot_name="leap_3303")
    assert _leftovers(tmp_path, {"api.urdf", "cli.urdf"}) == []


def test_params_json_honours_the_umask(tmp_path, umask):
    ohra.get_hand("leap_3303").to_json(tmp_path / "p.json")
    assert _mode(tmp_path / "p.json") == umask
    assert ohra.load_params(tmp_path / "p.json").to_json() == ohra.get_hand("leap_3303").to_json()


def test_static_html_honours_the_umask(tmp_path, umask, scene):
    path = viz.save_html(scene, tmp_path / "scene.html")
    assert _mode(path) == umask
    assert "<html" in path.read_text().lower()
    assert _leftovers(tmp_path, {"scene.html"}) == []


def test_png_honours_the_umask(tmp_path, umask):
    from ohra.sim.render import write_png

    path = write_png(np.zeros((8, 8, 3), np.uint8), tmp_path / "sheet.png")
    assert _mode(path) == umask and path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize("exc", [ZeroDivisionError, KeyboardInterrupt])
def test_failing_write_leaves_no_partial_and_no_temp_file(tmp_path, exc):
    def write(fh):
        fh.write(b"half a shard")
        raise exc("disk full")

    with pytest.raises(exc):
        atomic_write(tmp_path / "new.npz", write)
    assert _leftovers(tmp_path, set()) == []

    old = write_text(tmp_path / "old.json", '{"complete": true}\n')
    with pytest.raises(exc):
        atomic_write(old, write)
    assert old.read_text() == '{"complete": true}\n'
    assert _leftovers(tmp_path, {"old.json"}) == []


def test_failing_named_writer_leaves_nothing(tmp_path):
    with pytest.raises(RuntimeError), atomic_path(tmp_path / "fig.png", suffix=".png") as tmp:
        tmp.write_bytes(b"\x89PNG partial")
        raise RuntimeError("savefig failed")
    assert _leftovers(tmp_path, set()) == []


def test_write_npz_and_json_round_trip(tmp_path):
    a = np.arange(12, dtype=np.float32).reshape(3, 4)
    with np.load(write_npz(tmp_path / "a.npz", {"a": a})) as data:
        np.testing.assert_array_equal(data["a"], a)
    assert json.loads(write_json(tmp_path / "d.json", {"p": tmp_path}).read_text()) == {"p": str(tmp_path)}


def test_parent_folders_are_created(tmp_path):
    assert write_text(tmp_path / "a" / "b" / "c.txt", "x").read_text() == "x"


HOLD = """
import sys, time
from ohra.io import folder_lock
with folder_lock(sys.argv[1], "dataset"):
    print("held", flush=True)
    time.sleep(120)
"""


@pytest.fixture
def held(tmp_path):
    """A folder whose lock another process holds (killed, not released, at the end)."""
    import subprocess
    import sys

    folder = tmp_path / "run"
    p = subprocess.Popen([sys.executable, "-c", HOLD, str(folder)], stdout=subprocess.PIPE, text=True)
    assert p.stdout.readline().strip() == "held"
    yield folder, p
    p.kill()
    p.wait()


def test_a_folder_held_by_another_process_is_refused_with_its_pid(held):
    from ohra.errors import FolderInUseError
    from ohra.io import folder_lock

    folder, p = held
    with pytest.raises(FolderInUseError, match=rf"{folder}: another process \(pid {p.pid}\) is writing this dataset"):
        with folder_lock(folder, "dataset"):
            pass


def test_a_killed_holder_leaves_no_stale_lock(held):
    from ohra.io import folder_lock

    folder, p = held
    p.kill()
    p.wait()
    with folder_lock(folder, "dataset") as f:
        assert f == folder
    with folder_lock(folder, "dataset"):  # released on exit: taken again by the same process
        pass


def test_the_cli_refuses_a_dataset_another_build_is_writing(held, tmp_path):
    import subprocess
    import sys

    folder, _ = held
    recipe = tmp_path / "r.yaml"
    recipe.write_text("hands: [leap_2200]\nobjects: [builtin:box]\ngrasps_per_pair: 1\nfilter: false\n")
    proc = subprocess.run([sys.executable, "-m", "ohra.data", "build", str(recipe), "--out", str(folder)],
                          capture_output=True, text=True, timeout=600)
    lines = [l for l in proc.stderr.splitlines() if l.strip()]
    assert proc.returncode == 2 and len(lines) == 1 and "is writing this dataset" in lines[0], proc.stderr
    assert not (folder / "manifest.json").exists()


def test_an_output_path_that_is_a_folder_or_under_a_file_is_named_as_given(tmp_path):
    from ohra.errors import OutputPathError
    from ohra.io import check_output, write_text

    (tmp_path / "afile").write_text("x")
    with pytest.raises(OutputPathError, match=r"afile/out.json: .*afile is a file, not a folder"):
        write_text(tmp_path / "afile" / "out.json", "{}")
    with pytest.raises(OutputPathError, match=r"is a folder; give a file path"):
        write_text(tmp_path, "{}")
    with pytest.raises(OutputPathError, match=r"afile is a file; give a folder"):
        check_output(tmp_path / "afile", folder=True)
    assert check_output(tmp_path / "new" / "deeper" / "x.json") == tmp_path / "new" / "deeper" / "x.json"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile"]  # nothing was created by the checks


def test_an_output_folder_that_cannot_be_written_is_named_before_the_work(tmp_path, monkeypatch, capsys):
    """A read-only folder was found only when the result was written, after minutes of simulation, and the error
    named the hidden temporary file. (As root a 0555 folder stays writable, so the permission is simulated.)"""
    from ohra.cli.main import main
    from ohra.errors import OutputPathError
    from ohra.io import check_output

    ro = tmp_path / "ro"
    ro.mkdir()
    real = os.access
    monkeypatch.setattr(os, "access", lambda p, mode, **kw: False if str(p) == str(ro) else real(p, mode, **kw))
    with pytest.raises(OutputPathError, match=r"ro/r.json: cannot write into .*ro \(permission denied\)"):
        check_output(ro / "r.json")
    with pytest.raises(OutputPathError, match=r"cannot write into .*ro"):
        check_output(ro / "new" / "deeper", folder=True)  # the nearest existing folder decides
    assert check_output(tmp_path / "ok.json") == tmp_path / "ok.json"
    assert main(["rotate", "eval", "leap_canonical", "--episodes", "1", "-o", str(ro / "out")]) == 2
    assert "permission denied" in capsys.readouterr().err


def test_a_lock_on_a_file_is_one_error_and_a_failed_job_leaves_no_empty_folder(tmp_path):
    from ohra.errors import OutputPathError
    from ohra.io import LOCK_NAME, folder_lock

    (tmp_path / "afile").write_text("")
    with pytest.raises(OutputPathError, match="afile is a file; give a folder"):  # was FileExistsError
        with folder_lock(tmp_path / "afile"):
            pass
    with pytest.raises(ValueError):  # a job that fails its checks before writing anything
        with folder_lock(tmp_path / "run"):
            raise ValueError("no such hand in the data")
    assert not (tmp_path / "run").exists()
    with folder_lock(tmp_path / "run") as run:  # a job that wrote something keeps its folder
        (run / "config.json").write_text("{}")
    assert sorted(p.name for p in (tmp_path / "run").iterdir()) == [LOCK_NAME, "config.json"]
    (tmp_path / "mine").mkdir()
    with pytest.raises(ValueError):
        with folder_lock(tmp_path / "mine"):  # a folder the caller made stays
            raise ValueError
    assert (tmp_path / "mine").is_dir()


def test_an_output_suffix_is_checked_in_any_case_and_a_bare_suffix_is_named_as_such(tmp_path):
    """``-o UP.JSON`` was refused by one command and taken by another; ``-o .npz`` said "must end in .npz, got .npz"."""
    from ohra.errors import OutputPathError
    from ohra.io import check_suffix

    assert check_suffix(tmp_path / "UP.JSON", ".json") == tmp_path / "UP.JSON"
    with pytest.raises(OutputPathError, match=r"-o must end in .npz, got .npz \(a file name is needed before .npz\)"):
        check_suffix(".npz", ".npz")
    with pytest.raises(OutputPathError, match=r"--render must end in .png, got .*r.txt$"):
        check_suffix(tmp_path / "r.txt", ".png", "--render")
