"""Conditional diffusion over the wrist translation: noise schedule, DDIM sampler, denoiser network.

The network predicts the clean sample x0 (the reference's ``prediction_type='sample'``). Noise
schedule: the squared-cosine schedule of Nichol & Dhariwal (diffusers' ``squaredcos_cap_v2``),
``train_steps`` = 1000 levels. Sampling: deterministic DDIM (eta = 0, Song et al. 2021) on
``inference_steps`` = 10 levels with *trailing* spacing (999, 899, ..., 99; Lin et al. 2024), so
the first level is pure noise and the last step returns the x0 prediction itself. (The reference
ran 200 DDPM steps with leading spacing and never used its DDIM scheduler.) Predicted x0 is
clipped to ``±clip`` (translations are normalised by their training spread before diffusion).

A small scheduler written here instead of the ``diffusers`` package: the whole of what is used is
the three formulas below.
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np
import torch
from torch import nn


def cosine_alphas_cumprod(steps: int, max_beta: float = 0.999) -> np.ndarray:
    """(steps,) cumulative products of ``1 - beta_t`` of the squared-cosine schedule (float64)."""
    def abar(u: float) -> float:
        return math.cos((u + 0.008) / 1.008 * math.pi / 2) ** 2

    betas = np.array([min(1.0 - abar((i + 1) / steps) / abar(i / steps), max_beta) for i in range(steps)])
    return np.cumprod(1.0 - betas)


class DDIMScheduler:
    """Forward noising for training and deterministic DDIM steps for sampling."""

    def __init__(self, train_steps: int = 1000, inference_steps: int = 10):
        if not 1 <= int(inference_steps) <= int(train_steps):
            raise ValueError(f"need 1 <= inference_steps <= train_steps, got {inference_steps}, {train_steps}")
        self.train_steps = int(train_steps)
        self.inference_steps = int(inference_steps)
        self._abar = cosine_alphas_cumprod(self.train_steps)  # float64, for the per-step scalars
        self.alphas_cumprod = torch.tensor(self._abar, dtype=torch.float32)

    def add_noise(self, x0: torch.Tensor, noise: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        """x_t = sqrt(abar_t) x0 + sqrt(1 - abar_t) noise; ``t`` (B,) integer levels."""
        if self.alphas_cumprod.device != t.device:  # once per device, not a copy every training step
            self.alphas_cumprod = self.alphas_cumprod.to(t.device)
        ab = self.alphas_cumprod[t].unsqueeze(-1)
        return ab.sqrt() * x0 + (1.0 - ab).sqrt() * noise

    def timesteps(self, n: int | None = None) -> list[int]:
        """Trailing spacing: ``n`` levels from ``train_steps - 1`` down, evenly spaced."""
        n = self.inference_steps if n is None else int(n)
        return [int(v) for v in np.round(np.arange(self.train_steps, 0, -self.train_steps / n)).astype(int) - 1]

    def step(self, x_t: torch.Tensor, x0: torch.Tensor, t: int, t_prev: int) -> torch.Tensor:
        """DDIM (eta = 0) from level ``t`` to ``t_prev`` given the x0 estimate (``t_prev < 0``: clean)."""
        ab_t = float(self._abar[t])
        ab_prev = float(self._abar[t_prev]) if t_prev >= 0 else 1.0
        eps = (x_t - math.sqrt(ab_t) * x0) / math.sqrt(1.0 - ab_t)
        return math.sqrt(ab_prev) * x0 + math.sqrt(1.0 - ab_prev) * eps

    def sample(self, predict_x0: Callable[[torch.Tensor, int], torch.Tensor], shape: tuple[int, ...],
               generator: torch.Generator | None = None, clip: float | None = None, n: int | None = None) -> torch.Tensor:
        """Run DDIM from Gaussian noise; ``predict_x0(x_t, t)`` is the denoiser."""
        x = torch.randn(shape, generator=generator)
        ts = self.timesteps(n)
        for i, t in enumerate(ts):
            x0 = predict_x0(x, t)
            if clip is not None:
                x0 = x0.clamp(-clip, clip)
            x = self.step(x, x0, t, ts[i + 1] if i + 1 < len(ts) else -1)
        return x


def timestep_embedding(t: torch.Tensor, dim: int) -> torch.Tensor:
    """Sinusoidal embedding (B, dim) of integer levels ``t`` (B,) (Vaswani et al. / DDPM)."""
    half = dim // 2
    freqs = torch.exp(-math.log(10000.0) * torch.arange(half, dtype=torch.float32, device=t.device) / half)
    arg = t.float().unsqueeze(-1) * freqs
    return torch.cat([arg.sin(), arg.cos()], dim=-1)


class Denoiser(nn.Module):
    """MLP x0-predictor: ([x_t (x_dim), condition, time embedding]) -> x0 (x_dim); x_dim = 3 (the wrist
    translation) or 25 (translation and joints).

    The first layer is split into a condition part and an (x_t, time) part: the condition is the
    same at every sampling step, so :meth:`project_condition` runs once per sample and each of the
    DDIM steps only pays for the small (x_t, time) product and the rest of the MLP.
    """

    def __init__(self, cond_dim: int, hidden: tuple[int, ...] = (512, 256), time_dim: int = 64, x_dim: int = 3):
        super().__init__()
        self.time_dim = int(time_dim)
        self.x_dim = int(x_dim)
        self.cond_in = nn.Linear(cond_dim, hidden[0])
        self.xt_in = nn.Linear(x_dim + time_dim, hidden[0], bias=False)
        layers: list[nn.Module] = []
        for a, b in zip(hidden[:-1], hidden[1:]):
            layers += [nn.Mish(), nn.Linear(a, b)]
        layers += [nn.Mish(), nn.Linear(hidden[-1], x_dim)]
        self.body = nn.Sequential(*layers)

    def project_condition(self, cond: torch.Tensor) -> torch.Tensor:
        return self.cond_in(cond)

    def forward(self, x_t: torch.Tensor, t: torch.Tensor, cond_h: torch.Tensor) -> torch.Tensor:
        """x_t (B, x_dim), integer levels t (B,), projected condition (B, hidden[0]) -> x0 (B, x_dim)."""
        h = cond_h + self.xt_in(torch.cat([x_t, timestep_embedding(t, self.time_dim)], dim=-1))
        return self.body(h)

    def forward_level(self, x_t: torch.Tensor, t: int, cond_h: torch.Tensor) -> torch.Tensor:
        """:meth:`forward` with one level ``t`` for the whole batch (sampling): the time part of the
        first layer is one row, broadcast."""
        w = self.xt_in.weight  # (hidden, x_dim + time_dim)
        temb = timestep_embedding(torch.tensor([t], device=w.device), self.time_dim)
        h = cond_h + x_t @ w[:, :self.x_dim].T + temb @ w[:, self.x_dim:].T
        return self.body(h)


__all__ = ["DDIMScheduler", "Denoiser", "cosine_alphas_cumprod", "timestep_embedding"]
