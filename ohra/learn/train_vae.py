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
import math
import time
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np
import torch

from ohra.errors import CheckpointError
from ohra.interrupts import DeferredStop
from ohra.io import atomic_write, check_output, folder_lock, write_text
from ohra.learn.config import TrainConfig
from ohra.learn.encoding import Standardizer
from ohra.learn.encodings import DEFAULT_ENCODING, get_encoding
from ohra.learn.geometry import tips_q0
from ohra.learn.sampler import LOWERS, THUMB_RPY, UPPERS, mirror_vectors, sample_vectors
from ohra.learn.vae import GeometryLoss, MorphologyVAE, make_optimizer, path_smoothness, vae_loss
from ohra.learn.vae_metrics import reconstruct, reconstruct_vectors, reconstruction_metrics, shape_metrics
from ohra.transforms import rpy_to_matrix

CHECKPOINT_FORMAT = "ohra-vae-checkpoint"
MODEL_FORMAT = "ohra-vae-model"
FORMAT_VERSION = 1
HELDOUT_SEED_OFFSET = 1_000_003  # held-out hands come from a different seed than the training set
LOSS_TERMS = ("total", "mse", "ce_axis1", "ce_axis2", "bce", "kl", "rot", "tip", "smooth")


@dataclass
class TrainResult:
    model: MorphologyVAE
    standardizer: Standardizer
    metrics: dict[str, Any]
    run_dir: Path | None


# -- data -------------------------------------------------------------------------------------------
@dataclass
class Dataset:
    """Training hands: standardised encodings (N, D) float32 and the geometry targets (thumb
    rotation (N, 3, 3), joint presence (N, 22), q = 0 fingertips (N, 5, 3), NaN-free), of the
    form the encoding holds (right-hand form for an encoding with a left flag)."""

    x: torch.Tensor
    rotation: torch.Tensor
    present: torch.Tensor
    tips: torch.Tensor
    standardizer: Standardizer


def make_dataset(samples: int, seed: int, standardizer: Standardizer | None = None,
                 encoding: str = DEFAULT_ENCODING) -> Dataset:
    """Encoded synthetic hands (continuous part standardised) with their geometry targets."""
    enc = get_encoding(encoding)
    v = sample_vectors(samples, seed)
    x = enc.encode_vectors(v, warn=False)
    if enc.left is not None:  # the geometry targets of the form the encoding holds: left hands mirrored
        left = x[:, enc.left.start] > 0.5
        v[left] = mirror_vectors(v[left])
    if standardizer is None:
        standardizer = Standardizer.fit(x[:, enc.cont])
    x[:, enc.cont] = standardizer.transform(x[:, enc.cont])
    f32 = lambda a: torch.from_numpy(np.ascontiguousarray(a, dtype=np.float32))  # noqa: E731
    return Dataset(f32(x), f32(rpy_to_matrix(v[:, THUMB_RPY])), torch.from_numpy((v[:, LOWERS] != 0) | (v[:, UPPERS] != 0)),
                   f32(np.nan_to_num(tips_q0(v))), standardizer)


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
    old = TrainConfig.from_dict(ckpt["config"], str(path))
    for f in fields(TrainConfig):
        if f.name in TrainConfig.RESUMABLE_CHANGES and not (f.name == "epochs" and cfg.lr_schedule != "constant"):
            continue
        if getattr(old, f.name) != getattr(cfg, f.name):
            raise CheckpointError(
                f"{path}: cannot resume, the checkpoint was trained with {f.name}={getattr(old, f.name)!r}, "
                f"this run asks for {getattr(cfg, f.name)!r}"
            )
    if int(ckpt["epoch"]) > cfg.epochs:
        raise CheckpointError(f"{path}: checkpoint is at epoch {ckpt['epoch']}, beyond the requested {cfg.epochs} epochs")


def _resume_into(ckpt_path: Path, cfg: TrainConfig, digest: str, model, opt, gens) -> tuple[int, int, list]:
    """Load a checkpoint into model, optimiser and generators; returns (epoch, step, history)."""
    ckpt = load_torch_file(ckpt_path, CHECKPOINT_FORMAT)
    _check_resume(ckpt, cfg, ckpt_path)
    if ckpt.get("data_digest") != digest:
        raise CheckpointError(f"{ckpt_path}: training data differ from the checkpoint's (digest mismatch)")
    try:
        model.load_state_dict(ckpt["model"])
        opt.load_state_dict(ckpt["optimizer"])
        torch.set_rng_state(ckpt["rng"]["torch"])
        gens[0].set_state(ckpt["rng"]["data"])
        gens[1].set_state(ckpt["rng"]["noise"])
    except (RuntimeError, KeyError, ValueError) as exc:
        raise CheckpointError(f"{ckpt_path}: incompatible checkpoint ({str(exc).splitlines()[0][:160]})") from None
    return int(ckpt["epoch"]), int(ckpt["step"]), list(ckpt["history"])


def learning_rate(cfg: TrainConfig, step: int, total_steps: int) -> float:
    """Learning rate at ``step``: constant, or cosine from ``lr`` to ``lr * lr_final_ratio``."""
    if cfg.lr_schedule == "constant" or total_steps <= 1:
        return cfg.lr
    t = min(step / (total_steps - 1), 1.0)
    return cfg.lr * (cfg.lr_final_ratio + (1.0 - cfg.lr_final_ratio) * 0.5 * (1.0 + math.cos(math.pi * t)))


def _epoch(model, opt, data: Dataset, geom: GeometryLoss | None, cfg: TrainConfig, gens, step: int,
           total_steps: int) -> tuple[int, dict[str, float]]:
    """One pass over shuffled batches (last partial batch dropped); returns (step, mean losses)."""
    vc = model.config
    perm = torch.randperm(len(data.x), generator=gens[0])
    n_batches = len(data.x) // cfg.batch_size
    sums = {k: 0.0 for k in LOSS_TERMS}
    for b in range(n_batches):
        idx = perm[b * cfg.batch_size : (b + 1) * cfg.batch_size]
        xb = data.x[idx]
        out, mu, logvar = model(xb, generator=gens[1])
        terms = vae_loss(out, xb, mu, logvar, vc.beta, vc.encoding, vc.cont_weight, vc.presence_weight)
        if geom is not None:
            terms.update(geom(out["cont"], data.rotation[idx], data.present[idx], data.tips[idx]))
            terms["total"] = terms["total"] + vc.rot_weight * terms["rot"] + vc.tip_weight * terms["tip"]
            if vc.smooth_weight:
                terms["smooth"] = path_smoothness(model, geom, mu, data.present[idx], gens[1])
                terms["total"] = terms["total"] + vc.smooth_weight * terms["smooth"]
        for group in opt.param_groups:
            group["lr"] = learning_rate(cfg, step, total_steps)
        opt.zero_grad(set_to_none=True)
        terms["total"].backward()
        opt.step()
        step += 1
        for k in LOSS_TERMS:
            sums[k] += float(terms[k].detach()) if k in terms else 0.0
    return step, {k: sums[k] / n_batches for k in LOSS_TERMS}


def heldout_metrics(model, std: Standardizer, n: int, seed: int) -> dict[str, Any]:
    """Encoding-level and hand-level reconstruction metrics on ``n`` sampled hands of ``seed``."""
    enc = get_encoding(model.config.encoding)
    v = sample_vectors(n, seed)
    x = enc.encode_vectors(v, warn=False)
    out = {"seed": seed, **reconstruction_metrics(x, reconstruct(model, std, x), enc)}
    out["shape"] = shape_metrics(v, reconstruct_vectors(model, std, v))
    return out


def _final_metrics(model, std: Standardizer, cfg: TrainConfig, step: int, history: list, seconds: float) -> dict[str, Any]:
    """What metrics.json holds: losses per epoch, timing, memory, held-out reconstruction."""
    metrics: dict[str, Any] = {
        "epochs": cfg.epochs, "steps": step, "train_seconds_this_run": seconds,
        "train_seconds_total": history[-1]["elapsed_s"] if history else 0.0, "history": history,
        "final_losses": {k: history[-1][k] for k in LOSS_TERMS} if history else {},
        "cpu_seconds": time.process_time(), "peak_rss_mib": _peak_rss_mib(),
    }
    if cfg.heldout > 0:
        metrics["heldout"] = heldout_metrics(model, std, cfg.heldout, cfg.seed + HELDOUT_SEED_OFFSET)
    return metrics


def train(config: TrainConfig = TrainConfig(), run_dir: str | Path | None = None, resume: bool = False,
          progress: bool = True, on_epoch: Callable[[int, dict[str, float]], None] | None = None) -> TrainResult:
    """Train the VAE on ``config.samples`` synthetic hands; see the module docstring for outputs.

    ``resume``: continue from ``run_dir/checkpoints/last.pt`` (the configuration must match except
    for ``checkpoint_every`` and ``heldout``; the result equals an uninterrupted run).
    ``on_epoch(epoch, losses)`` is called after every epoch (e.g. to stop a run in a test).
    """
    from tqdm import tqdm

    cfg = config
    if cfg.samples < cfg.batch_size:
        raise CheckpointError(f"samples ({cfg.samples}) must be at least one batch ({cfg.batch_size}; ohra train vae: "
                              "--samples, --batch-size)")
    run = Path(run_dir) if run_dir is not None else None
    if run is not None:
        check_output(run, folder=True)  # before the minutes of training, not at the first write
    ckpt_path = run / "checkpoints" / "last.pt" if run is not None else None
    t_start = time.perf_counter()
    # one writer per run folder: a second process in the same folder would mix two runs' files
    lock = folder_lock(run, "VAE training run") if run is not None else contextlib.nullcontext()
    with lock, torch_settings(cfg.threads):
        vc = cfg.vae_config()
        data = make_dataset(cfg.samples, cfg.seed, encoding=vc.encoding)
        std = data.standardizer
        digest = _digest(data.x)
        torch.manual_seed(cfg.seed)
        model = MorphologyVAE(vc)
        geom = GeometryLoss(vc, std.mean, std.std) if (vc.rot_weight or vc.tip_weight or vc.smooth_weight) else None
        opt = make_optimizer(model, cfg.lr, cfg.betas, cfg.weight_decay)
        gens = (torch.Generator().manual_seed(cfg.seed), torch.Generator().manual_seed(cfg.seed + 1))
        epoch, step, history = 0, 0, []
        if resume:
            if ckpt_path is None:
                raise CheckpointError("resume needs a run directory")
            epoch, step, history = _resume_into(ckpt_path, cfg, digest, model, opt, gens)
        elapsed_before = float(history[-1]["elapsed_s"]) if history else 0.0
        done_before = len(history)
        if run is not None:
            write_text(run / "config.json", json.dumps(cfg.to_dict(), indent=2) + "\n")

        model.train()
        total_steps = cfg.epochs * (len(data.x) // cfg.batch_size)
        bar = tqdm(range(epoch, cfg.epochs), initial=epoch, total=cfg.epochs, desc="train vae", unit="epoch",
                   disable=not progress, dynamic_ncols=True)
        t_run = time.perf_counter()

        def checkpoint(done: int) -> None:
            atomic_save(_state(model, opt, done, step, gens, history, cfg, std, digest), ckpt_path)

        try:
            with DeferredStop("VAE training", at="after the current epoch") as stop:
                for ep in bar:
                    step, losses = _epoch(model, opt, data, geom, cfg, gens, step, total_steps)
                    history.append({"epoch": ep + 1, "step": step, **losses,
                                    "elapsed_s": elapsed_before + time.perf_counter() - t_run})
                    bar.set_postfix(loss=f"{losses['total']:.4f}", kl=f"{losses['kl']:.2f}")
                    done = ep + 1
                    periodic = ckpt_path is not None and (done % cfg.checkpoint_every == 0 or done == cfg.epochs)
                    if periodic:
                        checkpoint(done)
                    if on_epoch is not None:
                        on_epoch(done, losses)
                    if stop.requested:  # Ctrl-C waits for the epoch's end: a checkpoint there resumes exactly
                        if ckpt_path is not None and not periodic:
                            checkpoint(done)
                        stop.stop()  # a handler that returns (it chose to go on) lets training go on
        finally:
            bar.close()
        # the epochs' own time, as train_seconds_total counts it (not the last checkpoint's save after them)
        this_run = float(history[-1]["elapsed_s"]) - elapsed_before if len(history) > done_before else 0.0
        metrics = _final_metrics(model, std, cfg, step, history, this_run)
        metrics["wall_seconds"] = time.perf_counter() - t_start
        if run is not None:
            atomic_save(model_payload(model, std), run / "model.pt")
            write_text(run / "metrics.json", json.dumps(metrics, indent=2) + "\n")
    model.eval()
    return TrainResult(model, std, metrics, run)
