"""The grasp model: scheduler, encoders, conditions, sampling convention, joint limits, checkpoints."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from grasp_fixtures import tiny_model_config, tiny_train_config, write_dataset  # noqa: E402
from scipy.spatial.transform import Rotation  # noqa: E402

from ohra.errors import CheckpointError, GraspError, HandNotFoundError, ObjectError, OhraError, ParamsError  # noqa: E402
from ohra.hands import get_hand  # noqa: E402
from ohra.learn.grasp import GraspConfigError, GraspModelConfig  # noqa: E402
from ohra.learn.grasp.condition import PARAMS_DIM, HandCondition, params_vector  # noqa: E402
from ohra.learn.grasp.diffusion import DDIMScheduler, cosine_alphas_cumprod  # noqa: E402
from ohra.learn.grasp.encoder import DGCNNEncoder, PointNetEncoder  # noqa: E402
from ohra.learn.grasp.model import load_grasp_model  # noqa: E402
from ohra.learn.grasp.train import train_grasp  # noqa: E402
from ohra.objects.model import ObjectModel  # noqa: E402


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    return write_dataset(tmp_path_factory.mktemp("grasps"))


@pytest.fixture(scope="module")
def vae_model(dataset, tmp_path_factory):
    run = tmp_path_factory.mktemp("run_vae")
    return train_grasp(dataset, tiny_model_config(), tiny_train_config(), run, progress=False).model


@pytest.fixture(scope="module")
def params_model(dataset):
    return train_grasp(dataset, tiny_model_config(condition="params"), tiny_train_config(), progress=False).model


@pytest.fixture(scope="module")
def capsule():
    return ObjectModel.builtin("capsule")


# -- scheduler -------------------------------------------------------------------------------------
def test_schedule_is_squared_cosine_and_trailing():
    ab = cosine_alphas_cumprod(1000)
    assert ab[0] == pytest.approx(1.0, abs=1e-4) and ab[-1] < 1e-6
    assert np.all(np.diff(ab) < 0)
    assert DDIMScheduler(1000, 10).timesteps() == [999, 899, 799, 699, 599, 499, 399, 299, 199, 99]


def test_ddim_with_a_perfect_denoiser_returns_the_known_x0():
    s = DDIMScheduler(1000, 10)
    x0 = torch.tensor([[0.3, -1.2, 0.7], [2.0, 0.0, -0.5]])
    out = s.sample(lambda x, t: x0, (2, 3), torch.Generator().manual_seed(0))
    assert torch.allclose(out, x0, atol=1e-6)


def _gaussian_oracle(s: DDIMScheduler, mu: torch.Tensor, sd: float):
    """Exact E[x0 | x_t] for data ~ N(mu, sd^2 I)."""
    def predict(x, t):
        ab = float(s.alphas_cumprod[t])
        return mu + ab**0.5 * sd**2 / (ab * sd**2 + 1 - ab) * (x - ab**0.5 * mu)
    return predict


@pytest.mark.parametrize("steps, std_range", [(10, (0.8, 0.9)),
                                              pytest.param(1000, (0.98, 1.02), marks=pytest.mark.e2e)])  # ~3-6 s
def test_ddim_with_the_exact_denoiser_of_a_gaussian_recovers_it(steps, std_range):
    """The deterministic sampler maps noise onto N(mu, sd^2): the mean exactly, the spread up to the
    known shrinkage of a 10-step discretisation (a wrong update formula fails both)."""
    s = DDIMScheduler(1000, steps)
    mu, sd = torch.tensor([0.3, -0.6, 0.15]), 0.5
    x = s.sample(_gaussian_oracle(s, mu, sd), (20000, 3), torch.Generator().manual_seed(0))
    assert torch.allclose(x.mean(0), mu, atol=0.02)
    ratio = float(x.std(0).mean()) / sd
    assert std_range[0] < ratio < std_range[1]


def test_add_noise_matches_the_schedule():
    s = DDIMScheduler(1000, 10)
    x0, eps = torch.ones(3, 3), torch.zeros(3, 3)
    xt = s.add_noise(x0, eps, torch.tensor([0, 500, 999]))
    assert torch.allclose(xt[:, 0], s.alphas_cumprod[[0, 500, 999]].sqrt())


# -- encoders --------------------------------------------------------------------------------------
@pytest.mark.parametrize("enc", [PointNetEncoder((8, 16), 12), DGCNNEncoder((8, 16), 12, k=5)])
def test_encoders_are_permutation_invariant(enc):
    pts = torch.randn(2, 40, 3, generator=torch.Generator().manual_seed(0))
    f = enc(pts)
    assert f.shape == (2, 12)
    perm = torch.randperm(40, generator=torch.Generator().manual_seed(1))
    assert torch.allclose(enc(pts[:, perm]), f, atol=1e-5)
    assert not torch.allclose(enc(pts * 2.0), f)


def test_dgcnn_model_trains_and_samples(dataset):
    cfg = tiny_model_config(encoder="dgcnn", dgcnn_k=8)
    res = train_grasp(dataset, cfg, tiny_train_config(steps=2), progress=False)
    assert res.model.sample("barrett_hand", "builtin:capsule", 3).shape == (3, 31)


# -- sampling ----------------------------------------------------------------------------------------
def test_sample_shape_and_convention(vae_model, capsule):
    R = Rotation.random(5, random_state=3).as_matrix()
    g = vae_model.sample("allegro_hand_left", capsule, 5, rotations=R, seed=1)
    assert g.shape == (5, 31) and g.dtype == np.float64 and np.all(np.isfinite(g))
    np.testing.assert_allclose(g[:, 3:6], R[:, :, 0], atol=1e-12)
    np.testing.assert_allclose(g[:, 6:9], R[:, :, 1], atol=1e-12)
    # rot6d input gives the same grasps as matrices
    g6 = vae_model.sample("allegro_hand_left", capsule, 5, rotations=g[:, 3:9], seed=1)
    np.testing.assert_allclose(g6, g, atol=1e-6)
    # no rotations given: uniformly random ones, proper rotations
    from ohra.rotations import rot6d_to_matrix

    Rr = rot6d_to_matrix(vae_model.sample("allegro_hand_left", capsule, 200, seed=2)[:, 3:9])
    np.testing.assert_allclose(np.linalg.det(Rr), 1.0, atol=1e-6)
    assert np.abs(Rr[:, :, 0].mean(axis=0)).max() < 0.15  # palm normals spread over the sphere


def test_translations_are_denormalised(vae_model, capsule):
    """Palm positions come out in metres, on the scale of the training data (not unit-variance)."""
    last = vae_model.net.denoiser.body[-1]
    state = {k: v.clone() for k, v in last.state_dict().items()}
    try:
        with torch.no_grad():  # a denoiser that always predicts x0 = b (normalised units)
            last.weight.zero_()
            last.bias.copy_(torch.tensor([1.0, -2.0, 9.0]))
        g = vae_model.sample("barrett_hand", capsule, 4, seed=0)
    finally:
        last.load_state_dict(state)
    clip = vae_model.config.clip_sample
    np.testing.assert_allclose(g[:, :3], np.tile([1.0, -2.0, clip], (4, 1)) * vae_model.t_scale, rtol=1e-5)
    # RMS coordinate of the training palms: |t| = object radius + 3 cm, equal counts per object
    r_train = np.array([ObjectModel.builtin(o).radius + 0.03 for o in ("sphere", "box", "cylinder")])
    assert vae_model.t_scale == pytest.approx(np.sqrt(np.mean(r_train**2) / 3), rel=1e-5)


def test_rotations_slightly_off_orthonormal_come_out_as_rotations_and_one_rot6d_serves_one_grasp(vae_model, capsule):
    """Matrices within the 1e-4 tolerance are taken as the nearest rotation, so every grasp's rot6d holds two
    orthonormal columns; for n = 1 a (6,) rot6d is taken like a (3, 3) matrix."""
    R = Rotation.random(4, random_state=5).as_matrix()
    noisy = R + np.random.default_rng(0).uniform(-2e-5, 2e-5, R.shape)
    g = vae_model.sample("barrett_hand", capsule, 4, rotations=noisy, seed=0)
    a, b = g[:, 3:6], g[:, 6:9]
    np.testing.assert_allclose(np.linalg.norm(a, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(b, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.einsum("ni,ni->n", a, b), 0.0, atol=1e-12)
    np.testing.assert_allclose(a, R[:, :, 0], atol=1e-4)  # the nearest rotation: the one meant
    one = np.concatenate([R[0, :, 0], R[0, :, 1]])
    np.testing.assert_allclose(vae_model.sample("barrett_hand", capsule, 1, rotations=one, seed=0),
                               vae_model.sample("barrett_hand", capsule, 1, rotations=R[0], seed=0), atol=1e-6)


def test_same_seed_same_grasps(vae_model, capsule):
    a = vae_model.sample("shadow_hand_right", capsule, 8, seed=11)
    b = vae_model.sample("shadow_hand_right", capsule, 8, seed=11)
    c = vae_model.sample("shadow_hand_right", capsule, 8, seed=12)
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a, c)


def test_centre_makes_grasps_follow_a_mesh_whose_origin_lies_beside_it(vae_model):
    """``centre=True``: the network sees the object as if centred on its bounding box, and the grasps come
    back in the mesh frame, so moving the mesh's origin only moves the grasps. Without it, an origin
    farther off than any training object's is warned about."""
    import trimesh

    from ohra.errors import ObjectWarning

    def box(shift):
        mesh = trimesh.creation.box(extents=(0.05, 0.07, 0.09))
        mesh.apply_translation(shift)
        return ObjectModel(mesh, "box")

    shift = np.array([0.15, -0.02, 0.04])
    at_origin = vae_model.sample("allegro_hand_left", box((0, 0, 0)), 6, seed=3)
    moved = vae_model.sample("allegro_hand_left", box(shift), 6, seed=3, centre=True)
    np.testing.assert_allclose(moved[:, :3] - shift, at_origin[:, :3], atol=1e-6)
    np.testing.assert_allclose(moved[:, 3:], at_origin[:, 3:], atol=1e-6)
    with pytest.warns(ObjectWarning, match=r"15\.7 cm from its mesh frame's origin.*centre=True"):
        vae_model.sample("allegro_hand_left", box(shift), 2, seed=3)


def test_a_millimetre_mesh_is_named_as_such_once_not_as_an_off_centre_one(vae_model):
    """The library call warns like the CLI: a mesh in millimetres gets the size warning with the scale that
    fixes it (its 150 mm offset is a units problem, not a frame one), once per object."""
    import trimesh

    from ohra.errors import ObjectWarning

    mesh = trimesh.creation.box(extents=(50.0, 70.0, 90.0))  # a 5 x 7 x 9 cm box written in millimetres
    mesh.apply_translation((150.0, 0.0, 0.0))
    obj = ObjectModel(mesh, "box_mm")
    with pytest.warns(ObjectWarning) as got:
        vae_model.sample("barrett_hand", obj, 2, seed=0)
    messages = [str(w.message) for w in got if issubclass(w.category, ObjectWarning)]
    assert len(messages) == 1 and "box_mm" in messages[0] and "scale 0.001" in messages[0], messages
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error", ObjectWarning)
        vae_model.sample("barrett_hand", obj, 2, seed=1)  # said once


def _push_joints(model, value: float) -> None:
    """Bias the joint network far outside every limit, so only the clamp keeps outputs valid."""
    with torch.no_grad():
        model.net.joints.out[-1].bias.fill_(value)


@pytest.mark.parametrize("bias", [6.0, -6.0])
@pytest.mark.parametrize("hand", ["allegro_hand_left", "barrett_hand", "shadow_hand_right", "dex3_right", "leap_hand_right"])
def test_joints_within_limits_absent_zero_vae(vae_model, capsule, hand, bias):
    _check_limits(vae_model, hand, capsule, bias)


@pytest.mark.parametrize("bias", [6.0, -6.0])
@pytest.mark.parametrize("hand", ["leap_3303", "leap_1111", "barrett_hand"])
def test_joints_within_limits_absent_zero_params(params_model, capsule, hand, bias):
    """LEAP variants (never trained on, no base form) work with the params condition."""
    _check_limits(params_model, hand, capsule, bias)


def _check_limits(model, hand, obj, bias):
    """Clamped to the hand's limits, absent joints exactly 0, sampled as it is and as its mirror image (whose
    reversed joints saturate at the other limit)."""
    from ohra.canonical.mirror import mirror_params

    p = get_hand(hand)
    lo, up = np.asarray(p.joint_lowers), np.asarray(p.joint_uppers)
    signs = mirror_params(from_base if (from_base := _vae_form(model, p)) is not None else p).signs
    for mirror in (False, True):
        state = {k: v.clone() for k, v in model.net.joints.state_dict().items()}
        try:
            _push_joints(model, bias)
            g = model.sample(hand, obj, 16, seed=0, mirror=mirror)
        finally:
            model.net.joints.load_state_dict(state)
        q = g[:, 9:]
        assert np.all(q >= lo) and np.all(q <= up)
        absent = ~np.asarray(p.present_joints)
        assert absent.any() == (hand != "shadow_hand_right")  # every other hand here lacks some joints
        assert np.all(q[:, absent] == 0.0) and not np.signbit(q[:, absent]).any()
        movable = np.asarray(p.movable_joints)
        high = (bias > 0) == (signs > 0) if mirror else np.full(22, bias > 0)
        np.testing.assert_allclose(q[:, movable], np.broadcast_to(np.where(high, up, lo), q.shape)[:, movable], atol=1e-6)


def _vae_form(model, p):
    """The form a VAE-conditioned model mirrors (the base form), else None."""
    from ohra.learn.encoding import as_base

    return as_base(p) if model.condition.kind == "vae" else None


def test_vae_condition_refuses_hands_without_base_form(vae_model, capsule):
    with pytest.raises(ParamsError, match="condition='params'"):
        vae_model.sample("leap_3303", capsule, 2)


def test_bad_inputs_raise_ohra_errors(vae_model, capsule):
    for n in (0, -3, 2.5, True, "4"):
        with pytest.raises(GraspError, match="n must be a positive integer"):
            vae_model.sample("barrett_hand", capsule, n)
    with pytest.raises(GraspError, match="centre must be True or False, got 'no'"):  # "no" centred the object
        vae_model.sample("barrett_hand", capsule, 2, centre="no")
    with pytest.raises(GraspError, match=r"expected shape \(3, 3, 3\)"):
        vae_model.sample("barrett_hand", capsule, 3, rotations=np.eye(3)[None].repeat(2, 0))
    with pytest.raises(GraspError, match=r"expected shape \(2, 3, 3\) or \(2, 6\), got \(3, 6\)"):  # as passed
        vae_model.sample("barrett_hand", capsule, 2, rotations=np.tile([1, 0, 0, 0, 1, 0.0], (3, 1)))
    with pytest.raises(GraspError, match=r"rotations\[1\] is not a rotation"):
        vae_model.sample("barrett_hand", capsule, 2, rotations=np.stack([np.eye(3), 2 * np.eye(3)]))
    with pytest.raises(GraspError, match=r"rotations\[0\] is not a rotation"):
        vae_model.sample("barrett_hand", capsule, 1, rotations=np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(GraspError, match="NaN"):
        vae_model.sample("barrett_hand", capsule, 1, rotations=np.full((1, 6), np.nan))
    with pytest.raises(GraspError, match="expected real numbers, got complex"):
        vae_model.sample("barrett_hand", capsule, 1, rotations=np.eye(3)[None] + 1e-3j)
    with pytest.raises(HandNotFoundError, match="no_such_hand"):
        vae_model.sample("no_such_hand", capsule, 1)
    with pytest.raises(ObjectError, match="no_such_object"):
        vae_model.sample("barrett_hand", "builtin:no_such_object", 1)
    with pytest.raises(ObjectError, match="not found"):
        vae_model.sample("barrett_hand", "/nonexistent/mesh.obj", 1)
    with pytest.raises(GraspConfigError, match="encoder"):
        GraspModelConfig(encoder="transformer")
    with pytest.raises(GraspConfigError, match="inference_steps"):
        GraspModelConfig(inference_steps=2000)
    with pytest.raises(GraspConfigError, match="unknown setting"):
        GraspModelConfig.from_dict({"encoder": "pointnet", "layers": 3})


# -- conditions ------------------------------------------------------------------------------------
def test_params_condition_statistics_and_floor():
    hands = [get_hand(h) for h in ("allegro_hand_left", "barrett_hand", "shadow_hand_right")]
    c = HandCondition.fit("params", hands)
    assert c.dim == PARAMS_DIM == len(params_vector(hands[0]))
    x = np.stack([c.vector(h) for h in hands])
    np.testing.assert_allclose(x.mean(axis=0), 0.0, atol=1e-9)
    assert np.all(c.scale > 0)
    # an unseen LEAP variant gives a bounded vector despite dimensions constant over the training hands
    v = c.vector(get_hand("leap_3303"))
    assert np.all(np.isfinite(v)) and np.abs(v).max() < 100
    back = HandCondition.from_state({k: (np.asarray(w) if k != "kind" else w) for k, w in c.state().items()})
    np.testing.assert_array_equal(back.vector(hands[1]), c.vector(hands[1]))


def test_vae_condition_is_the_mean_latent_in_eval_mode():
    from ohra.learn.morph import load_vae

    c = HandCondition.fit("vae", [])
    mu, _ = load_vae().encode("barrett_hand")
    np.testing.assert_allclose(c.vector("barrett_hand"), mu, atol=1e-6)
    assert not c.vae.model.training


# -- checkpoints -----------------------------------------------------------------------------------
def test_saved_model_samples_identically(vae_model, capsule, tmp_path):
    vae_model.save(tmp_path)
    back = load_grasp_model(tmp_path)
    np.testing.assert_array_equal(back.sample("barrett_hand", capsule, 6, seed=4), vae_model.sample("barrett_hand", capsule, 6, seed=4))
    assert back.meta["hands"] == vae_model.meta["hands"]


def test_loaded_model_keeps_its_own_vae(vae_model, tmp_path):
    """The VAE travels inside the checkpoint: the condition does not depend on the shipped VAE."""
    vae_model.save(tmp_path)
    back = load_grasp_model(tmp_path)
    assert back.condition.vae is not vae_model.condition.vae
    np.testing.assert_array_equal(back.condition.vector("dex3_right"), vae_model.condition.vector("dex3_right"))


def test_bad_checkpoints_raise(tmp_path, vae_model):
    with pytest.raises(CheckpointError, match="no grasp model at"):
        load_grasp_model(tmp_path / "missing")
    (tmp_path / "model.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(CheckpointError, match="corrupt"):
        load_grasp_model(tmp_path)
    payload = vae_model.payload()
    payload["hand_dim"] = 99
    torch.save(payload, tmp_path / "model.pt")
    with pytest.raises(CheckpointError, match="incompatible grasp model"):
        load_grasp_model(tmp_path)
    torch.save({"format": "ohra-vae-model", "version": 1}, tmp_path / "model.pt")  # another ohra file
    with pytest.raises(CheckpointError, match=r"expected a grasp model \('ohra-grasp-model' or 'ohra-grasp-checkpoint'\), "
                                              r"got 'ohra-vae-model'"):
        load_grasp_model(tmp_path)


def test_shipped_model_loads_or_says_it_is_missing():
    from ohra.learn.grasp.model import default_model_dir

    if (default_model_dir() / "model.pt").is_file():
        m = load_grasp_model()
        assert m.sample("barrett_hand", "builtin:capsule", 2).shape == (2, 31)
    else:
        with pytest.raises(CheckpointError, match="no grasp model is shipped"):
            load_grasp_model()


def test_the_shipped_leap_model_conditions_on_raw_parameters_and_takes_any_hand(tmp_path, capsys):
    """``load_grasp_model("leap")``: the zero-shot study's all-data model, shipped; it samples for a LEAP
    variant in no dataset (which the default VAE model cannot condition on) and for a base-form hand.
    ``ohra grasp sample`` without ``--model`` picks it when the hand has no base form, and says so."""
    from ohra.cli.main import main
    from ohra.errors import ParamsError

    leap = load_grasp_model("leap")
    assert leap.condition.kind == "params" and "leap_2211" not in leap.meta["hands"]
    g = leap.sample("leap_2211", "builtin:box", 3, seed=1)
    assert g.shape == (3, 31) and np.array_equal(g, leap.sample("leap_2211", "builtin:box", 3, seed=1))
    assert leap.sample("barrett_hand", "builtin:box", 2).shape == (2, 31)
    with pytest.raises(ParamsError, match="--model leap"):
        load_grasp_model().sample("leap_2211", "builtin:box", 1)
    out = tmp_path / "g.npz"
    assert main(["grasp", "sample", "--hand", "leap_2211", "--object", "builtin:box", "-n", "3", "--seed", "0", "-o", str(out)]) == 0
    assert "used the shipped 'leap' model" in capsys.readouterr().err
    with np.load(out) as z:
        np.testing.assert_array_equal(z["grasps"], leap.sample("leap_2211", "builtin:box", 3, seed=0))
    assert main(["grasp", "sample", "--hand", "barrett_hand", "--object", "builtin:box", "-n", "2", "-o", str(out)]) == 0
    assert "note" not in capsys.readouterr().err  # a base-form hand keeps the default model
    # a hand with fewer than two fingers still samples, and is told its grasps cannot hold anything
    for hand, fingers in (("leap_0003", 1), ("leap_0033", 2)):
        assert main(["grasp", "sample", "--hand", hand, "--object", "builtin:box", "-n", "2", "-o", str(out)]) == 0
        assert ("1 finger(s): its grasps cannot hold" in capsys.readouterr().err) == (fingers < 2)
    # the wrong-condition study's sampling from the shell: leap_3033's joints, leap_3333's condition
    assert main(["grasp", "sample", "--hand", "leap_3033", "--condition-hand", "leap_3333", "--object", "builtin:box",
                 "-n", "3", "--seed", "0", "-o", str(out)]) == 0
    with np.load(out) as z:
        np.testing.assert_array_equal(z["grasps"], leap.sample("leap_3033", "builtin:box", 3, seed=0, condition_hand="leap_3333"))
        assert not np.array_equal(z["grasps"], leap.sample("leap_3033", "builtin:box", 3, seed=0))
    # best of K draws per rotation from the shell: what the library gives; a bad K is one line, exit 2
    assert main(["grasp", "sample", "--hand", "leap_2211", "--object", "builtin:box", "-n", "3", "--candidates", "4",
                 "-o", str(out)]) == 0
    with np.load(out) as z:
        np.testing.assert_array_equal(z["grasps"], leap.sample("leap_2211", "builtin:box", 3, seed=0, candidates=4))
    capsys.readouterr()
    assert main(["grasp", "sample", "--hand", "leap_2211", "--object", "builtin:box", "--candidates", "0", "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "candidates must be a positive integer" in err


def test_the_automatic_leap_model_is_the_shipped_one_and_its_note_never_precedes_an_error(tmp_path, capsys, monkeypatch):
    """A folder named ``leap`` where the user works does not stand in for the shipped model the CLI picks by
    itself; an invalid hand file is its own error, not a reason to switch models; the note comes after the
    work, so an error stays one line."""
    from ohra.cli.main import main

    monkeypatch.chdir(tmp_path)
    (tmp_path / "leap").mkdir()
    out = tmp_path / "g.npz"
    assert main(["grasp", "sample", "--hand", "leap_2211", "--object", "builtin:box", "-n", "2", "-o", str(out)]) == 0
    assert out.is_file()
    capsys.readouterr()
    (tmp_path / "empty.json").write_text("{}")
    (tmp_path / "hand.urdf").write_text("<robot name='x'/>")
    for hand, named in (("empty.json", "cannot tell the form"), ("hand.urdf", "a URDF is not a hand")):
        assert main(["grasp", "sample", "--hand", hand, "--object", "builtin:box", "-n", "2", "-o", str(out)]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and named in err and "note" not in err, err
    assert main(["grasp", "sample", "--hand", "leap_2211", "--object", "builtin:nosuch", "-n", "2", "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "nosuch" in err
    # an output under a file is refused before any sampling or simulation (no model is even loaded)
    import ohra.cli.grasp as grasp_cli

    monkeypatch.setattr(grasp_cli, "_load", lambda *a, **k: pytest.fail("loaded a model before checking -o"))
    for argv in (["grasp", "sample", "--hand", "leap_2211", "--object", "builtin:box", "-o", str(tmp_path / "empty.json" / "g.npz")],
                 ["grasp", "eval", "--hands", "leap_2211", "--objects", "builtin:box", "-o", str(tmp_path / "empty.json" / "r.json")]):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "empty.json is a file, not a folder" in err


def test_the_automatic_model_is_chosen_for_the_hand_the_model_is_conditioned_on(tmp_path, capsys):
    """``--condition-hand``: the model must read that hand (a LEAP condition needs the leap model), whatever
    the hand whose joints are sampled."""
    from ohra.cli.main import main

    out = tmp_path / "g.npz"
    assert main(["grasp", "sample", "--hand", "barrett_hand", "--condition-hand", "leap_3333", "--object", "builtin:box",
                 "-n", "2", "-o", str(out)]) == 0
    assert "used the shipped 'leap' model" in capsys.readouterr().err
    with np.load(out) as z:
        np.testing.assert_array_equal(z["grasps"], load_grasp_model("leap").sample("barrett_hand", "builtin:box", 2,
                                                                                   condition_hand="leap_3333"))


@pytest.mark.parametrize("seed", [-1, 1.5, "a", True])
def test_a_seed_numpy_cannot_take_is_a_grasp_error_naming_it(seed):
    from ohra.learn.grasp.config import GraspConfigError, GraspTrainConfig

    with pytest.raises(GraspError, match="seed must be a whole number >= 0"):
        load_grasp_model("leap").sample("leap_2211", "builtin:box", 1, seed=seed)
    with pytest.raises(GraspConfigError, match="seed must be a whole number >= 0"):
        GraspTrainConfig(seed=seed)
    assert load_grasp_model("leap").sample("leap_2211", "builtin:box", 1, seed=np.int64(3)).shape == (1, 31)


@pytest.mark.parametrize("refine", [0, 0.0, "no", 1])
def test_refine_takes_true_false_none_or_settings_only(refine):
    with pytest.raises(GraspError, match="refine must be True, False, None or a RefineSettings"):
        load_grasp_model("leap").sample("leap_2211", "builtin:box", 1, refine=refine)


def test_refine_numpy_false_is_off_and_numpy_true_is_on():
    leap = load_grasp_model("leap")
    plain = leap.sample("leap_2211", "builtin:box", 3, seed=2)
    refined = leap.sample("leap_2211", "builtin:box", 3, seed=2, refine=True)
    assert not np.array_equal(plain, refined)
    np.testing.assert_array_equal(leap.sample("leap_2211", "builtin:box", 3, seed=2, refine=np.False_), plain)
    np.testing.assert_array_equal(leap.sample("leap_2211", "builtin:box", 3, seed=2, refine=np.True_), refined)


def test_grasp_training_options_are_named_one_by_one():
    from ohra.learn.grasp.config import GraspConfigError, GraspTrainConfig

    with pytest.raises(GraspConfigError, match=r"^lr must be positive, got 0"):
        GraspTrainConfig(lr=0.0)
    with pytest.raises(GraspConfigError, match=r"^condition_noise must be >= 0, got -0.1"):
        GraspTrainConfig(condition_noise=-0.1)


def test_lazy_exports():
    import ohra.learn

    assert ohra.learn.load_grasp_model is load_grasp_model
    with pytest.raises(AttributeError):
        ohra.learn.grasp.no_such_name  # noqa: B018
    assert issubclass(GraspConfigError, OhraError)


def test_sampled_grasps_of_a_coupled_hand_hold_its_couplings_as_simulation_runs_them(tmp_path, capsys):
    """The network does not know a hand's couplings (Inspire's mimic joints): `ohra grasp sample` and evaluation
    set coupled joints from their drivers, so a stored grasp is the simulated one."""
    from ohra.canonical.couplings import residual
    from ohra.cli.main import main
    from ohra.hands import get_couplings
    from ohra.learn.grasp.evaluate import evaluate_model

    cs = get_couplings("inspire_hand_right")
    raw = load_grasp_model().sample("inspire_hand_right", "builtin:box", 4, seed=0)
    assert np.abs(residual(cs, raw[:, 9:])).max() > 0.01  # what the network gives
    f = tmp_path / "g.npz"
    assert main(["grasp", "sample", "--hand", "inspire_hand_right", "--object", "builtin:box", "-n", "4", "-o", str(f)]) == 0
    assert "6 coupled joint(s) of inspire_hand_right set from their drivers" in capsys.readouterr().err
    with np.load(f) as d:
        assert np.abs(residual(cs, d["grasps"][:, 9:])).max() < 1e-12
    rep = evaluate_model(load_grasp_model(), ["inspire_hand_right"], ["builtin:box"], n=2, protocol="reference")
    assert np.abs(residual(cs, rep.pairs[0].grasps[:, 9:])).max() < 1e-12


def test_grasp_eval_keeps_its_table_aligned_for_long_hand_labels(tmp_path, capsys):
    """A hand given as a file is labelled by its path: the columns after it stay under each other."""
    from ohra.cli.main import main

    deep = tmp_path / "a_folder_with_a_rather_long_name" / "leap_2212.json"
    deep.parent.mkdir()
    get_hand("leap_2212").to_json(deep)  # another hand: the same one by two spellings is refused
    argv = ["grasp", "eval", "--model", "leap", "--hands", "leap_2211", str(deep), "--objects", "builtin:box", "-n", "1",
            "--quiet"]
    assert main(argv) == 0
    rows = [ln for ln in capsys.readouterr().out.splitlines() if "ms/grasp" in ln]
    assert len(rows) == 2 and len(str(deep)) > 20
    assert rows[0].index("/1 ") == rows[1].index("/1 ") and rows[0].index("ms/grasp") == rows[1].index("ms/grasp")
