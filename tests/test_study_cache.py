"""The studies' run cache (benchmarks/_study_cache.py): a study process that reaches a run another
process is training waits for it instead of training it a second time into the same folder."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
try:
    from _study_cache import when_free
finally:
    sys.path.pop(0)

from ohra.io import folder_lock  # noqa: E402

HOLD = "import sys, time\nfrom ohra.io import folder_lock\nwith folder_lock(sys.argv[1]):\n    print('held', flush=True); time.sleep(1.5)"


def test_a_run_in_training_elsewhere_is_waited_for_then_taken(tmp_path, capsys):
    run = tmp_path / "run"
    p = subprocess.Popen([sys.executable, "-c", HOLD, str(run)], stdout=subprocess.PIPE, text=True)
    assert p.stdout.readline().strip() == "held"
    calls = []

    def get():
        calls.append(time.monotonic())
        with folder_lock(run, "training run"):
            return "trained here"

    assert when_free(get, poll_s=0.2) == "trained here"
    p.wait()
    assert len(calls) >= 2 and "is writing this training run" in (err := capsys.readouterr().err) and "waiting 0.2 s" in err


def test_evaluations_cached_before_the_urdf_damping_setting_stay_valid_where_it_cannot_matter(tmp_path):
    """Protocol.urdf_joint_damping cannot change a canonical evaluation (canonical URDFs carry no
    damping), nor an original one of a hand whose URDF has none: those cached verdicts are kept."""
    from dataclasses import replace

    from ohra.sim import Protocol

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    try:
        from _study_cache import _protocol_repr, carried_over, eval_key, store
    finally:
        sys.path.pop(0)
    drop, keep = Protocol(), replace(Protocol(), urdf_joint_damping=True)
    model, hands = {"run": "m"}, ["allegro", "shadow"]
    assert eval_key(model, hands=hands, original=False, protocol=drop) == eval_key(model, hands=hands, original=False, protocol=keep)
    new = eval_key(model, hands=hands, original=True, protocol=drop)
    assert new != eval_key(model, hands=hands, original=True, protocol=keep)

    before = {"model": model, "hands": hands, "original": True, "protocol": _protocol_repr(drop, ("urdf_joint_damping",))}
    store(path := tmp_path / "eval.json", before, {"per_hand": {}})
    undamped = lambda h: h == "allegro"  # noqa: E731
    assert carried_over(path, new, undamped)["hands"] == ["allegro"]  # shadow ran with the damping: evaluate again
    assert carried_over(path, eval_key(model, hands=hands, original=True, protocol=keep), undamped)["hands"] == hands
    assert carried_over(path, eval_key(model, hands=hands, original=True, protocol=replace(drop, friction=1.0)), undamped) is None
    assert carried_over(path, {**new, "n": 5}, undamped) is None


def test_a_stamp_left_by_a_run_that_never_trained_does_not_block_the_corrected_run(tmp_path):
    """A study started with a bad setting wrote its key, failed before training, and then refused the corrected
    command ("cached with other settings"). A stamp over no weights is dropped; one over a checkpoint still holds."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    try:
        from _study_cache import claim_run
    finally:
        sys.path.pop(0)

    from ohra.io import folder_lock

    run = tmp_path / "run"
    assert claim_run(run, {"steps": 5, "data": ["nope"]}) is False  # the mistyped first attempt stamps the run
    try:
        with folder_lock(run, "training run"):  # ... and its training fails, leaving its lock file (and a config)
            (run / "config.json").write_text("{}")
            raise RuntimeError("bad setting")
    except RuntimeError:
        pass
    assert claim_run(run, {"steps": 5, "data": ["grasps"]}) is False  # it held no weights: the fix goes ahead
    (run / "checkpoints").mkdir()
    (run / "checkpoints" / "last.pt").write_bytes(b"weights")
    try:
        claim_run(run, {"steps": 9, "data": ["grasps"]})
        raise AssertionError("a trained run was taken over by other settings")
    except SystemExit as exc:
        assert "cached with other settings (steps: 5 -> 9)" in str(exc)


def test_a_data_folder_that_is_not_a_dataset_is_named_before_any_stamp(tmp_path):
    import pytest

    from ohra.errors import DatasetError

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    try:
        from _study_cache import data_fingerprint
    finally:
        sys.path.pop(0)
    with pytest.raises(DatasetError, match=f"--data {tmp_path / 'nope'}: no dataset there"):
        data_fingerprint([str(tmp_path / "nope")])
