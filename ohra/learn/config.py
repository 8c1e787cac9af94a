"""Training configuration of the morphology VAE (no torch needed to read or build it)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from typing import Any


@dataclass(frozen=True)
class TrainConfig:
    """Training settings (paper values where the paper has one)."""

    samples: int = 65536  # synthetic training hands, drawn once
    epochs: int = 300
    batch_size: int = 1024  # shuffled, last partial batch dropped
    seed: int = 0
    lr: float = 1e-4
    betas: tuple[float, float] = (0.95, 0.999)
    weight_decay: float = 1e-6
    beta: float = 0.01  # KL weight
    latent_dim: int = 16
    checkpoint_every: int = 10  # epochs
    threads: int = 1  # torch CPU threads (results are reproducible for a fixed value; on 2 shared cores 1 is fastest)
    heldout: int = 8192  # held-out hands for the final metrics (0: none)

    # fields that may differ between a checkpoint and the run that resumes it
    RESUMABLE_CHANGES = ("epochs", "checkpoint_every", "heldout")

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["betas"] = list(self.betas)
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "TrainConfig":
        names = {f.name for f in fields(cls)}
        kw = {k: v for k, v in d.items() if k in names}
        if "betas" in kw:
            kw["betas"] = tuple(float(b) for b in kw["betas"])
        return cls(**kw)

    def vae_config(self):
        """The :class:`ohra.learn.vae.VAEConfig` of this run (imports torch)."""
        from ohra.learn.vae import VAEConfig

        return VAEConfig(latent_dim=self.latent_dim, beta=self.beta)
