"""The morphology VAE: model, loss, training, checkpoints and exact resume, shipped model, use, CLI."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

import ohra  # noqa: E402
from ohra.cli.main import main as cli_main  # noqa: E402
from ohra.errors import CheckpointError  # noqa: E402
from ohra.hands import registry  # noqa: E402
from ohra.canonical.kinematics import HandModel  # noqa: E402
from ohra.learn import encode_vectors, sample_vectors  # noqa: E402
from ohra.learn.encoding import FLAGS, LatentError  # noqa: E402
from ohra.learn.sampler import in_support  # noqa: E402
from ohra.learn.morph import Interpolation, default_model_dir, load_vae  # noqa: E402
from ohra.learn.train_vae import TrainConfig, reconstruct, reconstruction_metrics, train  # noqa: E402
from ohra.learn.vae import MorphologyVAE, VAEConfig, make_optimizer, vae_loss  # noqa: E402
from ohra.canonical.params import BaseParams  # noqa: E402

SMALL = TrainConfig(samples=2048, batch_size=256, epochs=4, threads=1, heldout=256, checkpoint_every=1)


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


# -- training ---------------------------------------------------------------------------------------
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
    assert vae.latent_dim == 16 and not vae.model.training
    assert vae.config["samples"] == 65536 and vae.metrics["heldout"]["presence_accuracy"] >= 0.99
    size = sum(f.stat().st_size for f in default_model_dir().iterdir())
    assert size < 4 * 2 ** 20
    x = encode_vectors(sample_vectors(2048, 424242), warn=False)  # fresh held-out hands
    m = reconstruction_metrics(x, reconstruct(vae.model, vae.standardizer, x))
    assert m["presence_accuracy"] >= 0.99 and m["axis_accuracy"] >= 0.98


def test_encode_is_deterministic_and_decode_of_any_latent_is_valid(vae):
    p = sample_vectors(1, 3)[0]
    mu1, lv1 = vae.encode(BaseParams.from_vector(p))
    mu2, _ = vae.encode(BaseParams.from_vector(p))
    assert mu1.shape == lv1.shape == (16,) and np.array_equal(mu1, mu2) and isinstance(mu1, np.ndarray)
    rng = np.random.default_rng(0)
    zs = np.concatenate([rng.normal(size=(40, 16)), rng.normal(size=(10, 16)) * 1e3, np.full((1, 16), 1e3),
                         np.full((1, 16), -1e3), np.full((1, 16), 1e30), np.full((1, 16), np.inf)])
    hands = vae.decode(zs)
    assert len(hands) == len(zs)
    for h in hands[-6:] + hands[:3]:
        HandModel.from_params(h)  # renders and loads
    with pytest.raises(LatentError, match=r"\(16,\)"):
        vae.decode(np.zeros(15))
    with pytest.raises(LatentError, match="NaN"):
        vae.decode(np.full(16, np.nan))


def test_registered_hands_encode_and_reconstruct_their_presence_pattern(vae):
    """Every registered base hand encodes; those whose joint pattern the sampler can produce get
    their presence pattern back exactly. Barrett's "thumb" (finger 3) has no joint 1, a pattern the
    reference sampler never draws: it is outside the training distribution."""
    names = [n for n in ohra.list_hands() if "base" in registry.registered_forms(n)]
    assert {"dex3_right", "shadow_hand_right", "barrett_hand"} <= set(names)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        mu, logvar = vae.encode(names)
        x = np.stack([encode_vectors(ohra.get_hand(n, "base").to_vector()) for n in names])
    assert mu.shape == (len(names), 16) and np.isfinite(mu).all() and np.isfinite(logvar).all()
    support = [in_support(f > 0.5) for f in x[:, FLAGS]]
    assert [n for n, s in zip(names, support) if not s] == ["barrett_hand"]
    y = reconstruct(vae.model, vae.standardizer, x)
    wrong = [n for n, a, b, s in zip(names, x[:, FLAGS], y[:, FLAGS], support) if s and not np.array_equal(a, b)]
    assert not wrong, f"presence pattern not reconstructed for {wrong}"


def test_interpolation_from_dex3_to_shadow(vae):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        it = vae.interpolate("dex3_right", "shadow_hand_right", 8)
    assert isinstance(it, Interpolation) and len(it) == 8 and it.alphas[0] == 0 and it.alphas[-1] == 1
    assert it.params[0].num_fingers == 3 and it.params[-1].num_fingers == 5
    assert it.params[0].dof == ohra.get_hand("dex3_right", "base").dof
    assert it.params[-1].dof == 22
    assert all(p.handedness == "right" for p in it.params)
    for text in it.urdfs:
        HandModel(text)


# -- CLI --------------------------------------------------------------------------------------------
def test_cli_interpolate_writes_urdfs_png_and_html(vae, tmp_path, capsys):
    rc = cli_main(["vae", "interpolate", "dex3_right", "shadow_hand_right", "-n", "4", "-o", str(tmp_path)])
    assert rc == 0
    assert sorted(p.name for p in tmp_path.glob("*.urdf")) == [f"interp_{i:02d}.urdf" for i in range(4)]
    assert (tmp_path / "strip.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "<html" in (tmp_path / "scene.html").read_text()[:2000].lower()
    assert "wrote 4 URDFs" in capsys.readouterr().out


def test_cli_bad_input_is_one_line_and_exit_2(vae, tmp_path, capsys):
    ext = ohra.get_hand("shadow_hand_right", "base").to_extended()
    cases = [
        (["vae", "decode", "1,2,3"], "expected shape (16,)"),
        (["vae", "decode", "a,b"], "comma-separated"),
        (["vae", "encode", "no_such_hand"], "unknown hand"),
    ]
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"\x00garbage")
    cases.append((["vae", "encode", "dex3_right", "--model", str(bad)], "corrupt"))
    d = ext.to_dict()
    d["finger_radii"] = [r * (1.0 + 0.1 * i) for i, r in enumerate(d["finger_radii"])]
    wrong_form = tmp_path / "ext.json"
    wrong_form.write_text(json.dumps(d))
    cases.append((["vae", "encode", str(wrong_form)], "base"))
    for argv, msg in cases:
        rc = cli_main(argv)
        err = capsys.readouterr().err
        assert rc == 2, argv
        assert msg in err and "Traceback" not in err and err.count("\n") == 1, (argv, err)


def test_cli_train_small_run_and_resume(tmp_path, capsys):
    out = tmp_path / "run"
    args = ["train", "vae", "--samples", "1024", "--epochs", "1", "--batch-size", "512", "--threads", "1",
            "--heldout", "128", "-o", str(out), "--quiet"]
    assert cli_main(args) == 0
    assert "held-out (128 hands)" in capsys.readouterr().out
    assert cli_main(args) == 2 and "--resume" in capsys.readouterr().err
    args[args.index("--epochs") + 1] = "2"
    assert cli_main(args + ["--resume"]) == 0
    assert json.loads((out / "metrics.json").read_text())["steps"] == 4
    assert load_vae(out).latent_dim == 16
