"""The morphology VAE (torch): 66-D hand encoding <-> 16-D latent (reference §7.3, paper settings).

Encoder: Linear(66, 512)-BN-ReLU, Linear(512, 256)-BN-ReLU, Linear(256, 128)-BN-ReLU, then two
Linear(128, 16) heads for the mean and log-variance. Decoder, mirrored: Linear(16, 128)-BN-ReLU,
(128, 256)-BN-ReLU, (256, 512)-BN-ReLU and four heads from 512 features: 32 continuous values
(standardised units), two 6-way logits for the thumb axes and 22 presence logits.

Loss = MSE(continuous) + CE(axis 1) + CE(axis 2) + BCE(presence) + beta * KL, beta = 0.01, with
``KL = -1/2 * mean_batch sum_latent (1 + logvar - mu^2 - exp(logvar))``. Unlike the reference,
the continuous targets are standardised (see :mod:`ohra.learn.encoding`), and the presence head
returns logits (BCE-with-logits: the same loss, numerically stable).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import torch
from torch import nn
from torch.nn import functional as F

from ohra.learn.encoding import AXIS1, AXIS2, CONT, CONT_DIM, ENCODING_DIM, FLAGS


@dataclass(frozen=True)
class VAEConfig:
    """Architecture and loss weights (paper settings by default)."""

    input_dim: int = ENCODING_DIM
    hidden: tuple[int, ...] = (512, 256, 128)
    latent_dim: int = 16
    beta: float = 0.01

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["hidden"] = list(self.hidden)
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "VAEConfig":
        return cls(int(d["input_dim"]), tuple(int(h) for h in d["hidden"]), int(d["latent_dim"]), float(d["beta"]))


def _mlp(sizes: list[int]) -> nn.Sequential:
    layers: list[nn.Module] = []
    for a, b in zip(sizes[:-1], sizes[1:]):
        layers += [nn.Linear(a, b), nn.BatchNorm1d(b), nn.ReLU()]
    return nn.Sequential(*layers)


class MorphologyVAE(nn.Module):
    """MLP VAE over 66-D hand encodings (continuous part standardised)."""

    def __init__(self, config: VAEConfig = VAEConfig()):
        super().__init__()
        self.config = config
        h = list(config.hidden)
        self.encoder = _mlp([config.input_dim, *h])
        self.fc_mu = nn.Linear(h[-1], config.latent_dim)
        self.fc_logvar = nn.Linear(h[-1], config.latent_dim)
        self.decoder = _mlp([config.latent_dim, *reversed(h)])
        self.head_cont = nn.Linear(h[0], CONT_DIM)
        self.head_axis1 = nn.Linear(h[0], 6)
        self.head_axis2 = nn.Linear(h[0], 6)
        self.head_presence = nn.Linear(h[0], 22)

    def encode(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(B, 66) -> mean and log-variance, each (B, latent_dim)."""
        f = self.encoder(x)
        return self.fc_mu(f), self.fc_logvar(f)

    def decode(self, z: torch.Tensor) -> dict[str, torch.Tensor]:
        """(B, latent_dim) -> dict of ``cont`` (B, 32), ``axis1``/``axis2`` logits (B, 6), ``presence`` logits (B, 22)."""
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
             beta: float = 0.01) -> dict[str, torch.Tensor]:
    """Loss terms (``mse``, ``ce_axis1``, ``ce_axis2``, ``bce``, ``kl``) and their ``total``."""
    terms = {
        "mse": F.mse_loss(out["cont"], x[:, CONT]),
        "ce_axis1": F.cross_entropy(out["axis1"], x[:, AXIS1].argmax(dim=1)),
        "ce_axis2": F.cross_entropy(out["axis2"], x[:, AXIS2].argmax(dim=1)),
        "bce": F.binary_cross_entropy_with_logits(out["presence"], x[:, FLAGS]),
        "kl": -0.5 * torch.mean(torch.sum(1.0 + logvar - mu.pow(2) - logvar.exp(), dim=1)),
    }
    terms["total"] = terms["mse"] + terms["ce_axis1"] + terms["ce_axis2"] + terms["bce"] + beta * terms["kl"]
    return terms


def make_optimizer(model: nn.Module, lr: float = 1e-4, betas: tuple[float, float] = (0.95, 0.999),
                   weight_decay: float = 1e-6) -> torch.optim.Adam:
    """Adam with the paper's settings (the reference code leaves betas and weight decay unused)."""
    return torch.optim.Adam(model.parameters(), lr=lr, betas=betas, weight_decay=weight_decay)


def outputs_to_encoding(out: dict[str, torch.Tensor]) -> torch.Tensor:
    """Decoder outputs -> (B, 66): continuous (standardised), axis logits, presence probabilities."""
    return torch.cat([out["cont"], out["axis1"], out["axis2"], torch.sigmoid(out["presence"])], dim=1)


__all__ = ["VAEConfig", "MorphologyVAE", "vae_loss", "make_optimizer", "outputs_to_encoding", "ENCODING_DIM"]
