"""Training of the morphology VAE: fixed synthetic dataset, periodic atomic checkpoints, exact resume.

A run directory holds::

    checkpoints/last.pt   model + optimiser + RNG states + epoch/step + loss history (every
                          ``checkpoint_every`` epochs and at the end; written atomically)
    model.pt              the trained model (weights + standardiser + architecture), what load_vae reads
    config.json           the training configuration
    metrics.json          per-epoch losses, held-out reconstruction metrics, timing

Determinism: given the seed, training on CPU is bit-for-bit reproducible (explicit torch
generators for shuffling and reparameterisation noise, deterministic algorithms, a fixed number of
threads), and resuming from a checkpoint gives exactly the weights of an uninterrupted run: the
checkpoint stores everything the next step depends on.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import time
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np
import torch

from ohra.errors import CheckpointError
from ohra.io import atomic_write, write_text
from ohra.learn.encoding import AXIS1, AXIS2, CONT, CONT_GROUPS, FLAGS, Standardizer, encode_vectors
from ohra.learn.sampler import sample_vectors
from ohra.learn.config import TrainConfig
from ohra.learn.vae import MorphologyVAE, make_optimizer, vae_loss

CHECKPOINT_FORMAT = "ohra-vae-checkpoint"
MODEL_FORMAT = "ohra-vae-model"
FORMAT_VERSION = 1
HELDOUT_SEED_OFFSET = 1_000_003  # held-out hands come from a different seed than the training set
LOSS_TERMS = ("total", "mse", "ce_axis1", "ce_axis2", "bce", "kl")


@dataclass
class TrainResult:
    model: MorphologyVAE
    standardizer: Standardizer
    metrics: dict[str, Any]
    run_dir: Path | None


# -- data -------------------------------------------------------------------------------------------
def make_dataset(samples: int, seed: int, standardizer: Standardizer | None = None) -> tuple[torch.Tensor, Standardizer]:
    """Encoded synthetic hands (float32, continuous part standardised) and the standardiser used."""
    x = encode_vectors(sample_vectors(samples, seed), warn=False)
    if standardizer is None:
        standardizer = Standardizer.fit(x[:, CONT])
    x[:, CONT] = standardizer.transform(x[:, CONT])
    return torch.from_numpy(x.astype(np.float32)), standardizer


def _digest(x: torch.Tensor) -> str:
    return hashlib.sha256(x.numpy().tobytes()).hexdigest()[:16]


# -- io ---------------------------------------------------------------------------------------------
def atomic_save(obj: Any, path: Path) -> None:
    """torch.save to a temporary file in the same folder, then rename over ``path`` (see :mod:`ohra.io`)."""
    atomic_write(path, lambda fh: torch.save(obj, fh))


def load_torch_file(path: Path, expected_format: str) -> dict[str, Any]:
    """A checkpoint/model dict, or :class:`CheckpointError` saying what is wrong with the file."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"checkpoint not found: {path}")
    try:
        obj = torch.load(io.BytesIO(path.read_bytes()), map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises assorted errors for truncated / foreign files
        raise CheckpointError(f"{path}: corrupt or not a torch checkpoint ({type(exc).__name__})") from None
    if not isinstance(obj, dict) or obj.get("format") != expected_format:
        got = obj.get("format") if isinstance(obj, dict) else type(obj).__name__
        raise CheckpointError(f"{path}: expected an {expected_format!r} file, got {got!r}")
    if int(obj.get("version", -1)) != FORMAT_VERSION:
        raise CheckpointError(f"{path}: format version {obj.get('version')!r}, this ohra reads version {FORMAT_VERSION}")
    return obj


@contextlib.contextmanager
def torch_settings(threads: int) -> Iterator[None]:
    """Fixed thread count and deterministic algorithms for the duration of a run (then restored)."""
    old_threads = torch.get_num_threads()
    old_det = torch.are_deterministic_algorithms_enabled()
    torch.set_num_threads(max(1, int(threads)))
    torch.use_deterministic_algorithms(True)
    try:
        yield
    finally:
        torch.set_num_threads(old_threads)
        torch.use_deterministic_algorithms(old_det)


# -- evaluation -------------------------------------------------------------------------------------
@torch.no_grad()
def reconstruct(model: MorphologyVAE, standardizer: Standardizer, x_raw: np.ndarray, batch: int = 8192) -> np.ndarray:
    """Encode with the mean latent and decode (eval mode): raw encodings (N, 66) -> (N, 66).

    Output: continuous part in raw units, axis groups as one-hot, presence flags as 0/1.
    """
    was_training = model.training
    model.eval()
    outs = []
    for i in range(0, len(x_raw), batch):
        xb = np.array(x_raw[i : i + batch], dtype=float, copy=True)
        xb[:, CONT] = standardizer.transform(xb[:, CONT])
        mu, _ = model.encode(torch.from_numpy(xb.astype(np.float32)))
        o = model.decode(mu)
        y = np.zeros((len(xb), 66))
        y[:, CONT] = standardizer.inverse(o["cont"].double().numpy())
        rows = np.arange(len(xb))
        y[rows, AXIS1.start + o["axis1"].argmax(dim=1).numpy()] = 1.0
        y[rows, AXIS2.start + o["axis2"].argmax(dim=1).numpy()] = 1.0
        y[:, FLAGS] = (o["presence"] > 0).double().numpy()
        outs.append(y)
    model.train(was_training)
    return np.concatenate(outs) if outs else np.zeros((0, 66))


def reconstruction_metrics(x_raw: np.ndarray, y: np.ndarray) -> dict[str, Any]:
    """Accuracy and RMSE of reconstructions ``y`` of raw encodings ``x_raw`` (both (N, 66)).

    ``presence_accuracy``: fraction of the 22N flags right; ``presence_exact``: fraction of hands
    with all 22 right. ``axis_accuracy``: thumb axes of present (movable) thumb joints 1/2;
    ``axis_accuracy_all``: both axis slots of every hand (absent axes encode as +x).
    RMSE per parameter group in metres / radians, over the values of the present parts.
    """
    flags_t, flags_y = x_raw[:, FLAGS] > 0.5, y[:, FLAGS] > 0.5
    a_t = np.stack([x_raw[:, AXIS1].argmax(1), x_raw[:, AXIS2].argmax(1)], axis=1)
    a_y = np.stack([y[:, AXIS1].argmax(1), y[:, AXIS2].argmax(1)], axis=1)
    present_axes = flags_t[:, :2]
    err = y[:, CONT] - x_raw[:, CONT]
    rmse = {}
    for name, (sl, unit) in CONT_GROUPS.items():
        e = err[:, sl]
        mask = x_raw[:, CONT][:, sl] != 0.0  # zeros mark parts that are absent in this hand
        rmse[f"{name}_{unit}"] = float(np.sqrt(np.mean(e[mask] ** 2))) if mask.any() else 0.0
    return {
        "n": int(len(x_raw)),
        "presence_accuracy": float(np.mean(flags_t == flags_y)),
        "presence_exact": float(np.mean(np.all(flags_t == flags_y, axis=1))),
        "axis_accuracy": float(np.mean((a_t == a_y)[present_axes])) if present_axes.any() else 1.0,
        "axis_accuracy_all": float(np.mean(a_t == a_y)),
        "rmse": rmse,
    }


def _peak_rss_mib() -> float | None:
    """Peak resident memory of this process so far [MiB] (None where the platform has no getrusage)."""
    try:
        import resource
    except ImportError:  # pragma: no cover - Windows
        return None
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


# -- training ---------------------------------------------------------------------------------------
def _state(model, opt, epoch, step, gens, history, cfg, std, digest) -> dict[str, Any]:
    return {
        "format": CHECKPOINT_FORMAT,
        "version": FORMAT_VERSION,
        "config": cfg.to_dict(),
        "vae_config": cfg.vae_config().to_dict(),
        "model": model.state_dict(),
        "optimizer": opt.state_dict(),
        "standardizer": {k: torch.tensor(v) for k, v in std.to_dict().items()},
        "epoch": epoch,
        "step": step,
        "rng": {"torch": torch.get_rng_state(), "data": gens[0].get_state(), "noise": gens[1].get_state()},
        "history": history,
        "data_digest": digest,
    }


def model_payload(model: MorphologyVAE, std: Standardizer) -> dict[str, Any]:
    """What ``model.pt`` holds: weights, standardiser and architecture (no optimiser state)."""
    return {
        "format": MODEL_FORMAT,
        "version": FORMAT_VERSION,
        "vae_config": model.config.to_dict(),
        "model": model.state_dict(),
        "standardizer": {k: torch.tensor(v) for k, v in std.to_dict().items()},
    }


def _check_resume(ckpt: dict[str, Any], cfg: TrainConfig, path: Path) -> None:
    old = TrainConfig.from_dict(ckpt["config"])
    for f in fields(TrainConfig):
        if f.name in TrainConfig.RESUMABLE_CHANGES:
            continue
        if getattr(old, f.name) != getattr(cfg, f.name):
            raise CheckpointError(
                f"{path}: cannot resume, the checkpoint was trained with {f.name}={getattr(old, f.name)!r}, "
                f"this run asks for {getattr(cfg, f.name)!r}"
            )
    if int(ckpt["epoch"]) > cfg.epochs:
        raise CheckpointError(f"{path}: checkpoint is at epoch {ckpt['epoch']}, beyond the requested {cfg.epochs} epochs")


def train(config: TrainConfig = TrainConfig(), run_dir: str | Path | None = None, resume: bool = False,
          progress: bool = True, on_epoch: Callable[[int, dict[str, float]], None] | None = None) -> TrainResult:
    """Train the VAE on ``config.samples`` synthetic hands; see the module docstring for outputs.

    ``resume``: continue from ``run_dir/checkpoints/last.pt`` (the configuration must match except
    for ``epochs``, ``checkpoint_every`` and ``heldout``; the result equals an uninterrupted run).
    ``on_epoch(epoch, losses)`` is called after every epoch (e.g. to stop a run in a test).
    """
    from tqdm import tqdm

    cfg = config
    if cfg.samples < cfg.batch_size:
        raise CheckpointError(f"samples ({cfg.samples}) must be at least one batch ({cfg.batch_size})")
    run = Path(run_dir) if run_dir is not None else None
    ckpt_path = run / "checkpoints" / "last.pt" if run is not None else None
    t_start = time.perf_counter()
    with torch_settings(cfg.threads):
        x, std = make_dataset(cfg.samples, cfg.seed)
        digest = _digest(x)
        torch.manual_seed(cfg.seed)
        model = MorphologyVAE(cfg.vae_config())
        opt = make_optimizer(model, cfg.lr, cfg.betas, cfg.weight_decay)
        g_data = torch.Generator().manual_seed(cfg.seed)
        g_noise = torch.Generator().manual_seed(cfg.seed + 1)
        epoch, step, history, elapsed_before = 0, 0, [], 0.0
        if resume:
            if ckpt_path is None:
                raise CheckpointError("resume needs a run directory")
            ckpt = load_torch_file(ckpt_path, CHECKPOINT_FORMAT)
            _check_resume(ckpt, cfg, ckpt_path)
            if ckpt.get("data_digest") != digest:
                raise CheckpointError(f"{ckpt_path}: training data differ from the checkpoint's (digest mismatch)")
            try:
                model.load_state_dict(ckpt["model"])
                opt.load_state_dict(ckpt["optimizer"])
                torch.set_rng_state(ckpt["rng"]["torch"])
                g_data.set_state(ckpt["rng"]["data"])
                g_noise.set_state(ckpt["rng"]["noise"])
            except (RuntimeError, KeyError, ValueError) as exc:
                raise CheckpointError(f"{ckpt_path}: incompatible checkpoint ({str(exc).splitlines()[0][:160]})") from None
            epoch, step, history = int(ckpt["epoch"]), int(ckpt["step"]), list(ckpt["history"])
            elapsed_before = float(history[-1]["elapsed_s"]) if history else 0.0
        if run is not None:
            write_text(run / "config.json", json.dumps(cfg.to_dict(), indent=2) + "\n")

        model.train()
        n_batches = len(x) // cfg.batch_size
        bar = tqdm(range(epoch, cfg.epochs), initial=epoch, total=cfg.epochs, desc="train vae", unit="epoch",
                   disable=not progress, dynamic_ncols=True)
        t_run = time.perf_counter()
        for ep in bar:
            perm = torch.randperm(len(x), generator=g_data)
            sums = {k: 0.0 for k in LOSS_TERMS}
            for b in range(n_batches):
                xb = x[perm[b * cfg.batch_size : (b + 1) * cfg.batch_size]]
                out, mu, logvar = model(xb, generator=g_noise)
                terms = vae_loss(out, xb, mu, logvar, cfg.beta)
                opt.zero_grad(set_to_none=True)
                terms["total"].backward()
                opt.step()
                step += 1
                for k in LOSS_TERMS:
                    sums[k] += float(terms[k].detach())
            losses = {k: sums[k] / n_batches for k in LOSS_TERMS}
            history.append({"epoch": ep + 1, "step": step, **losses,
                            "elapsed_s": elapsed_before + time.perf_counter() - t_run})
            bar.set_postfix(loss=f"{losses['total']:.4f}", kl=f"{losses['kl']:.2f}")
            done = ep + 1
            if ckpt_path is not None and (done % cfg.checkpoint_every == 0 or done == cfg.epochs):
                atomic_save(_state(model, opt, done, step, (g_data, g_noise), history, cfg, std, digest), ckpt_path)
            if on_epoch is not None:
                on_epoch(done, losses)
        bar.close()
        train_seconds = time.perf_counter() - t_run

        metrics: dict[str, Any] = {
            "epochs": cfg.epochs,
            "steps": step,
            "train_seconds_this_run": train_seconds,
            "train_seconds_total": history[-1]["elapsed_s"] if history else 0.0,
            "history": history,
            "final_losses": {k: history[-1][k] for k in LOSS_TERMS} if history else {},
        }
        if cfg.heldout > 0:
            x_held = encode_vectors(sample_vectors(cfg.heldout, cfg.seed + HELDOUT_SEED_OFFSET), warn=False)
            metrics["heldout"] = {"seed": cfg.seed + HELDOUT_SEED_OFFSET,
                                  **reconstruction_metrics(x_held, reconstruct(model, std, x_held))}
        metrics["wall_seconds"] = time.perf_counter() - t_start
        metrics["peak_rss_mib"] = _peak_rss_mib()
    if run is not None:
        atomic_save(model_payload(model, std), run / "model.pt")
        write_text(run / "metrics.json", json.dumps(metrics, indent=2) + "\n")
    model.eval()
    return TrainResult(model, std, metrics, run)
