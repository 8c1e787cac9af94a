"""The morphology VAE (torch): hand encoding <-> latent (reference §7.3 architecture).

Encoder: Linear(D, 512)-BN-ReLU, Linear(512, 256)-BN-ReLU, Linear(256, 128)-BN-ReLU, then two
Linear(128, latent) heads for the mean and log-variance. Decoder, mirrored: Linear(latent, 128)-BN-ReLU,
(128, 256)-BN-ReLU, (256, 512)-BN-ReLU and four heads from 512 features: the continuous values
(standardised units), two 6-way logits for the thumb axes and 22 presence logits. ``D`` and the
continuous size come from the encoding (:mod:`ohra.learn.encodings`): 66 / 32 for the paper's
``reference66``, 70 / 35 for ``rot6d70``.

Loss (:func:`vae_loss`) = ``cont_weight`` x MSE(continuous, mean over values) + CE(axis 1) + CE(axis 2)
+ ``presence_weight`` x BCE(presence, mean over flags) + beta x KL, with
``KL = -1/2 mean_batch sum_latent (1 + logvar - mu^2 - exp(logvar))``; the paper's setting is
``cont_weight = presence_weight = 1, beta = 0.01``. With the geometry terms the flags need the
weight of a sum over flags (``presence_weight = 22``): at 1 their gradient drowns and presence
accuracy stays near 73 % (measured, 20 epochs). :class:`GeometryLoss` adds, on the
decoded hand in metres (teacher-forced joint presence):

* ``rot``: Frobenius distance of the decoded thumb mounting rotation to the true one
  (``2 sqrt(2) sin(theta / 2)``, about ``1.4 theta``, for a rotation error ``theta``);
* ``tip``: mean fingertip distance at q = 0 over present fingers, in units of ``tip_scale``
  metres, from the batched torch FK of the canonical tree (:mod:`ohra.learn.fk_torch`);
* ``smooth`` (:func:`path_smoothness`): fingertip moves beyond 1.5 cm of one 1/15 step along the
  latent line between two training hands.

Both are distances, not squares (pseudo-Huber, smooth at 0): squared tip errors of several
centimetres early in training outweigh the classification terms so much that, through Adam's
per-weight scaling, presence and axis accuracy collapse (measured: 70 % / 20 % after 20 epochs).

Unlike the reference, the continuous targets are standardised and the presence head returns logits.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from typing import Any

import torch
from torch import nn
from torch.nn import functional as F

from ohra.learn.encodings import get_encoding
from ohra.learn.fk_torch import finger_presence, rpy_matrix, tips

REFERENCE_ENCODING = "reference66"


@dataclass(frozen=True)
class VAEConfig:
    """Architecture and loss weights. The defaults are the paper's (the 66-D reference encoding);
    a config without the newer keys (a model saved before they existed) reads as those defaults."""

    input_dim: int = 66
    hidden: tuple[int, ...] = (512, 256, 128)
    latent_dim: int = 16
    beta: float = 0.01
    encoding: str = REFERENCE_ENCODING
    cont_weight: float = 1.0
    presence_weight: float = 1.0
    rot_weight: float = 0.0
    tip_weight: float = 0.0
    smooth_weight: float = 0.0
    tip_scale: float = 0.01  # m

    def __post_init__(self) -> None:
        from ohra.errors import ParamsError

        enc = get_encoding(self.encoding)
        if self.input_dim != enc.dim:
            raise ParamsError(f"VAEConfig: input_dim {self.input_dim} does not match encoding {enc.name!r} ({enc.dim})")
        sizes = [self.latent_dim, *self.hidden]
        if any(isinstance(k, bool) or not isinstance(k, int) or k < 1 for k in sizes):
            raise ParamsError(f"VAEConfig: latent_dim and hidden sizes must be whole numbers >= 1, got latent_dim="
                              f"{self.latent_dim!r}, hidden={tuple(self.hidden)!r}")

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["hidden"] = list(self.hidden)
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "VAEConfig":
        kw: dict[str, Any] = {}
        for f in fields(cls):
            if f.name in d:
                kw[f.name] = tuple(int(h) for h in d[f.name]) if f.name == "hidden" else type(f.default)(d[f.name])
        unknown = set(d) - {f.name for f in fields(cls)}
        if unknown:
            raise ValueError(f"VAEConfig: unknown keys {sorted(unknown)}")
        return cls(**kw)


def _mlp(sizes: list[int]) -> nn.Sequential:
    layers: list[nn.Module] = []
    for a, b in zip(sizes[:-1], sizes[1:]):
        layers += [nn.Linear(a, b), nn.BatchNorm1d(b), nn.ReLU()]
    return nn.Sequential(*layers)


class MorphologyVAE(nn.Module):
    """MLP VAE over hand encodings (continuous part standardised)."""

    def __init__(self, config: VAEConfig = VAEConfig()):
        super().__init__()
        self.config = config
        enc = get_encoding(config.encoding)
        h = list(config.hidden)
        self.encoder = _mlp([config.input_dim, *h])
        self.fc_mu = nn.Linear(h[-1], config.latent_dim)
        self.fc_logvar = nn.Linear(h[-1], config.latent_dim)
        self.decoder = _mlp([config.latent_dim, *reversed(h)])
        self.head_cont = nn.Linear(h[0], enc.cont_dim)
        self.head_axis1 = nn.Linear(h[0], 6)
        self.head_axis2 = nn.Linear(h[0], 6)
        self.head_presence = nn.Linear(h[0], enc.binary.stop - enc.binary.start)  # 22 flags (+ left flag)

    def encode(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(B, D) -> mean and log-variance, each (B, latent_dim)."""
        f = self.encoder(x)
        return self.fc_mu(f), self.fc_logvar(f)

    def decode(self, z: torch.Tensor) -> dict[str, torch.Tensor]:
        """(B, latent_dim) -> dict of ``cont`` (B, C), ``axis1``/``axis2`` logits (B, 6), ``presence`` logits
        (B, 22, or 23 with the left-hand flag last)."""
        f = self.decoder(z)
        return {
            "cont": self.head_cont(f),
            "axis1": self.head_axis1(f),
            "axis2": self.head_axis2(f),
            "presence": self.head_presence(f),
        }

    def forward(self, x: torch.Tensor, generator: torch.Generator | None = None):
        """Encode, reparameterise (noise from ``generator``) and decode; returns (out, mu, logvar)."""
        mu, logvar = self.encode(x)
        eps = torch.randn(mu.shape, generator=generator, dtype=mu.dtype, device=mu.device)
        z = mu + eps * torch.exp(0.5 * logvar)
        return self.decode(z), mu, logvar


def vae_loss(out: dict[str, torch.Tensor], x: torch.Tensor, mu: torch.Tensor, logvar: torch.Tensor,
             beta: float = 0.01, encoding: str = REFERENCE_ENCODING, cont_weight: float = 1.0,
             presence_weight: float = 1.0) -> dict[str, torch.Tensor]:
    """Loss terms (``mse``, ``ce_axis1``, ``ce_axis2``, ``bce``, ``kl``) and their ``total``."""
    enc = get_encoding(encoding)
    terms = {
        "mse": F.mse_loss(out["cont"], x[:, enc.cont]),
        "ce_axis1": F.cross_entropy(out["axis1"], x[:, enc.axis1].argmax(dim=1)),
        "ce_axis2": F.cross_entropy(out["axis2"], x[:, enc.axis2].argmax(dim=1)),
        "bce": F.binary_cross_entropy_with_logits(out["presence"], x[:, enc.binary]),
        "kl": -0.5 * torch.mean(torch.sum(1.0 + logvar - mu.pow(2) - logvar.exp(), dim=1)),
    }
    terms["total"] = (cont_weight * terms["mse"] + terms["ce_axis1"] + terms["ce_axis2"] + presence_weight * terms["bce"]
                      + beta * terms["kl"])
    return terms


def gram_schmidt(x6: torch.Tensor, order: str = "xy") -> torch.Tensor:
    """(B, 6) rot6d -> (B, 3, 3) rotations (differentiable); ``order`` as in
    :func:`ohra.learn.geometry.matrix_from_rot6d` (``"zx"``: z column first, then x)."""
    a, b = x6[:, 0:3], x6[:, 3:6]
    e1 = F.normalize(a, dim=1, eps=1e-8)
    e2 = F.normalize(b - (e1 * b).sum(1, keepdim=True) * e1, dim=1, eps=1e-8)
    e3 = torch.linalg.cross(e1, e2, dim=1)
    return torch.stack([e1, e2, e3] if order == "xy" else [e2, e3, e1], dim=2)


class GeometryLoss(nn.Module):
    """The ``rot`` and ``tip`` terms on decoded hands in metres (see the module docstring).

    Built from the config and the standardiser (mean/std of the continuous block, raw units).
    Targets come per batch: the true thumb rotation (B, 3, 3), joint presence (B, 22) and q = 0
    fingertips (B, 5, 3).
    """

    def __init__(self, config: VAEConfig, mean: Any, std: Any):
        super().__init__()
        self.config = config
        self.enc = get_encoding(config.encoding)
        self.register_buffer("mean", torch.as_tensor(mean, dtype=torch.float32))
        self.register_buffer("std", torch.as_tensor(std, dtype=torch.float32))

    def thumb_rotation(self, raw: torch.Tensor) -> torch.Tensor:
        rot = raw[:, self.enc.rotation.start - self.enc.cont.start : self.enc.rotation.stop - self.enc.cont.start]
        return gram_schmidt(rot, "zx") if rot.shape[1] == 6 else rpy_matrix(rot)

    def tips(self, cont: torch.Tensor, present: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Decoded continuous block (standardised, (B, C)) and joint presence (B, 22) -> q = 0 fingertips
        (B, 5, 3) [m] and the thumb mounting rotations (B, 3, 3)."""
        raw = cont * self.std + self.mean
        R = self.thumb_rotation(raw)
        n = len(raw)
        t = tips(raw[:, 8:23].reshape(n, 5, 3), raw[:, 2:8].reshape(n, 2, 3), R, torch.zeros(n, 2, 3, dtype=raw.dtype),
                 raw[:, 23:29], present)
        return t, R

    def forward(self, cont: torch.Tensor, R_true: torch.Tensor, present: torch.Tensor,
                tips_true: torch.Tensor) -> dict[str, torch.Tensor]:
        t, R = self.tips(cont, present)
        mask = finger_presence(present)
        d = _soft_norm(((t - tips_true) / self.config.tip_scale).pow(2).sum(-1))
        return {
            "rot": _soft_norm((R - R_true).pow(2).sum((1, 2))).mean(),
            "tip": (d * mask).sum() / mask.sum().clamp(min=1),
        }


def path_smoothness(model: "MorphologyVAE", geom: GeometryLoss, mu: torch.Tensor, present: torch.Tensor,
                    generator: torch.Generator, steps: int = 15, limit: float = 0.015) -> torch.Tensor:
    """How far a latent interpolation step moves fingertips beyond ``limit`` metres.

    Each hand i is paired with the next one in the batch; at a random point of the straight line
    between their mean latents the decoder takes one step of 1/``steps`` of the line, and every
    finger present in both hands whose q = 0 tip moves more than ``limit`` adds the excess (in
    ``tip_scale`` units). This is the benchmark's interpolation check, trained on pairs of training
    hands, so that the latent space between hands decodes to hands in between.
    """
    mu_j = torch.roll(mu, 1, dims=0)
    both = present & torch.roll(present, 1, dims=0)
    alpha = torch.rand(len(mu), 1, generator=generator, dtype=mu.dtype)
    z_a = mu + alpha * (mu_j - mu)
    z_b = z_a + (mu_j - mu) / steps
    t_a, _ = geom.tips(model.decode(z_a)["cont"], both)
    t_b, _ = geom.tips(model.decode(z_b)["cont"], both)
    excess = torch.relu(torch.sqrt((t_a - t_b).pow(2).sum(-1) + 1e-12) - limit) / geom.config.tip_scale
    mask = finger_presence(both)
    return (excess * mask).sum() / mask.sum().clamp(min=1)


SOFT = 0.1  # pseudo-Huber width: 1 mm in tip units, 0.07 rad for rotations


def _soft_norm(sq: torch.Tensor) -> torch.Tensor:
    """sqrt(sq + SOFT^2) - SOFT: a distance (bounded gradient, unlike its square), smooth at 0."""
    return torch.sqrt(sq + SOFT * SOFT) - SOFT


def make_optimizer(model: nn.Module, lr: float = 1e-4, betas: tuple[float, float] = (0.95, 0.999),
                   weight_decay: float = 1e-6) -> torch.optim.Adam:
    """Adam with the paper's settings (the reference code leaves betas and weight decay unused)."""
    return torch.optim.Adam(model.parameters(), lr=lr, betas=betas, weight_decay=weight_decay)


def outputs_to_encoding(out: dict[str, torch.Tensor]) -> torch.Tensor:
    """Decoder outputs -> (B, D): continuous (standardised), axis logits, presence probabilities."""
    return torch.cat([out["cont"], out["axis1"], out["axis2"], torch.sigmoid(out["presence"])], dim=1)


__all__ = ["VAEConfig", "MorphologyVAE", "vae_loss", "GeometryLoss", "path_smoothness", "gram_schmidt", "make_optimizer",
           "outputs_to_encoding"]
