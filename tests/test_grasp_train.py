"""Grasp-model data, batches, training (determinism, exact resume), object split, evaluation, CLI."""

from __future__ import annotations

import importlib
import json
from pathlib import Path
from dataclasses import replace

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from grasp_fixtures import HANDS, tiny_model_config, tiny_train_config, write_dataset  # noqa: E402

from ohra.errors import CheckpointError, DatasetError, GraspError, ParamsError  # noqa: E402
from ohra.hands import get_hand  # noqa: E402
from ohra.learn.grasp.config import GraspConfigError  # noqa: E402
from ohra.learn.grasp.data import TrainingData, check_disjoint, make_batch  # noqa: E402
from ohra.learn.grasp.evaluate import check_unseen, diversity, evaluate_model, pair_seed  # noqa: E402
from ohra.learn.grasp.model import load_grasp_model  # noqa: E402
from ohra.learn.grasp.train import learning_rate, train_grasp  # noqa: E402
from ohra.objects.model import ObjectModel  # noqa: E402
from ohra.rotations import rot6d_to_matrix  # noqa: E402


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    return write_dataset(tmp_path_factory.mktemp("grasps"))


def _tables(td):
    hand = torch.zeros(len(td.hands), 4)
    present = torch.from_numpy(np.stack([p.present_joints for p in td.params]))
    return hand, present


# -- data and split --------------------------------------------------------------------------------
def test_split_holds_out_test_objects_by_name_and_mesh(tmp_path):
    """A renamed copy of a test object (same mesh) is held out too; the split is disjoint."""
    root = write_dataset(tmp_path, objects=("sphere", "box", "capsule"), renamed={"ball": "sphere"})
    td = TrainingData.load(root, tiny_train_config(test_objects=("sphere",)))
    train = {o.name for o in td.objects}
    assert train == {"box", "capsule"}
    assert {o for _, o in td.test_grasps} == {"sphere", "ball"}
    sphere_hash = ObjectModel.builtin("sphere").mesh_hash
    assert sphere_hash not in {o.mesh_hash for o in td.objects}
    assert len(td) == 3 * 2 * 6 and set(np.unique(td.obj_idx)) == {0, 1}
    assert len(TrainingData.load(root, tiny_train_config(test_objects=("sphere",), max_per_pair=2))) == 3 * 2 * 2


def test_the_test_objects_a_recipe_split_off_are_never_trained_on(tmp_path):
    """A dataset whose manifest records ``split.test`` (``ohra data build`` with a recipe split) holds those
    objects out without being told again (training on them silently was the bug), on top of ``test_objects``."""
    import json

    root = write_dataset(tmp_path, objects=("sphere", "box", "capsule"))
    man = json.loads((root / "manifest.json").read_text())
    man["split"] = {"train": ["sphere", "capsule"], "test": ["box"]}
    (root / "manifest.json").write_text(json.dumps(man))
    td = TrainingData.load(root, tiny_train_config(test_objects=()))
    assert {o.name for o in td.objects} == {"sphere", "capsule"} and set(td.test_objects) == {"box"}
    td = TrainingData.load(root, tiny_train_config(test_objects=("capsule",)))
    assert {o.name for o in td.objects} == {"sphere"} and set(td.test_objects) == {"box", "capsule"}


def test_zero_shot_split_holds_out_test_hands_by_name_and_parameters(tmp_path):
    """A zero-shot model never sees its test hand, not even a copy stored under another name."""
    import json

    a = write_dataset(tmp_path / "a", objects=("box", "capsule"))
    b = write_dataset(tmp_path / "b", hands=("barrett_hand",), objects=("box", "capsule"), seed=1)
    man = json.loads((b / "manifest.json").read_text())
    man["hands"]["my_gripper"] = man["hands"].pop("barrett_hand")  # same parameters, another name
    (b / "manifest.json").write_text(json.dumps(man))
    full = TrainingData.load([a, b], tiny_train_config(test_objects=()))
    assert set(full.hands) == {"allegro_hand_left", "barrett_hand", "shadow_hand_right", "my_gripper"}
    td = TrainingData.load([a, b], tiny_train_config(test_objects=(), test_hands=("barrett_hand",)))
    assert td.hands == ["allegro_hand_left", "shadow_hand_right"] and len(td) == 2 * 2 * 6
    assert set(td.summary()["test_hands"]) == {"barrett_hand"}
    with pytest.raises(DatasetError, match="both training and test"):
        TrainingData.load([a], tiny_train_config(hands=("barrett_hand",), test_hands=("barrett_hand",)))


@pytest.mark.parametrize("legacy", [False, True])
def test_procedural_training_objects_are_rebuilt_from_the_manifest(tmp_path, legacy):
    """Procedural shapes have no file: the manifest names them (``procedural:box:3``; datasets made
    before that said ``builtin`` under the shape's default name) and the loader rebuilds them."""
    import json

    root = write_dataset(tmp_path, hands=("barrett_hand",), objects=("capsule",), procedural=(("box", 3), ("ellipsoid", 7)))
    man = json.loads((root / "manifest.json").read_text())
    assert man["hands"]["barrett_hand"]["shards"]["box-3"]["object"]["source"] == "procedural:box:3"
    if legacy:
        for sh in man["hands"]["barrett_hand"]["shards"].values():
            sh["object"]["source"] = "builtin"
        (root / "manifest.json").write_text(json.dumps(man))
    td = TrainingData.load(root, tiny_train_config())
    assert {o.name for o in td.objects} == {"box-3", "ellipsoid-7"}
    assert {o.mesh_hash for o in td.objects} == {ObjectModel.procedural("box", 3).mesh_hash,
                                                 ObjectModel.procedural("ellipsoid", 7).mesh_hash}


def test_procedural_objects_made_on_another_cpu_load_by_geometry_not_by_last_bits(tmp_path):
    """A procedural object's vertices once depended on the CPU's NumPy kernels in the last bit, so the
    committed manifests carry hashes this machine may not reproduce: a procedural entry whose hash
    differs but whose faces, extents and volume agree (1e-9 relative) is the same object; a real mesh
    is still held to its hash, and a procedural entry of other geometry is refused."""
    from ohra.learn.grasp.data import load_dataset_object

    obj = ObjectModel.procedural("superquadric", 5)
    desc = obj.describe()
    info = {k: desc[k] for k in ("source", "faces", "extents_m", "volume_m3")} | {"mesh_hash": "0" * 16}
    assert load_dataset_object(tmp_path, "superquadric-5", info, {}).mesh_hash == obj.mesh_hash
    legacy = dict(info, source="builtin")  # datasets before sources named procedural shapes
    assert load_dataset_object(tmp_path, "superquadric-5", legacy, {}).name == "superquadric-5"
    for key, value in [("volume_m3", info["volume_m3"] * (1 + 1e-6)), ("faces", info["faces"] + 2),
                       ("extents_m", [info["extents_m"][0] * (1 + 1e-6), *info["extents_m"][1:]])]:
        with pytest.raises(DatasetError, match="has mesh hash"):
            load_dataset_object(tmp_path, "superquadric-5", dict(info, **{key: value}), {})
    sphere = ObjectModel.builtin("sphere").describe()
    with pytest.raises(DatasetError, match="has mesh hash"):
        load_dataset_object(tmp_path, "sphere", {k: sphere[k] for k in ("source", "faces", "extents_m", "volume_m3")}
                            | {"mesh_hash": "0" * 16}, {})


def test_check_disjoint_raises_on_overlap():
    check_disjoint({"box": "aa"}, {"sphere": "bb"})
    with pytest.raises(DatasetError, match="names \\['box'\\]"):
        check_disjoint({"box": "aa"}, {"box": "cc"})
    with pytest.raises(DatasetError, match="mesh hashes \\['aa'\\]"):
        check_disjoint({"box": "aa"}, {"cube": "aa"})


def test_model_records_its_split_and_refuses_seen_objects(dataset):
    model = train_grasp(dataset, tiny_model_config(), tiny_train_config(steps=1), progress=False).model
    assert set(model.meta["train_objects"]) == {"sphere", "box", "cylinder"}
    assert set(model.meta["test_objects"]) == {"capsule"}
    check_unseen(model, [ObjectModel.builtin("capsule")])
    with pytest.raises(DatasetError, match="training set"):
        check_unseen(model, [ObjectModel.builtin("box")])


def test_bad_data_raise(tmp_path, dataset):
    with pytest.raises(DatasetError, match="no manifest"):
        TrainingData.load(tmp_path, tiny_train_config())
    with pytest.raises(DatasetError, match="no_such_hand"):
        TrainingData.load(dataset, tiny_train_config(hands=("barrett_hand", "no_such_hand")))
    with pytest.raises(DatasetError, match=r"no training grasps left after holding out the test objects \['box'"):
        TrainingData.load(dataset, tiny_train_config(test_objects=("sphere", "box", "cylinder", "capsule")))
    with pytest.raises(DatasetError, match=r"after holding out the test objects \['capsule'\] and the test hands \["):
        TrainingData.load(dataset, tiny_train_config(test_hands=("allegro_hand_left", "barrett_hand", "shadow_hand_right")))


def test_a_test_object_in_no_dataset_is_warned_about_by_the_library(dataset):
    """A misspelt test object would let the object meant be trained on: the library says so, not only the CLI."""
    from ohra.errors import ObjectWarning

    with pytest.warns(ObjectWarning, match=r"test object\(s\) capsuel are in none of the datasets"):
        td = TrainingData.load(dataset, tiny_train_config(test_objects=("capsule", "capsuel")))
    assert "capsule" not in {o.name for o in td.objects}
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error", ObjectWarning)
        TrainingData.load(dataset, tiny_train_config(test_objects=("capsule",)))


def test_batches_are_robot_balanced_and_deterministic(tmp_path):
    root = write_dataset(tmp_path, objects=("sphere", "box"), counts={"allegro_hand_left": 60, "barrett_hand": 3,
                                                                      "shadow_hand_right": 6})
    cfg = tiny_train_config(batch_size=3000, test_objects=())
    td = TrainingData.load(root, cfg)
    assert np.bincount(td.hand_idx).tolist() == [120, 6, 12]
    b = make_batch(td, cfg, 16, 0, *_tables(td), t_scale=1.0)
    frac = np.bincount(b.present.sum(1).numpy())  # hands differ in their number of present joints
    assert sorted(frac[frac > 0] / 3000) == pytest.approx([1 / 3] * 3, abs=0.04)
    b2 = make_batch(td, cfg, 16, 0, *_tables(td), t_scale=1.0)
    assert torch.equal(b.t_norm, b2.t_norm) and torch.equal(b.clouds, b2.clouds)
    assert not torch.equal(make_batch(td, cfg, 16, 1, *_tables(td), t_scale=1.0).t_norm, b.t_norm)
    one = replace(cfg, batch_size=64, objects_per_step=1)
    for step in range(4):  # a pool of one object per step: one cloud, still every hand
        b = make_batch(td, one, 16, step, *_tables(td), t_scale=1.0)
        assert len(b.clouds) == 1 and len(np.unique(b.present.sum(1).numpy())) == 3


def test_condition_noise_perturbs_each_row_and_nothing_else(tmp_path):
    root = write_dataset(tmp_path, objects=("sphere", "box"))
    cfg = tiny_train_config(batch_size=512, test_objects=())
    td = TrainingData.load(root, cfg)
    plain = make_batch(td, cfg, 16, 3, *_tables(td), t_scale=1.0)
    noisy = make_batch(td, replace(cfg, condition_noise=0.25), 16, 3, *_tables(td), t_scale=1.0)
    assert torch.equal(plain.t_norm, noisy.t_norm) and torch.equal(plain.clouds, noisy.clouds)  # same rows and clouds
    assert torch.equal(plain.generator.get_state(), noisy.generator.get_state())  # same diffusion noise
    assert torch.equal(plain.hand, torch.zeros_like(plain.hand))
    d = noisy.hand - plain.hand
    assert float(d.std()) == pytest.approx(0.25, rel=0.05) and len(torch.unique(d[:, 0])) == len(d)  # one draw per row
    again = make_batch(td, replace(cfg, condition_noise=0.25), 16, 3, *_tables(td), t_scale=1.0)
    assert torch.equal(again.hand, noisy.hand)
    with pytest.raises(GraspConfigError, match="condition_noise"):
        replace(cfg, condition_noise=-0.1)


def test_objects_are_encoded_once_per_copy_and_rotated_with_their_grasps(tmp_path):
    """Each distinct object appears rotated_copies times in a batch; its points seen from the palm
    frame are those of the unrotated object (cloud and grasp turned by the same rotation)."""
    root = write_dataset(tmp_path, objects=("box", "cylinder"))
    cfg = tiny_train_config(batch_size=40, rotated_copies=2, point_noise=0.0, test_objects=())
    td = TrainingData.load(root, cfg)
    b = make_batch(td, cfg, 32, 3, *_tables(td), t_scale=1.0)
    assert b.clouds.shape == (4, 32, 3) and b.cloud_idx.max() <= 3
    for r in range(0, 40, 7):
        t, R = b.t_norm[r].double().numpy(), rot6d_to_matrix(b.rot6d[r].double().numpy())
        local = (b.clouds[b.cloud_idx[r]].double().numpy() - t) @ R  # cloud in the palm frame
        # the same grasp unrotated: find it among the data by its joints
        i = int(np.flatnonzero(np.all(np.abs(td.q - b.q[r].double().numpy()) < 1e-6, axis=1))[0])
        R0 = rot6d_to_matrix(td.rot6d[i])
        pool_local = (td.surface[td.obj_idx[i]].astype(float) - td.t[i]) @ R0
        d = np.linalg.norm(local[:, None] - pool_local[None], axis=2).min(axis=1)
        assert d.max() < 1e-5


def test_learning_rate_is_cosine():
    cfg = tiny_train_config(steps=100, lr=1e-3, lr_min=1e-5)
    assert learning_rate(cfg, 0) == pytest.approx(1e-3)
    assert learning_rate(cfg, 50) == pytest.approx(0.5 * (1e-3 + 1e-5))
    assert learning_rate(cfg, 100) == pytest.approx(1e-5)


# -- training ----------------------------------------------------------------------------------------
def test_training_twice_gives_the_same_losses_and_weights(dataset):
    a = train_grasp(dataset, tiny_model_config(), tiny_train_config(), progress=False)
    b = train_grasp(dataset, tiny_model_config(), tiny_train_config(), progress=False)
    assert [h["total"] for h in a.metrics["history"]] == [h["total"] for h in b.metrics["history"]]
    for (k, v), w in zip(a.model.net.state_dict().items(), b.model.net.state_dict().values()):
        assert torch.equal(v, w), k
    c = train_grasp(dataset, tiny_model_config(), tiny_train_config(seed=1), progress=False)
    assert c.metrics["history"][-1]["total"] != a.metrics["history"][-1]["total"]


def test_training_reduces_the_loss(dataset):
    res = train_grasp(dataset, tiny_model_config(), tiny_train_config(steps=60, log_every=10, lr=3e-3), progress=False)
    h = res.metrics["history"]
    assert h[-1]["total"] < 0.7 * h[0]["total"]
    assert set(res.metrics["heldout_losses"]) == {f"{h}/capsule" for h in HANDS}


class _Stop(Exception):
    pass


def test_resume_equals_an_uninterrupted_run(dataset, tmp_path):
    full = train_grasp(dataset, tiny_model_config(), tiny_train_config(), tmp_path / "full", progress=False)

    def stop(step, _):
        if step == 4:  # after the checkpoint at step 3, before the one at 6
            raise _Stop

    with pytest.raises(_Stop):
        train_grasp(dataset, tiny_model_config(), tiny_train_config(), tmp_path / "cut", progress=False, on_step=stop)
    with pytest.warns(UserWarning, match=r"checkpoint at step 3 of 6 \(the run has not finished"):
        load_grasp_model(tmp_path / "cut")  # no model.pt yet: it samples from the checkpoint, and says so
    resumed = train_grasp(dataset, tiny_model_config(), tiny_train_config(), tmp_path / "cut", resume=True, progress=False)
    assert resumed.metrics["history"] == [{**h, "elapsed_s": r["elapsed_s"]} for h, r in
                                          zip(full.metrics["history"], resumed.metrics["history"])]
    for (k, v), w in zip(full.model.net.state_dict().items(), resumed.model.net.state_dict().values()):
        assert torch.equal(v, w), k
    # the run directory holds what it says; a folder named twice is recorded once (it is read once)
    run = tmp_path / "full"
    assert json.loads((run / "config.json").read_text())["train"]["steps"] == 6
    twice = train_grasp([dataset, Path(f"{dataset}/")], tiny_model_config(), tiny_train_config(steps=1), tmp_path / "twice",
                        progress=False)
    assert json.loads((tmp_path / "twice" / "config.json").read_text())["data"] == [str(dataset)]
    assert twice.metrics["data"] == train_grasp(dataset, tiny_model_config(), tiny_train_config(steps=1), progress=False).metrics["data"]
    assert json.loads((run / "metrics.json").read_text())["steps"] == 6
    a = load_grasp_model(run).sample("barrett_hand", "builtin:capsule", 4, seed=0)
    np.testing.assert_array_equal(a, full.model.sample("barrett_hand", "builtin:capsule", 4, seed=0))
    # a longer run continues from the finished one
    longer = train_grasp(dataset, tiny_model_config(), tiny_train_config(steps=8), run, resume=True, progress=False)
    assert longer.metrics["history"][-1]["step"] == 8


@pytest.mark.parametrize("signum, ends_with", [("SIGINT", KeyboardInterrupt), ("SIGTERM", _Stop)])
def test_ctrl_c_saves_the_step_it_stopped_at_and_the_resume_equals_an_uninterrupted_run(dataset, tmp_path, signum, ends_with,
                                                                                          terminal_sigint):
    """Ctrl-C (or a scheduler's SIGTERM) between two checkpoints loses no step: the trainer finishes the step,
    checkpoints it, then stops as the signal would have (KeyboardInterrupt; SIGTERM's own handler)."""
    import os
    import signal

    full = train_grasp(dataset, tiny_model_config(), tiny_train_config(), tmp_path / "full", progress=False)

    def terminated(*_):  # stands in for SIGTERM's default end
        raise _Stop

    def interrupt(step, _):
        if step == 4:  # after the checkpoint at step 3, before the one at 6
            os.kill(os.getpid(), getattr(signal, signum))

    previous = signal.signal(signal.SIGTERM, terminated)
    try:
        with pytest.raises(ends_with):
            train_grasp(dataset, tiny_model_config(), tiny_train_config(), tmp_path / "cut", progress=False, on_step=interrupt)
        assert signal.getsignal(signal.SIGTERM) is terminated  # the handlers are put back
    finally:
        signal.signal(signal.SIGTERM, previous)
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    assert torch.load(tmp_path / "cut" / "checkpoints" / "last.pt", weights_only=False)["step"] == 4
    resumed = train_grasp(dataset, tiny_model_config(), tiny_train_config(), tmp_path / "cut", resume=True, progress=False)
    assert [h["step"] for h in resumed.metrics["history"]] == [h["step"] for h in full.metrics["history"]]
    for (k, v), w in zip(full.model.net.state_dict().items(), resumed.model.net.state_dict().values()):
        assert torch.equal(v, w), k


def test_a_resume_with_no_step_left_keeps_the_training_time(dataset, tmp_path):
    first = train_grasp(dataset, tiny_model_config(), tiny_train_config(), tmp_path / "r", progress=False).metrics
    again = train_grasp(dataset, tiny_model_config(), tiny_train_config(), tmp_path / "r", resume=True, progress=False).metrics
    assert again["steps_this_run"] == 0
    assert again["train_seconds_total"] == first["train_seconds_total"] == first["history"][-1]["elapsed_s"]
    assert again["train_seconds_this_run"] == 0.0
    # both to the last step (this run's seconds counted the final checkpoint too: 4.34 s against a total of 4.32 s)
    assert 0 < first["train_seconds_this_run"] <= first["train_seconds_total"]


def test_a_run_another_process_is_training_is_refused_and_left_alone(dataset, tmp_path):
    """Two processes resuming one run would interleave its checkpoints: the second fails at once."""
    import subprocess
    import sys

    from ohra.errors import FolderInUseError

    run = tmp_path / "run"
    train_grasp(dataset, tiny_model_config(), tiny_train_config(steps=2), run, progress=False)
    before = (run / "checkpoints" / "last.pt").read_bytes()
    hold = "import sys, time\nfrom ohra.io import folder_lock\nwith folder_lock(sys.argv[1]):\n    print('held', flush=True); time.sleep(120)"
    p = subprocess.Popen([sys.executable, "-c", hold, str(run)], stdout=subprocess.PIPE, text=True)
    try:
        assert p.stdout.readline().strip() == "held"
        with pytest.raises(FolderInUseError, match=f"pid {p.pid}.*grasp training run"):
            train_grasp(dataset, tiny_model_config(), tiny_train_config(steps=4), run, resume=True, progress=False)
    finally:
        p.kill()
        p.wait()
    assert (run / "checkpoints" / "last.pt").read_bytes() == before
    assert train_grasp(dataset, tiny_model_config(), tiny_train_config(steps=4), run, resume=True, progress=False).metrics["steps"] == 4


def test_resume_refuses_other_settings_or_data(dataset, tmp_path):
    train_grasp(dataset, tiny_model_config(), tiny_train_config(), tmp_path, progress=False)
    with pytest.raises(CheckpointError, match="batch_size"):
        train_grasp(dataset, tiny_model_config(), tiny_train_config(batch_size=8), tmp_path, resume=True, progress=False)
    with pytest.raises(CheckpointError, match="model was made with object_dim=32, this run asks for 16"):
        train_grasp(dataset, tiny_model_config(object_dim=16), tiny_train_config(), tmp_path, resume=True, progress=False)
    other = write_dataset(tmp_path / "other", seed=1)  # same hands and objects, other grasps
    with pytest.raises(CheckpointError, match="data differ"):
        train_grasp(other, tiny_model_config(), tiny_train_config(), tmp_path, resume=True, progress=False)
    with pytest.raises(CheckpointError, match="not found"):
        train_grasp(dataset, tiny_model_config(), tiny_train_config(), tmp_path / "none", resume=True, progress=False)


@pytest.mark.parametrize("kwargs, message", [
    (dict(steps=2.5), "steps: expected a whole number, got 2.5"),
    (dict(steps=True), "steps: expected a whole number, got True"),
    (dict(steps="10"), "steps: expected a whole number, got '10'"),
    (dict(lr=float("inf")), "lr: expected a finite number, got inf"),
    (dict(lr=1e-3, lr_min=1.1e-3), r"lr_min \(0.0011\) exceeds lr \(0.001\)"),
    (dict(point_noise=float("nan")), "point_noise: expected a finite number"),
    (dict(test_objects="capsule"), "test_objects: expected a tuple of names, got 'capsule'"),
    (dict(hands="barrett_hand"), "hands: expected a tuple of names"),
    (dict(device="cuda:00"), "device: expected"),
    (dict(device=torch.device("cpu")), r"device: expected .* \(a string\)"),
])
def test_training_settings_that_are_not_what_they_claim_are_refused_when_made(kwargs, message):
    """A bare string of test objects was read letter by letter (the object meant to be held out was trained on);
    floats, bools and numeric strings passed int(); an infinite learning rate trained to NaN."""
    with pytest.raises(GraspConfigError, match=message):
        tiny_train_config(**kwargs)


def test_the_edges_of_the_training_settings_are_accepted():
    assert tiny_train_config(steps=np.int64(3), lr=1e-3, lr_min=1e-3, max_per_pair=0).steps == 3


@pytest.mark.parametrize("kwargs, message", [
    (dict(encoder_channels=(16, 0)), r"encoder_channels\[1\] must be >= 1, got 0"),
    (dict(denoiser_hidden=(64, -5)), r"denoiser_hidden\[1\] must be >= 1"),
    (dict(joint_blocks=-1), "joint_blocks must be >= 0, got -1"),
    (dict(n_points=2.5), "n_points: expected a whole number"),
    (dict(object_dim=2**40), "object_dim must be <= 65,536, got 1,099,511,627,776"),  # was torch's allocation traceback
    (dict(denoiser_hidden=(512, 65537)), r"denoiser_hidden\[1\] must be <= 65,536"),
])
def test_model_settings_with_empty_layers_are_refused(kwargs, message):
    with pytest.raises(GraspConfigError, match=message):
        tiny_model_config(**kwargs)
    assert tiny_model_config(joint_blocks=0).joint_blocks == 0  # no residual blocks: a valid network


def test_a_diverging_run_stops_and_a_model_with_broken_weights_refuses_to_sample(dataset, tmp_path):
    run = tmp_path / "diverged"
    with pytest.raises(GraspError, match=r"training diverged at step \d+: loss nan"):
        train_grasp(dataset, tiny_model_config(), tiny_train_config(lr=1e6, lr_min=0.0), run, progress=False)
    assert not (run / "model.pt").exists()
    model = train_grasp(dataset, tiny_model_config(), tiny_train_config(steps=1), progress=False).model
    with torch.no_grad():
        next(model.net.joints.parameters()).fill_(float("nan"))
    with pytest.raises(CheckpointError, match="computes non-finite grasps"):
        model.sample("barrett_hand", "builtin:capsule", 2, seed=0)


def test_a_run_directory_holding_a_run_is_not_trained_over(dataset, tmp_path):
    train_grasp(dataset, tiny_model_config(), tiny_train_config(steps=2), tmp_path, progress=False)
    before = (tmp_path / "checkpoints" / "last.pt").read_bytes()
    with pytest.raises(CheckpointError, match="already holds a training run.*resume=True"):
        train_grasp(dataset, tiny_model_config(), tiny_train_config(steps=2), tmp_path, progress=False)
    assert (tmp_path / "checkpoints" / "last.pt").read_bytes() == before


# -- devices -----------------------------------------------------------------------------------------
def test_a_device_is_checked_when_the_settings_are_made_and_when_training_starts(dataset):
    with pytest.raises(GraspConfigError, match=r"device: expected 'cpu', 'cuda', 'cuda:N' or 'mps' \(a string\), got 'gpu'"):
        tiny_train_config(device="gpu")
    with pytest.raises(GraspConfigError, match="penetration and contact terms run on the CPU only"):
        tiny_train_config(device="cuda", penetration_weight=1.0)
    if not torch.cuda.is_available():
        with pytest.raises(GraspConfigError, match="device 'cuda': this torch .* sees no CUDA GPU"):
            train_grasp(dataset, tiny_model_config(), tiny_train_config(device="cuda"), progress=False)


@pytest.mark.parametrize("encoder", ["pointnet", "dgcnn"])
def test_a_training_step_runs_whole_on_another_device_with_the_cpu_drawn_batch(dataset, encoder):
    """Every tensor of a step follows the batch to the network's device (checked on torch's 'meta'
    device, which needs no GPU: a tensor left on the CPU fails there as it would on CUDA); the batch
    and its diffusion noise are drawn on the CPU, so they are the same on every device."""
    from ohra.learn.grasp.model import GraspNet
    from ohra.learn.grasp.train import train_step

    td = TrainingData.load([dataset], tiny_train_config(), None)
    batch = make_batch(td, tiny_train_config(), 16, 0, *_tables(td), 0.1)
    assert batch.to("cpu") is batch
    moved = batch.to("meta")
    tensors = [f for f, v in vars(batch).items() if isinstance(v, torch.Tensor)]
    assert len(tensors) == 12 and all(getattr(moved, f).device.type == "meta" for f in tensors)
    assert moved.generator is batch.generator
    net = GraspNet(tiny_model_config(encoder=encoder, dgcnn_k=4), 4).to("meta")
    terms = train_step(net, moved, 1.0)
    assert set(terms) == {"diffusion", "joints", "total"} and all(t.device.type == "meta" for t in terms.values())


# -- evaluation --------------------------------------------------------------------------------------
def test_diversity_measures():
    g = np.zeros((4, 31))
    g[:, 3], g[:, 7] = 1.0, 1.0  # identity rotations
    g[:, :3] = [0.1, 0.0, 0.0]
    d = diversity(g, np.ones(22, bool))
    assert d["approach_spread"] == pytest.approx(0.0) and d["joint_std_rad"] == 0.0
    g[2:, :3] = [-0.1, 0.0, 0.0]
    g[:, 9] = [0.0, 1.0, 0.0, 1.0]
    d = diversity(g, np.ones(22, bool))
    assert d["approach_spread"] == pytest.approx(1.0)
    assert d["joint_std_rad"] == pytest.approx(0.5 / 22)
    assert diversity(g[:1], np.ones(22, bool)) is None


def test_evaluate_model_runs_the_protocol(dataset):
    model = train_grasp(dataset, tiny_model_config(), tiny_train_config(steps=2), progress=False).model
    rep = evaluate_model(model, ["barrett_hand"], ["builtin:capsule"], n=2, seed=5)
    (p,) = rep.pairs
    assert p.success.shape == (2,) and p.grasps.shape == (2, 31) and p.sim_seconds > 0
    np.testing.assert_array_equal(p.grasps, model.sample("barrett_hand", "builtin:capsule", 2,
                                                         seed=pair_seed(5, "barrett_hand", p.object_hash)))
    d = rep.to_dict()
    assert d["per_hand"]["barrett_hand"]["n"] == 2 and d["pairs"][0]["diversity_all"] is not None
    with pytest.raises(DatasetError, match="training set"):
        evaluate_model(model, ["barrett_hand"], ["builtin:box"], n=1)


def test_original_replay_uses_the_same_grasps(dataset, hands_dir):
    model = train_grasp(dataset, tiny_model_config(), tiny_train_config(steps=1), progress=False).model
    can = evaluate_model(model, ["barrett_hand"], ["builtin:capsule"], n=2, seed=3)
    orig = evaluate_model(model, ["barrett_hand"], ["builtin:capsule"], n=2, seed=3, original=True)
    np.testing.assert_array_equal(can.pairs[0].grasps, orig.pairs[0].grasps)
    assert orig.pairs[0].original and orig.meta["original"]
    from ohra.canonical.params import BaseParams

    with pytest.raises(GraspError, match="by name"):
        evaluate_model(model, [BaseParams.from_vector(get_hand("barrett_hand").to_vector())], ["builtin:capsule"], n=1,
                       original=True)


def test_a_hand_the_model_cannot_condition_on_fails_before_any_simulation(dataset, monkeypatch):
    model = train_grasp(dataset, tiny_model_config(), tiny_train_config(steps=1), progress=False).model
    assert model.condition.kind == "vae"  # the VAE reads base-form hands only; LEAP variants have none

    def no_sim(*args, **kwargs):
        raise AssertionError("a simulation started before every hand was checked")

    import ohra.sim

    monkeypatch.setattr(ohra.sim, "GraspEvaluator", no_sim)
    with pytest.raises(ParamsError, match="hand 'leap_2211'.*base form"):
        evaluate_model(model, ["barrett_hand", "leap_2211"], ["builtin:capsule"], n=1)
    with pytest.raises(ParamsError, match="hand 'leap_3333'"):
        evaluate_model(model, ["barrett_hand"], ["builtin:capsule"], n=1, condition_hand="leap_3333")


class _RecordingEvaluator:
    """Stands in for ohra.sim.GraspEvaluator: every grasp succeeds, the simulated hands are recorded."""

    hands: list = []

    def __init__(self, hand, obj, protocol=None):
        type(self).hands.append(hand.name)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def evaluate(self, grasps, workers=1, progress=False):
        from types import SimpleNamespace

        return SimpleNamespace(success=np.ones(len(grasps), bool))


def test_workers_below_one_are_refused_before_any_sampling_or_simulation(dataset, monkeypatch):
    model = train_grasp(dataset, tiny_model_config(), tiny_train_config(steps=1), progress=False).model

    def must_not_run(*args, **kwargs):
        raise AssertionError("a pair was sampled or simulated before workers was checked")

    import ohra.sim

    monkeypatch.setattr(ohra.sim, "GraspEvaluator", must_not_run)
    monkeypatch.setattr(model, "sample", must_not_run)
    for workers in (0, -1, 1.5, True):
        with pytest.raises(GraspError, match=rf"workers must be an integer >= 1, got {workers!r}"):
            evaluate_model(model, ["barrett_hand"], ["builtin:capsule"], n=1, workers=workers)


def test_hands_given_as_params_keep_apart_in_the_report(dataset, monkeypatch):
    """A hand given as params has no name: it is labelled by its content hash (``hand_key``, as
    ``meta["condition_hand"]`` names one), so two such hands are two rows of ``per_hand`` (they were
    both "hand", pooled); the label, and so the pair's seed, does not depend on the hand's place in the
    list; a name keeps its name."""
    from ohra.learn.grasp.condition import hand_key
    from ohra.learn.grasp.evaluate import hand_label

    import ohra.sim

    model = train_grasp(dataset, tiny_model_config(), tiny_train_config(steps=1), progress=False).model
    monkeypatch.setattr(ohra.sim, "GraspEvaluator", _RecordingEvaluator)
    monkeypatch.setattr(_RecordingEvaluator, "hands", [])
    a, b = get_hand("barrett_hand"), get_hand("shadow_hand_right")
    rep = evaluate_model(model, [a, b, "allegro_hand_left"], ["builtin:capsule"], n=2, seed=5)
    labels = [hand_key(a), hand_key(b), "allegro_hand_left"]
    assert [p.hand for p in rep.pairs] == labels == _RecordingEvaluator.hands
    assert list(rep.per_hand()) == labels and all(r["n"] == 2 for r in rep.per_hand().values())
    assert [p["hand"] for p in json.loads(rep.to_json())["pairs"]] == labels
    alone = evaluate_model(model, [b], ["builtin:capsule"], n=2, seed=5)
    assert alone.pairs[0].hand == labels[1] and alone.pairs[0].seed == rep.pairs[1].seed
    np.testing.assert_array_equal(alone.pairs[0].grasps, rep.pairs[1].grasps)
    assert hand_label(dataset / "x" / "params.json", a) == str(dataset / "x" / "params.json")  # a path: all of it


# -- CLI ------------------------------------------------------------------------------------------------
@pytest.fixture
def cli():
    main_mod = importlib.import_module("ohra.cli.main")
    assert "grasp" in main_mod.COMMANDS  # registered like every other command group
    return main_mod.main


def test_cli_train_sample_and_errors(cli, dataset, tmp_path, capsys):
    run = tmp_path / "run"
    args = ["train", "grasp", "--data", str(dataset), "--test-objects", "capsule", "--steps", "2", "--batch-size", "8",
            "-o", str(run), "--quiet"]
    assert cli(args) == 0
    captured = capsys.readouterr()
    assert "trained 2 steps" in captured.out and "note" not in captured.err  # capsule is in the data: held out
    typo = ["train", "grasp", "--data", str(dataset), "--test-objects", "capsule", "capsuel", "--steps", "1",
            "--batch-size", "8", "-o", str(tmp_path / "typo"), "--quiet"]
    assert cli(typo) == 0
    assert "test object(s) capsuel are in none of the datasets" in capsys.readouterr().err
    absent_hand = ["train", "grasp", "--data", str(dataset), "--hands", "barrett_hand", "shadow_hand_right", "--test-hands",
                   "leap_1111", "--steps", "1", "--batch-size", "8", "-o", str(tmp_path / "th"), "--quiet"]
    assert cli(absent_hand) == 0
    assert "test hand(s) leap_1111 are in none of the datasets by name" in capsys.readouterr().err
    assert cli(args) == 2  # already a run there
    assert "--resume" in capsys.readouterr().err
    out = tmp_path / "g.npz"
    assert cli(["grasp", "sample", "--model", str(run), "--hand", "barrett_hand", "--object", "builtin:capsule",
                "-n", "5", "-o", str(out)]) == 0
    with np.load(out) as z:
        assert z["grasps"].shape == (5, 31)
    assert cli(["grasp", "sample", "--model", str(run), "--hand", "nope", "--object", "builtin:capsule", "-o", str(out)]) == 2
    assert "nope" in capsys.readouterr().err
    assert cli(["grasp", "eval", "--model", str(run), "--hands", "barrett_hand", "--objects", "builtin:box", "-n", "1"]) == 2
    assert "training set" in capsys.readouterr().err
    assert cli(["train", "grasp", "--data", str(tmp_path / "none"), "-o", str(tmp_path / "r2"), "--quiet"]) == 2
    if not torch.cuda.is_available():  # a device this machine lacks: one line, before any data is read
        assert cli(["train", "grasp", "--data", str(tmp_path / "none"), "--device", "cuda", "-o", str(tmp_path / "r3"), "--quiet"]) == 2
        assert "sees no CUDA GPU" in capsys.readouterr().err


def test_cli_names_a_millimetre_mesh_takes_scale_and_expands_object_folders(cli, dataset, tmp_path, capsys):
    run = tmp_path / "run"
    assert cli(["train", "grasp", "--data", str(dataset), "--steps", "1", "--batch-size", "8", "-o", str(run), "--quiet"]) == 0
    capsys.readouterr()
    folder = tmp_path / "meshes"
    folder.mkdir()
    # shapes the model never saw (the built-in sphere and cylinder are training objects: refused as such when re-exported)
    ObjectModel.procedural("ellipsoid", 901).mesh.apply_scale(1000.0).export(folder / "ball_mm.stl")
    ObjectModel.procedural("cylinder", 902).mesh.apply_scale(1000.0).export(folder / "can_mm.stl")
    out = tmp_path / "g.npz"
    sample = ["grasp", "sample", "--model", str(run), "--hand", "barrett_hand", "--object", str(folder / "ball_mm.stl"),
              "-n", "2", "-o", str(out)]
    assert cli(sample) == 0
    assert "ohra: warning: object 'ball_mm'" in (err := capsys.readouterr().err) and "--scale 0.001" in err
    assert cli([*sample, "--scale", "0.001"]) == 0
    assert "warning" not in capsys.readouterr().err
    report = tmp_path / "r.json"
    assert cli(["grasp", "eval", "--model", str(run), "--hands", "barrett_hand", "--objects", str(folder), "--scale", "0.001",
                "-n", "1", "--quiet", "-o", str(report)]) == 0
    assert sorted(p["object"] for p in json.loads(report.read_text())["pairs"]) == ["ball_mm", "can_mm"]


def test_a_dataset_made_on_another_machine_finds_its_mesh_under_this_object_root(tmp_path, monkeypatch):
    """Manifests store absolute mesh paths; moved to another machine, the same trailing path under
    OHRA_OBJECTS_ROOT is used (the mesh hash still has to match)."""
    import shutil

    from ohra.learn.grasp.data import load_dataset_object

    here = tmp_path / "objects" / "ycb" / "Ball"
    here.mkdir(parents=True)
    ObjectModel.builtin("sphere").mesh.export(here / "mesh.stl")
    obj = ObjectModel.load(here / "mesh.stl", name="Ball")
    info = {"source": "/elsewhere/shared/objects/ycb/Ball/mesh.stl", "mesh_hash": obj.mesh_hash}
    monkeypatch.setenv("OHRA_OBJECTS_ROOT", str(tmp_path / "objects"))
    assert load_dataset_object(tmp_path, "Ball", info, {}).mesh_hash == obj.mesh_hash
    shutil.rmtree(tmp_path / "objects")
    with pytest.raises(DatasetError, match="cannot load training object 'Ball'"):
        load_dataset_object(tmp_path, "Ball", info, {})


def test_a_vae_condition_on_hands_without_a_base_form_names_the_hand_and_the_training_option(tmp_path):
    root = write_dataset(tmp_path / "d", hands=("barrett_hand", "leap_2211"), objects=("box", "capsule"))
    with pytest.raises(GraspConfigError, match=r"training hand 'leap_2211' cannot be vae-conditioned .*--condition params"):
        train_grasp(root, tiny_model_config(condition="vae"), tiny_train_config(steps=1), progress=False)


def test_a_misspelt_hand_is_named_before_torch_is_imported(tmp_path):
    """``ohra grasp sample --hand TYPO`` answered after ~5 s of torch imports; the hand is read first."""
    import subprocess
    import sys

    code = ("import sys; from ohra.cli.main import main; "
            f"rc = main(['grasp', 'sample', '--hand', 'TYPO', '--object', 'builtin:box', '-o', {str(tmp_path / 'g.npz')!r}]); "
            "print(rc, 'torch' in sys.modules)")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.stdout.split() == ["2", "False"], proc.stderr
    assert "unknown hand 'TYPO'" in proc.stderr
