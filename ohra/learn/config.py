"""Training configuration of the morphology VAE (no torch needed to read or build it)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from typing import Any


from ohra.errors import ParamsError, is_finite_real, is_whole, reject_unknown, require_seed

# What a configuration written before a key existed meant (the paper's reference setup).
LEGACY_DEFAULTS: dict[str, Any] = {
    "encoding": "reference66", "cont_weight": 1.0, "presence_weight": 1.0, "rot_weight": 0.0, "tip_weight": 0.0,
    "smooth_weight": 0.0, "lr_schedule": "constant", "lr_final_ratio": 1.0,
}
# the paper's values of the fields whose defaults changed (TrainConfig.reference())
PAPER = {**LEGACY_DEFAULTS, "lr": 1e-4, "beta": 0.01, "latent_dim": 16, "epochs": 300}
LR_SCHEDULES = ("constant", "cosine")


@dataclass(frozen=True)
class TrainConfig:
    """Training settings. The defaults are the shipped model's; ``TrainConfig.reference()`` gives
    the paper's (66-D encoding, ``beta = 0.01``, constant ``lr = 1e-4``, 300 epochs)."""

    samples: int = 65536  # synthetic training hands, drawn once
    epochs: int = 250  # 16,000 steps: about 21 min on one thread of this 2-core machine (<= 30 min budget)
    batch_size: int = 1024  # shuffled, last partial batch dropped
    seed: int = 0
    lr: float = 1e-3  # peak; see lr_schedule
    betas: tuple[float, float] = (0.95, 0.999)
    weight_decay: float = 1e-6
    beta: float = 0.001  # KL weight (paper: 0.01, which caps the precision at ~0.4 standard deviations)
    latent_dim: int = 32  # paper: 16, too few for the ~30 independent continuous values of a hand
    checkpoint_every: int = 10  # epochs
    threads: int = 1  # torch CPU threads (results are reproducible for a fixed value; on 2 shared cores 1 is fastest)
    heldout: int = 8192  # held-out hands for the final metrics (0: none)
    encoding: str = "rot6d70"  # see ohra.learn.encodings
    cont_weight: float = 1.0  # weight of the continuous MSE (standardised units, mean over values)
    presence_weight: float = 22.0  # weight of the presence BCE (mean over flags): a sum over the 22 flags
    rot_weight: float = 1.0  # weight of the thumb-rotation term (GeometryLoss)
    tip_weight: float = 1.0  # weight of the q = 0 fingertip term (GeometryLoss, 1 cm units)
    smooth_weight: float = 0.0  # weight of the interpolation-step term (path_smoothness, 1 cm units)
    lr_schedule: str = "cosine"  # or "constant" (cosine: from lr to lr * lr_final_ratio over the run)
    lr_final_ratio: float = 0.01

    # fields that may differ between a checkpoint and the run that resumes it ("epochs" only with a
    # constant learning rate: a cosine schedule depends on the run's length)
    RESUMABLE_CHANGES = ("epochs", "checkpoint_every", "heldout")

    def __post_init__(self) -> None:
        if self.lr_schedule not in LR_SCHEDULES:
            raise ParamsError(f"TrainConfig: lr_schedule must be one of {LR_SCHEDULES}, got {self.lr_schedule!r}")
        require_seed(self.seed, ParamsError, "TrainConfig: seed")
        for name in ("epochs", "batch_size", "checkpoint_every"):  # epochs=0 returned an untrained model
            v = getattr(self, name, None)
            if v is not None and (not is_whole(v) or v < 1):
                raise ParamsError(f"TrainConfig: {name} must be a whole number >= 1, got {v!r}")
        lr = self.lr
        if not is_finite_real(lr) or lr <= 0:
            raise ParamsError(f"TrainConfig: lr must be a finite number > 0, got {lr!r}")

    @classmethod
    def reference(cls, **changes: Any) -> "TrainConfig":
        """The paper's settings (the previously shipped model was trained with them)."""
        return cls(**{**PAPER, **changes})

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["betas"] = list(self.betas)
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any], source: str = "training config") -> "TrainConfig":
        """From a dict (e.g. a run's config.json); unknown keys raise :class:`ParamsError` naming
        ``source`` and the key; keys missing from an older file take their :data:`LEGACY_DEFAULTS`."""
        reject_unknown(d, (f.name for f in fields(cls)), ParamsError, source, "key(s)")
        kw = {**{k: v for k, v in LEGACY_DEFAULTS.items() if k not in d}, **d}
        if "betas" in kw:
            kw["betas"] = tuple(float(b) for b in kw["betas"])
        return cls(**kw)

    def vae_config(self):
        """The :class:`ohra.learn.vae.VAEConfig` of this run (imports torch)."""
        from ohra.learn.encodings import get_encoding
        from ohra.learn.vae import VAEConfig

        return VAEConfig(input_dim=get_encoding(self.encoding).dim, latent_dim=self.latent_dim, beta=self.beta,
                         encoding=self.encoding, cont_weight=self.cont_weight, presence_weight=self.presence_weight,
                         rot_weight=self.rot_weight, smooth_weight=self.smooth_weight,
                         tip_weight=self.tip_weight)
