"""The morphology VAE: model, losses, training, checkpoints and exact resume, shipped model, use, CLI."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

import ohra  # noqa: E402
from ohra.cli.main import main as cli_main  # noqa: E402
from ohra.errors import CheckpointError, OhraError  # noqa: E402
from ohra.hands import registry  # noqa: E402
from ohra.canonical.kinematics import HandModel  # noqa: E402
from ohra.learn import encode_vectors, sample_vectors  # noqa: E402
from ohra.learn.encoding import LatentError  # noqa: E402
from ohra.learn.sampler import in_support, mirror_vectors  # noqa: E402
from ohra.learn import geometry as geo  # noqa: E402
from ohra.learn.morph import Interpolation, default_model_dir, load_vae, reference_model_dir, tip_moves  # noqa: E402
from ohra.learn.sampler_reference import sample_reference_vectors  # noqa: E402
from ohra.learn.train_vae import TrainConfig, learning_rate, make_dataset, train  # noqa: E402
from ohra.learn.vae import GeometryLoss, MorphologyVAE, VAEConfig, make_optimizer, path_smoothness, vae_loss  # noqa: E402
from ohra.learn.vae_metrics import reconstruct, reconstruction_metrics  # noqa: E402
from ohra.canonical.params import BaseParams  # noqa: E402

SMALL = TrainConfig(samples=2048, batch_size=256, epochs=4, threads=1, heldout=256, checkpoint_every=1, lr_schedule="constant")


def _states_equal(a: dict, b: dict) -> bool:
    return a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)


# -- model and loss ---------------------------------------------------------------------------------
def test_architecture_and_paper_optimiser_settings():
    m = MorphologyVAE()
    lin = [mod for mod in m.encoder if isinstance(mod, torch.nn.Linear)]
    assert [(l.in_features, l.out_features) for l in lin] == [(66, 512), (512, 256), (256, 128)]
    assert sum(isinstance(mod, torch.nn.BatchNorm1d) for mod in m.encoder) == 3
    dec = [mod for mod in m.decoder if isinstance(mod, torch.nn.Linear)]
    assert [(l.in_features, l.out_features) for l in dec] == [(16, 128), (128, 256), (256, 512)]
    m.eval()
    mu, logvar = m.encode(torch.zeros(5, 66))
    out = m.decode(mu)
    assert mu.shape == logvar.shape == (5, 16)
    assert {k: tuple(v.shape) for k, v in out.items()} == {"cont": (5, 32), "axis1": (5, 6), "axis2": (5, 6), "presence": (5, 22)}
    opt = make_optimizer(m)
    g = opt.param_groups[0]
    assert g["lr"] == 1e-4 and g["betas"] == (0.95, 0.999) and g["weight_decay"] == 1e-6
    assert VAEConfig().beta == 0.01


def test_loss_terms_match_their_definitions():
    torch.manual_seed(0)
    x = torch.from_numpy(encode_vectors(sample_vectors(64, 0)).astype(np.float32))
    m = MorphologyVAE()
    out, mu, logvar = m(x, generator=torch.Generator().manual_seed(1))
    t = vae_loss(out, x, mu, logvar, beta=0.01)
    assert torch.isclose(t["mse"], ((out["cont"] - x[:, :32]) ** 2).mean())
    kl = (-0.5 * (1 + logvar - mu ** 2 - logvar.exp()).sum(dim=1)).mean()
    assert torch.isclose(t["kl"], kl)
    total = t["mse"] + t["ce_axis1"] + t["ce_axis2"] + t["bce"] + 0.01 * t["kl"]
    assert torch.isclose(t["total"], total)


def test_rot6d70_model_shapes_and_config_round_trip():
    cfg = TrainConfig(latent_dim=32).vae_config()
    assert cfg.encoding == "rot6d70" and cfg.input_dim == 70
    m = MorphologyVAE(cfg).eval()
    out = m.decode(m.encode(torch.zeros(3, 70))[0])
    assert {k: tuple(v.shape) for k, v in out.items()} == {"cont": (3, 35), "axis1": (3, 6), "axis2": (3, 6), "presence": (3, 23)}
    assert VAEConfig.from_dict(cfg.to_dict()) == cfg
    old = {"input_dim": 66, "hidden": [512, 256, 128], "latent_dim": 16, "beta": 0.01}  # a model saved before
    assert VAEConfig.from_dict(old).encoding == "reference66"
    with pytest.raises(ValueError, match="does not match"):
        VAEConfig(input_dim=66, encoding="rot6d70")
    with pytest.raises(OhraError, match="unknown key"):
        TrainConfig.from_dict({"samples": 10, "bogus": 1}, "run/config.json")


def test_geometry_terms_are_zero_for_the_truth_and_grow_with_the_error():
    data = make_dataset(64, 3, encoding="rot6d70")
    cfg = VAEConfig(input_dim=70, encoding="rot6d70", tip_weight=1.0, rot_weight=1.0)
    geom = GeometryLoss(cfg, data.standardizer.mean, data.standardizer.std)
    # the training targets use the right-hand form of each hand, as the encoding does
    exact = geom(data.x[:, :35], data.rotation, data.present, data.tips)
    assert exact["tip"] < 1e-4 and exact["rot"] < 1e-4
    shifted = data.x[:, :35].clone()
    shifted[:, 8:23] += 0.01 / torch.as_tensor(data.standardizer.std[8:23], dtype=torch.float32)  # every base +1 cm
    t = geom(shifted, data.rotation, data.present, data.tips)["tip"]
    assert abs(float(t) - (np.sqrt(3 + 0.01) - 0.1)) < 1e-3  # pseudo-Huber of a sqrt(3) cm move


def test_path_smoothness_is_zero_without_moves_and_counts_big_steps():
    data = make_dataset(64, 4, encoding="rot6d70")
    cfg = VAEConfig(input_dim=70, encoding="rot6d70", smooth_weight=1.0)
    geom = GeometryLoss(cfg, data.standardizer.mean, data.standardizer.std)
    torch.manual_seed(0)
    m = MorphologyVAE(cfg).eval()
    g = torch.Generator().manual_seed(0)
    with torch.no_grad():
        same = torch.zeros(64, cfg.latent_dim)
        assert float(path_smoothness(m, geom, same, data.present, g)) == 0.0
        spread = torch.randn(64, cfg.latent_dim, generator=g)
        small = float(path_smoothness(m, geom, spread, data.present, g, limit=1.0))  # 1 m: nothing exceeds it
        big = float(path_smoothness(m, geom, 1e3 * spread, data.present, g, limit=0.0))
    assert small == 0.0 and big > 0.0


def test_cosine_learning_rate_schedule():
    cfg = TrainConfig(lr=1e-3, lr_schedule="cosine", lr_final_ratio=0.01)
    assert learning_rate(cfg, 0, 101) == pytest.approx(1e-3)
    assert learning_rate(cfg, 50, 101) == pytest.approx(1e-3 * (0.01 + 0.99 * 0.5))
    assert learning_rate(cfg, 100, 101) == pytest.approx(1e-5)
    assert learning_rate(TrainConfig(lr=1e-3, lr_schedule="constant"), 70, 101) == 1e-3


# -- training ---------------------------------------------------------------------------------------
@pytest.mark.e2e  # ~11 s of VAE training: moved out of the default suite (stop 56) to keep it near 5 min
def test_a_few_hundred_steps_reduce_every_reconstruction_term():
    cfg = TrainConfig(samples=4096, batch_size=256, epochs=15, threads=1, heldout=512)  # 240 steps
    res = train(cfg, progress=False)
    h = res.metrics["history"]
    assert res.metrics["steps"] == 240
    for term in ("total", "mse", "ce_axis1", "ce_axis2", "bce"):
        assert h[-1][term] < 0.9 * h[0][term], (term, h[0][term], h[-1][term])
    # KL is the regulariser: it grows from ~0 as the latent starts to carry information
    assert h[-1]["kl"] > h[0]["kl"]
    assert res.metrics["heldout"]["presence_accuracy"] > 0.6  # chance level is ~0.5


def test_resume_after_interruption_equals_uninterrupted_training(tmp_path):
    full = train(SMALL, tmp_path / "a", progress=False)

    class Interrupted(Exception):
        pass

    def stop_at_2(epoch, losses):
        if epoch == 2:
            raise Interrupted

    with pytest.raises(Interrupted):
        train(SMALL, tmp_path / "b", progress=False, on_epoch=stop_at_2)
    ck = torch.load(tmp_path / "b" / "checkpoints" / "last.pt", weights_only=True)
    assert ck["epoch"] == 2 and ck["step"] == 16
    resumed = train(SMALL, tmp_path / "b", resume=True, progress=False)
    assert _states_equal(full.model.state_dict(), resumed.model.state_dict())
    a = torch.load(tmp_path / "a" / "checkpoints" / "last.pt", weights_only=True)
    b = torch.load(tmp_path / "b" / "checkpoints" / "last.pt", weights_only=True)
    assert _states_equal(a["optimizer"]["state"][0], b["optimizer"]["state"][0])
    strip = lambda hist: [{k: v for k, v in e.items() if k != "elapsed_s"} for e in hist]  # noqa: E731
    assert strip(full.metrics["history"]) == strip(resumed.metrics["history"])
    assert (tmp_path / "b" / "model.pt").is_file() and json.loads((tmp_path / "b" / "metrics.json").read_text())["steps"] == 32
    # extending a finished run continues it; a different seed cannot resume it
    more = train(TrainConfig(**{**SMALL.to_dict(), "epochs": 5, "betas": SMALL.betas}), tmp_path / "a", resume=True, progress=False)
    assert more.metrics["steps"] == 40
    with pytest.raises(CheckpointError, match="seed"):
        train(TrainConfig(**{**SMALL.to_dict(), "seed": 9, "betas": SMALL.betas}), tmp_path / "a", resume=True, progress=False)


def test_ctrl_c_waits_for_the_epoch_checkpoints_it_and_the_resume_is_exact(tmp_path, terminal_sigint):
    """With checkpoints every 3 epochs, Ctrl-C in epoch 2 still keeps epoch 2 (the loop finishes it, saves, stops)."""
    import os
    import signal

    cfg = TrainConfig(**{**SMALL.to_dict(), "checkpoint_every": 3, "betas": SMALL.betas})
    full = train(cfg, progress=False)

    def interrupt(epoch, losses):
        if epoch == 2:
            os.kill(os.getpid(), signal.SIGINT)

    with pytest.raises(KeyboardInterrupt):
        train(cfg, tmp_path / "b", progress=False, on_epoch=interrupt)
    assert torch.load(tmp_path / "b" / "checkpoints" / "last.pt", weights_only=True)["epoch"] == 2
    resumed = train(cfg, tmp_path / "b", resume=True, progress=False)
    assert _states_equal(full.model.state_dict(), resumed.model.state_dict())


def test_training_is_deterministic_for_a_seed():
    cfg = TrainConfig(samples=1024, batch_size=256, epochs=2, threads=1, heldout=0)
    a, b = train(cfg, progress=False), train(cfg, progress=False)
    c = train(TrainConfig(samples=1024, batch_size=256, epochs=2, threads=1, heldout=0, seed=1), progress=False)
    assert _states_equal(a.model.state_dict(), b.model.state_dict())
    assert not _states_equal(a.model.state_dict(), c.model.state_dict())


def test_corrupt_or_missing_checkpoints_raise_checkpoint_errors(tmp_path):
    train(SMALL, tmp_path / "run", progress=False)
    last = tmp_path / "run" / "checkpoints" / "last.pt"
    last.write_bytes(last.read_bytes()[:1000])  # truncated
    with pytest.raises(CheckpointError, match="corrupt"):
        train(SMALL, tmp_path / "run", resume=True, progress=False)
    (tmp_path / "run" / "model.pt").write_text("not a model")
    with pytest.raises(CheckpointError, match="model.pt"):
        load_vae(tmp_path / "run")
    with pytest.raises(CheckpointError, match="no VAE model"):
        load_vae(tmp_path / "nowhere")
    with pytest.raises(CheckpointError, match="not found"):
        train(SMALL, tmp_path / "fresh", resume=True, progress=False)
    torch.save({"format": "something-else", "version": 1}, tmp_path / "other.pt")
    with pytest.raises(CheckpointError, match="expected"):
        load_vae(tmp_path / "other.pt")


# -- the shipped model ------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def vae():
    return load_vae()  # package data: a missing or broken shipped model fails these tests


def test_shipped_model_loads_with_config_and_metrics_and_meets_the_targets(vae):
    assert vae.encoding.name == "rot6d70" and vae.latent_dim == vae.config["latent_dim"] and not vae.model.training
    assert vae.config["samples"] == 65536 and vae.metrics["heldout"]["presence_accuracy"] >= 0.99
    size = sum(f.stat().st_size for f in default_model_dir().iterdir())
    assert size < 4 * 2 ** 20
    v = sample_vectors(2048, 424242)  # fresh held-out hands
    x = vae.encoding.encode_vectors(v, warn=False)
    m = reconstruction_metrics(x, reconstruct(vae.model, vae.standardizer, x), vae.encoding)
    assert m["presence_accuracy"] >= 0.99 and m["axis_accuracy"] >= 0.98 and m["handedness_accuracy"] >= 0.99


def test_the_reference_model_still_loads_and_reconstructs_its_encoding():
    ref = load_vae(reference_model_dir())
    assert ref.encoding.name == "reference66" and ref.latent_dim == 16
    x = encode_vectors(sample_reference_vectors(512, 7), warn=False)
    m = reconstruction_metrics(x, reconstruct(ref.model, ref.standardizer, x), ref.encoding)
    assert m["presence_accuracy"] >= 0.99 and m["axis_accuracy"] >= 0.98


def test_encode_is_deterministic_and_decode_of_any_latent_is_valid_and_plausible(vae):
    d = vae.latent_dim
    p = sample_vectors(1, 3)[0]
    mu1, lv1 = vae.encode(BaseParams.from_vector(p))
    mu2, _ = vae.encode(BaseParams.from_vector(p))
    assert mu1.shape == lv1.shape == (d,) and np.array_equal(mu1, mu2) and isinstance(mu1, np.ndarray)
    rng = np.random.default_rng(0)
    zs = np.concatenate([rng.normal(size=(200, d)), rng.normal(size=(10, d)) * 1e3, np.full((1, d), 1e3),
                         np.full((1, d), -1e3), np.full((1, d), 1e30), np.full((1, d), np.inf)])
    V = vae.decode_vectors(zs)
    assert not geo.knuckles_inside_palm(V).any() and not geo.thumb_into_palm(V).any()
    assert (geo.finger_clearance(V) >= 0).all()
    with pytest.warns(UserWarning, match=r"latent component inf lies far outside the VAE's prior"):
        hands = vae.decode(zs)
    assert len(hands) == len(zs)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        vae.decode(zs[:200])  # draws from the prior: no warning
    with pytest.warns(UserWarning, match="8.5 lies far outside"):
        vae.decode(np.full(d, -8.5))
    for h in hands[-6:] + hands[:3]:
        HandModel.from_params(h)  # renders and loads
    with pytest.raises(LatentError, match=rf"\({d},\)"):
        vae.decode(np.zeros(d - 1))
    with pytest.raises(LatentError, match="NaN"):
        vae.decode(np.full(d, np.nan))


def test_encoding_no_hands_is_a_params_error_naming_the_problem(vae):
    from ohra.errors import ParamsError
    from ohra.learn.morph import encode

    for call in (lambda: vae.encode([]), lambda: vae.encode(()), lambda: encode([], vae=vae)):
        with pytest.raises(ParamsError, match="no hands given"):
            call()


def test_registered_hands_encode_and_reconstruct_their_presence_pattern(vae):
    """Every registered base hand is inside the sampler's support and gets its presence pattern
    and handedness back exactly."""
    names = [n for n in ohra.list_hands() if "base" in registry.registered_forms(n)]
    assert {"dex3_right", "shadow_hand_right", "barrett_hand"} <= set(names)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        mu, logvar = vae.encode(names)
        x = vae.encoding.encode_vectors(np.stack([ohra.get_hand(n, "base").to_vector() for n in names]))
    assert mu.shape == (len(names), vae.latent_dim) and np.isfinite(mu).all() and np.isfinite(logvar).all()
    assert all(in_support(f > 0.5) for f in x[:, vae.encoding.flags])
    y = reconstruct(vae.model, vae.standardizer, x)
    b = vae.encoding.binary
    wrong = [n for n, a, c in zip(names, x[:, b], y[:, b]) if not np.array_equal(a, c)]
    assert not wrong, f"presence pattern or handedness not reconstructed for {wrong}"


def test_interpolation_from_dex3_to_shadow(vae):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        it = vae.interpolate("dex3_right", "shadow_hand_right", 8)
    assert isinstance(it, Interpolation) and len(it) == 8 and it.alphas[0] == 0 and it.alphas[-1] == 1
    assert it.params[0].num_fingers == 3 and it.params[-1].num_fingers == 5
    assert it.params[0].dof == ohra.get_hand("dex3_right", "base").dof
    assert it.params[-1].dof == 22
    assert all(p.handedness == "right" for p in it.params)
    assert [p.isclose(ohra.get_hand(n, "base")) for p, n in zip(it.originals, ("dex3_right", "shadow_hand_right"))] == [True, True]
    for text in it.urdfs:
        HandModel(text)


def test_interpolation_steps_share_the_fingertip_arc_length_evenly(vae):
    """Barrett's thumb turns ~130 degrees towards Shadow's: at even alphas the decoder puts most of
    that into a few steps; at equal arc length every step that keeps the joints moves the fingertips
    by about total / 15, the total measured on a dense sampling of the same latent line."""
    a, b = ohra.get_hand("barrett_hand", "base"), ohra.get_hand("shadow_hand_right", "base")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        it = vae.interpolate(a, b, 16, spacing="arc")
        (mu_a, _), (mu_b, _) = vae.encode(a), vae.encode(b)
    assert np.all(np.diff(it.alphas) > 0) and it.alphas[0] == 0.0 and it.alphas[-1] == 1.0
    assert np.allclose(it.z, (1 - it.alphas)[:, None] * mu_a + it.alphas[:, None] * mu_b)
    t = np.linspace(0.0, 1.0, 2001)
    total = tip_moves(vae.decode_vectors((1 - t)[:, None] * mu_a + t[:, None] * mu_b)).sum()
    steps = tip_moves(np.stack([p.to_vector() for p in it.params]))
    kept = steps[steps > 0]
    assert len(kept) >= 5 and kept.max() <= 1.05 * total / 15 and kept.min() >= 0.5 * total / 15, 1e3 * kept
    # the alphas depend on the spacing; "even" is the plain latent line
    even = vae.interpolate(a, b, 16, spacing="even")
    assert np.array_equal(even.alphas, np.linspace(0, 1, 16))
    with pytest.raises(LatentError, match="spacing"):
        vae.interpolate(a, b, 16, spacing="uneven")


def test_tip_moves_measure_fingertip_moves_and_skip_structure_changes():
    v = ohra.get_hand("shadow_hand_left", "base").to_vector()
    longer = v.copy()
    longer[5] += 0.01  # non-thumb proximal length: every finger's tip moves 1 cm along +z
    fewer = v.copy()
    fewer[[38 + 4, 60 + 4]] = 0.0  # thumb joint 5 gone: a change of structure, not a move
    right = mirror_vectors(v[None])[0]  # the same hand turned right: a change of structure too
    assert np.allclose(tip_moves(np.stack([v, longer, longer, fewer, right])), [0.01, 0.0, 0.0, 0.0])


@pytest.mark.assets
def test_an_endpoint_given_as_a_spec_file_is_labelled_by_its_hand(vae, hands_dir, tmp_path):
    """The strip and scene named a spec endpoint by its file's stem ('original three' for myhand3)."""
    spec = tmp_path / "copied_under_another_name.yaml"
    spec.write_text(registry.spec_path("dex3_right").read_text())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        it = vae.interpolate(str(spec), "shadow_hand_right", 2, spacing="even")
    assert it.endpoints == ("dex3_right", "shadow_hand_right")


# -- CLI --------------------------------------------------------------------------------------------
def test_cli_interpolate_writes_urdfs_png_and_html(vae, tmp_path, capsys):
    rc = cli_main(["vae", "interpolate", "dex3_right", "shadow_hand_right", "-n", "4", "-o", str(tmp_path)])
    assert rc == 0
    assert sorted(p.name for p in tmp_path.glob("*.urdf")) == [f"interp_{i:02d}.urdf" for i in range(4)]
    assert (tmp_path / "strip.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    scene = (tmp_path / "scene.html").read_text()
    assert "<html" in scene[:2000].lower()
    assert "dex3_right -&gt; shadow_hand_right: decoded hands left to right at path fraction a = 0.00, " in scene
    assert "1.00; grey, above the ends: the two hands as given</div>" in scene
    out = capsys.readouterr()
    assert "wrote 4 URDFs" in out.err and "interp_00.urdf: " in out.out  # the files on stderr, what they hold on stdout


def test_cli_bad_input_is_one_line_and_exit_2(vae, tmp_path, capsys):
    ext = ohra.get_hand("shadow_hand_right", "base").to_extended()
    cases = [
        (["vae", "decode", "1,2,3"], f"expected shape ({vae.latent_dim},)"),
        (["vae", "decode", "a,b"], "comma-separated"),
        (["vae", "encode", "no_such_hand"], "unknown hand"),
        (["vae", "encode", "leap_3303"], "leap_3303 is a LEAP variant"),
    ]
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"\x00garbage")
    cases.append((["vae", "encode", "dex3_right", "--model", str(bad)], "corrupt"))
    d = ext.to_dict()
    d["finger_radii"] = [r * (1.0 + 0.1 * i) for i, r in enumerate(d["finger_radii"])]
    wrong_form = tmp_path / "ext.json"
    wrong_form.write_text(json.dumps(d))
    cases.append((["vae", "encode", str(wrong_form)], "the morphology VAE works on base-form params"))  # not "ask for the extended form"
    # which of two hands it is (the message named no hand)
    cases.append((["vae", "encode", "shadow_hand_right", str(wrong_form)], f"hand '{wrong_form}': the morphology VAE works"))
    (tmp_path / "empty.npy").write_bytes(b"")
    (tmp_path / "afile").write_text("x")
    z = ",".join(["0.1"] * vae.latent_dim)
    cases += [(["vae", "decode", str(tmp_path / "empty.npy")], "cannot read a latent"),
              (["vae", "decode", "0.1,,0.2"], "an empty field"),
              (["vae", "interpolate", "barrett_hand", "dex3_right", "-n", "2", "-o", str(tmp_path / "afile")], "afile is a file"),
              (["vae", "decode", z, "-o", str(tmp_path / "ok.json"), "--urdf", str(tmp_path)], "is a folder"),
              (["vae", "decode", z, "-o", str(tmp_path / "ok.json"), "--urdf", str(tmp_path / "." / "ok.json")], "the same file"),
              (["vae", "decode", z.replace("0.1", "inf", 1)], "must be finite"),
              (["train", "vae", "--samples", "64", "--batch-size", "32", "--heldout", "8", "--epochs", "1", "-o", str(tmp_path / "afile")], "afile is a file"),
              (["train", "vae", "--samples", "64", "--batch-size", "32", "--epochs", "1", "--seed", "-1", "-o", str(tmp_path / "r")],
               "seed must be a whole number >= 0")]
    for argv, msg in cases:
        rc = cli_main(argv)
        err = capsys.readouterr().err
        assert rc == 2, argv
        assert msg in err and "Traceback" not in err and err.count("\n") == 1, (argv, err)
    assert not (tmp_path / "ok.json").exists() and not (tmp_path / "r").exists()  # nothing written by a failed command


def test_cli_decode_reads_what_encode_writes(vae, tmp_path, capsys):
    """``ohra vae encode HAND > e.json; ohra vae decode e.json`` was 'expected shape (32,), got ()'."""
    assert cli_main(["vae", "encode", "dex3_right"]) == 0
    one = tmp_path / "one.json"
    one.write_text(capsys.readouterr().out)
    assert cli_main(["vae", "decode", str(one), "-o", str(tmp_path / "dex3.json")]) == 0
    capsys.readouterr()
    mu = json.loads(one.read_text())["dex3_right"]["mu"]
    assert ohra.load_params(tmp_path / "dex3.json").to_json() == vae.decode(np.array(mu)).to_json()
    assert cli_main(["vae", "encode", "dex3_right", "barrett_hand"]) == 0
    two = tmp_path / "two.json"
    two.write_text(capsys.readouterr().out)
    assert cli_main(["vae", "decode", str(two)]) == 2
    assert "holds the encodings of 2 hands (dex3_right, barrett_hand)" in capsys.readouterr().err


def test_cli_train_small_run_and_resume(tmp_path, capsys):
    out = tmp_path / "run"
    args = ["train", "vae", "--samples", "1024", "--epochs", "1", "--batch-size", "512", "--threads", "1",
            "--heldout", "128", "-o", str(out), "--quiet"]
    assert cli_main(args) == 0
    assert "held-out (128 hands)" in capsys.readouterr().out
    assert cli_main(args) == 2 and "--resume" in capsys.readouterr().err
    assert cli_main(args + ["--resume"]) == 0  # a finished run resumes to itself
    m = json.loads((out / "metrics.json").read_text())
    assert m["steps"] == 2
    assert m["train_seconds_this_run"] == 0.0  # resumed to itself: nothing trained in this run
    assert load_vae(out).latent_dim == TrainConfig().latent_dim
    # the default cosine learning rate depends on the run's length: it cannot be extended
    args[args.index("--epochs") + 1] = "2"
    capsys.readouterr()
    assert cli_main(args + ["--resume"]) == 2
    err = capsys.readouterr().err
    assert "epochs=1" in err and err.count("\n") == 1


def test_vae_api_counts_and_hands_of_the_wrong_type_are_named(vae):
    from ohra.errors import ParamsError
    from ohra.learn.encoding import LatentError
    from ohra.learn.sampler import sample_params

    with pytest.raises(LatentError, match="a whole number of at least 2 steps, got 2.5"):
        vae.interpolate("barrett_hand", "dex3_right", n=2.5)
    for n in (2.5, -1, True):
        with pytest.raises(ParamsError, match="number of samples must be a whole number >= 0"):
            sample_params(n, seed=0)
    with pytest.raises(ParamsError, match="sampler seed must be a whole number >= 0"):
        sample_params(1, seed=-1)
    for bad in (5, None):
        with pytest.raises(ParamsError, match="encode: expected a hand .* got"):
            vae.encode(bad)
    names = ["shadow_hand_right", "allegro_hand_right"]
    mu, _ = vae.encode(names)
    for iterable in (np.array(names), (n for n in names), dict.fromkeys(names).keys()):  # any iterable of hands
        np.testing.assert_array_equal(vae.encode(iterable)[0], mu)


def test_a_vae_run_another_process_is_training_is_refused_and_left_alone(tmp_path):
    """Two processes training into one folder mixed their files (one's config, the other's model): the second
    fails at once, as synth and the grasp and rotation trainings do."""
    import subprocess
    import sys

    from ohra.errors import FolderInUseError

    run = tmp_path / "run"
    hold = "import sys, time\nfrom ohra.io import folder_lock\nwith folder_lock(sys.argv[1]):\n    print('held', flush=True); time.sleep(120)"
    p = subprocess.Popen([sys.executable, "-c", hold, str(run)], stdout=subprocess.PIPE, text=True)
    try:
        assert p.stdout.readline().strip() == "held"
        with pytest.raises(FolderInUseError, match=f"pid {p.pid}.*VAE training run"):
            train(SMALL, run, progress=False)
    finally:
        p.kill()
        p.wait()
    assert not (run / "config.json").exists() and not (run / "model.pt").exists()
