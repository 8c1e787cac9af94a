"""The grasp model with diffused joints (``GraspModelConfig.diffuse_joints``): the 22 joints denoised with the
wrist translation, standardised by the training data's per-joint statistics, in place of the joint network."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from grasp_fixtures import tiny_model_config, tiny_train_config, write_dataset  # noqa: E402

from ohra.errors import GraspError  # noqa: E402
from ohra.hands import get_hand  # noqa: E402
from ohra.learn.grasp.config import GraspConfigError, GraspModelConfig  # noqa: E402
from ohra.learn.grasp.data import TrainingData  # noqa: E402
from ohra.learn.grasp.model import GraspNet, load_grasp_model  # noqa: E402
from ohra.learn.grasp.train import train_grasp  # noqa: E402
from ohra.learn.train_vae import atomic_save, load_torch_file  # noqa: E402


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    return write_dataset(tmp_path_factory.mktemp("grasps"))


@pytest.fixture(scope="module")
def run(dataset, tmp_path_factory):
    folder = tmp_path_factory.mktemp("run_dq")
    res = train_grasp(dataset, tiny_model_config(diffuse_joints=True), tiny_train_config(), folder, progress=False)
    return res, folder


def test_the_option_is_a_boolean_and_off_by_default():
    assert GraspModelConfig().diffuse_joints is False
    with pytest.raises(GraspConfigError, match="diffuse_joints: expected True or False, got 'yes'"):
        GraspModelConfig(diffuse_joints="yes")
    assert GraspModelConfig.from_dict({"diffuse_joints": True}).diffuse_joints is True


def test_a_diffused_joint_model_has_no_joint_network_and_denoises_25_numbers():
    net = GraspNet(tiny_model_config(diffuse_joints=True), hand_dim=4)
    assert net.joints is None and net.denoiser.x_dim == 25
    assert {"q_mean", "q_std"} <= set(net.state_dict())
    default = GraspNet(tiny_model_config(), hand_dim=4)
    assert default.joints is not None and default.denoiser.x_dim == 3 and "q_mean" not in default.state_dict()


def test_joint_statistics_are_taken_over_the_rows_that_have_the_joint():
    net = GraspNet(tiny_model_config(diffuse_joints=True), hand_dim=4)
    q = np.zeros((4, 22))
    present = np.zeros((4, 22), dtype=bool)
    q[:, 0], present[:, 0] = [0.2, 0.4, 0.6, 9.0], [True, True, True, False]  # row 3 lacks joint 0: its 9.0 is padding
    q[:, 1], present[:, 1] = [0.5, 0.5, 0.5, 0.5], True  # never moves: the spread floor
    net.set_joint_statistics(q, present)
    assert net.q_mean[0].item() == pytest.approx(0.4)
    assert net.q_std[0].item() == pytest.approx(np.std([0.2, 0.4, 0.6]), rel=1e-6)
    assert net.q_mean[1].item() == pytest.approx(0.5) and net.q_std[1].item() == pytest.approx(0.05)
    assert net.q_mean[2].item() == 0.0 and net.q_std[2].item() == 1.0  # no row has it
    with pytest.raises(GraspError, match="joint network"):
        GraspNet(tiny_model_config(), hand_dim=4).set_joint_statistics(q, present)


def test_training_stores_the_statistics_of_its_own_data(run, dataset):
    res, _ = run
    td = TrainingData.load(dataset, tiny_train_config())
    present = np.stack([p.present_joints for p in td.params])[td.hand_idx]
    k = 13  # a joint some training hands lack (Allegro and Barrett have no little finger)
    assert not present[:, k].all() and present[:, k].any()
    want = td.q[present[:, k], k]
    assert res.model.net.q_mean[k].item() == pytest.approx(want.mean(), rel=1e-5)
    assert res.model.net.q_std[k].item() == pytest.approx(max(want.std(), 0.05), rel=1e-5)


def test_the_joint_loss_ignores_absent_joints_and_reads_the_diffused_estimate():
    torch.manual_seed(0)
    net = GraspNet(tiny_model_config(diffuse_joints=True), hand_dim=4)
    b = 8
    args = dict(obj_feat=torch.randn(b, 32), hand=torch.randn(b, 4), rot6d=torch.randn(b, 6), t_norm=torch.randn(b, 3))
    present = torch.ones(b, 22, dtype=torch.bool)
    present[:, 5] = False
    q = torch.randn(b, 22)
    base = net.losses(q=q, present=present, generator=torch.Generator().manual_seed(1), **args)
    q2 = q.clone()
    q2[:, 5] += 3.0  # an absent joint's value
    same = net.losses(q=q2, present=present, generator=torch.Generator().manual_seed(1), **args)
    assert same["joints"].item() == pytest.approx(base["joints"].item(), rel=1e-6)
    q3 = q.clone()
    q3[:, 4] += 3.0  # a present one
    other = net.losses(q=q3, present=present, generator=torch.Generator().manual_seed(1), **args)
    assert other["joints"].item() > base["joints"].item() + 0.05  # one of 21 joints 3 units off: ~ +0.1
    assert other["diffusion"].item() != base["diffusion"].item()  # the translation is denoised from the same noisy vector


def test_sampled_joints_are_the_denoised_ones_destandardised(run):
    """A denoiser that always predicts x0 = b gives translations b * t_scale and joints b * std + mean
    (clipped at ``clip_sample`` standard units) before the hand's limits."""
    res, _ = run
    net = res.model.net
    last = net.denoiser.body[-1]
    state = {k: v.clone() for k, v in last.state_dict().items()}
    bias = torch.linspace(-0.5, 0.5, 25)
    bias[4] = 9.0  # beyond the clip
    try:
        with torch.no_grad():
            last.weight.zero_()
            last.bias.copy_(bias)
            x, q = net.sample_grasp(torch.zeros(3, net.cond_dim), torch.Generator().manual_seed(0))
    finally:
        last.load_state_dict(state)
    np.testing.assert_allclose(x.numpy(), np.tile(bias[:3].numpy(), (3, 1)), rtol=1e-5)
    want = bias[3:].clamp(-4.0, 4.0) * net.q_std + net.q_mean
    np.testing.assert_allclose(q.numpy(), np.tile(want.numpy(), (3, 1)), rtol=1e-5, atol=1e-6)


def test_each_steps_joint_estimate_is_held_within_the_hands_limits_and_absent_joints_at_their_training_zero(run):
    """Given the hand's limits and present joints, every DDIM step's x0 estimate of a joint lies within the limits
    (in standard units) and an absent joint's is 0, the value training saw; the outputs for absent joints are never
    trained (masked loss), so left free they would feed untrained values into the next step."""
    res, _ = run
    net = res.model.net
    p = get_hand("barrett_hand")
    lower = torch.tensor(np.asarray(p.joint_lowers), dtype=torch.float32)
    upper = torch.tensor(np.asarray(p.joint_uppers), dtype=torch.float32)
    present = torch.from_numpy(np.asarray(p.present_joints, dtype=bool))
    last = net.denoiser.body[-1]
    state = {k: v.clone() for k, v in last.state_dict().items()}
    seen = []
    orig = net.scheduler.step

    def spy(x_t, x0, t, t_prev):
        seen.append(x0.clone())
        return orig(x_t, x0, t, t_prev)

    net.scheduler.step = spy
    try:
        with torch.no_grad():
            last.weight.zero_()
            last.bias.fill_(9.0)  # every estimate far beyond every limit
            x, q = net.sample_grasp(torch.zeros(2, net.cond_dim), torch.Generator().manual_seed(0), lower, upper, present)
    finally:
        last.load_state_dict(state)
        del net.scheduler.step
    up_std = (upper - net.q_mean) / net.q_std
    for x0 in seen:
        assert torch.all(x0[:, 3:][:, ~present] == 0.0)
        torch.testing.assert_close(x0[:, 3:][:, present], up_std[present].expand(2, -1))
    torch.testing.assert_close(q[:, present], upper[present].expand(2, -1))
    torch.testing.assert_close(q[:, ~present], net.q_mean[~present].expand(2, -1))  # 0 standard units (clamped to 0 later)


@pytest.mark.parametrize("value", [6.0, -6.0])
@pytest.mark.parametrize("hand", ["allegro_hand_left", "barrett_hand"])
def test_diffused_joints_are_clamped_to_the_hand_and_absent_ones_are_zero(run, hand, value):
    res, _ = run
    model = res.model
    last = model.net.denoiser.body[-1]
    state = {k: v.clone() for k, v in last.state_dict().items()}
    try:
        with torch.no_grad():
            last.bias[3:] = value  # 4 standard units off every mean: most joints beyond a limit
            g = model.sample(hand, "builtin:capsule", 8, seed=0, mirror=False)
    finally:
        last.load_state_dict(state)
    p = get_hand(hand)
    lo, up, absent = np.asarray(p.joint_lowers), np.asarray(p.joint_uppers), ~np.asarray(p.present_joints)
    q = g[:, 9:]
    assert np.all(q >= lo) and np.all(q <= up)
    assert absent.any() and np.all(q[:, absent] == 0.0)
    at_limit = np.isclose(q, up if value > 0 else lo, atol=1e-6)[:, np.asarray(p.movable_joints)]
    assert at_limit.mean() > 0.5


def test_a_saved_model_samples_identically_and_a_run_resumes(run, dataset, tmp_path):
    res, folder = run
    g = res.model.sample("shadow_hand_right", "builtin:capsule", 5, seed=4)
    assert g.shape == (5, 31) and np.all(np.isfinite(g))
    np.testing.assert_array_equal(load_grasp_model(folder).sample("shadow_hand_right", "builtin:capsule", 5, seed=4), g)
    ckpt_path = folder / "checkpoints" / "last.pt"
    ckpt = load_torch_file(ckpt_path, "ohra-grasp-checkpoint")
    ckpt["model"]["q_mean"] = torch.full((22,), 0.123)  # a sentinel: refitting on the same data would not keep it
    atomic_save(ckpt, ckpt_path)
    longer = train_grasp(dataset, tiny_model_config(diffuse_joints=True), tiny_train_config(steps=8), folder, resume=True,
                         progress=False)
    assert longer.metrics["history"][-1]["step"] == 8
    torch.testing.assert_close(longer.model.net.q_mean, torch.full((22,), 0.123))  # kept from the checkpoint, not refitted


def test_a_checkpoint_made_before_the_option_existed_resumes(dataset, tmp_path):
    """Runs trained before ``diffuse_joints`` was a setting store no such key: it reads as its default."""
    train_grasp(dataset, tiny_model_config(), tiny_train_config(), tmp_path / "old", progress=False)
    ckpt_path = tmp_path / "old" / "checkpoints" / "last.pt"
    ckpt = load_torch_file(ckpt_path, "ohra-grasp-checkpoint")
    del ckpt["spec"]["model"]["diffuse_joints"]
    atomic_save(ckpt, ckpt_path)
    res = train_grasp(dataset, tiny_model_config(), tiny_train_config(steps=8), tmp_path / "old", resume=True, progress=False)
    assert res.metrics["history"][-1]["step"] == 8
    from ohra.errors import CheckpointError

    with pytest.raises(CheckpointError, match="diffuse_joints=False, this run asks for True"):
        train_grasp(dataset, tiny_model_config(diffuse_joints=True), tiny_train_config(steps=9), tmp_path / "old", resume=True,
                    progress=False)


def test_the_finger_terms_need_a_joint_network(dataset):
    with pytest.raises(GraspConfigError, match="penetration and contact terms act on the joint network"):
        train_grasp(dataset, tiny_model_config(diffuse_joints=True), tiny_train_config(penetration_weight=1.0), progress=False)


def test_the_cli_trains_a_diffused_joint_model(dataset, tmp_path):
    from ohra.cli.main import main

    out = tmp_path / "cli_run"
    assert main(["train", "grasp", "--data", str(dataset), "--diffuse-joints", "--steps", "2", "--batch-size", "8",
                 "--test-objects", "capsule", "--quiet", "-o", str(out)]) == 0
    m = load_grasp_model(out)
    assert m.config.diffuse_joints and m.net.joints is None
