"""PPO settings for the rotation policies (no torch or stable-baselines3 needed to read them).

The paper's policy (HORA's) is PPO with an MLP 512-256-128 (ELU), gamma 0.99, GAE lambda 0.95,
clip 0.2, 5 epochs per rollout, an adaptive learning rate that keeps the KL divergence near 0.02
(rl_games: lr / 1.5 above 2x the target, x 1.5 below half of it), no entropy bonus, gradient norm 1,
observations normalised by running statistics. Those carry over to Stable-Baselines3 unchanged.
What does not: HORA's 16,384 GPU environments x 8-step horizons (131k samples per update, lr 5e-3);
on 2 CPU cores we collect ``n_envs`` x ``n_steps`` = 2 x 1024 samples per update, so the initial
learning rate is SB3's 3e-4 (the adaptive rule moves it from there), and ``vf_coef`` is SB3's 0.5
(rl_games' critic_coef 4 weighs a differently scaled value loss). And the initial action noise: HORA
starts at std 1 (10^9 samples to shrink it); with std 1 the targets random-walk and the pose penalty
(0.3 x sum of squared deviations, growing with the walk) dominates: measured on LEAP, returns fell
from -230 to -1000 over the first 100k steps, while a policy that holds still scores ~0. At std 0.2
(log -1.6) that noise costs ~-27 per 400-step episode, so the rotation term is visible from the start.

``policy="lstm"``: a recurrent policy, sb3-contrib's ``RecurrentPPO`` (the paper's policy has a GRU;
sb3-contrib offers an LSTM only): observations -> LSTM of ``lstm_hidden`` units (actor and critic
each their own; ``lstm_critic=False``: the actor's only) -> the ``net_arch`` MLP. Same adaptive learning
rate and other settings. sb3-contrib back-propagates through whole episode pieces (up to a minibatch
long, at a batch of a few sequences), which makes training several times slower per step than the MLP on a CPU.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from typing import Any, Mapping

from ohra.errors import OhraError, reject_unknown


class RLConfigError(OhraError, ValueError):
    """A PPO setting is unknown or out of range."""


POLICIES = ("mlp", "lstm")


@dataclass(frozen=True)
class PPOSettings:
    """Training settings. Units: environment control steps (all envs together) and minutes."""

    total_steps: int = 1_000_000
    max_minutes: float | None = None  # wall-clock budget; training stops (and saves) when it is spent
    seed: int = 0
    n_envs: int = 2  # subprocess environments (one per core)
    n_steps: int = 1024  # per env per rollout
    batch_size: int = 512
    n_epochs: int = 5
    gamma: float = 0.99
    gae_lambda: float = 0.95
    clip_range: float = 0.2
    learning_rate: float = 3e-4  # initial; then adapted to kl_target
    kl_target: float | None = 0.02  # None: constant learning rate
    lr_bounds: tuple[float, float] = (1e-6, 1e-2)
    ent_coef: float = 0.0
    vf_coef: float = 0.5
    max_grad_norm: float = 1.0
    net_arch: tuple[int, ...] = (512, 256, 128)
    activation: str = "elu"
    log_std_init: float = -1.6  # action noise std 0.2 at the start (HORA: 1.0; see the module doc)
    normalize_obs: bool = True
    normalize_reward: bool = True
    checkpoint_every: int = 50_000  # steps
    threads: int = 1  # torch CPU threads in the learner
    policy: str = "mlp"  # "mlp" (SB3 PPO) or "lstm" (sb3-contrib RecurrentPPO; needs the rl extra's sb3-contrib)
    lstm_hidden: int = 256  # units of each LSTM (policy="lstm")
    lstm_critic: bool = True  # policy="lstm": the critic has its own LSTM; False: an MLP on the observations (~2x faster updates)

    def __post_init__(self) -> None:
        for name in ("learning_rate", "clip_range", "gamma", "gae_lambda", "ent_coef", "vf_coef", "max_grad_norm", "log_std_init"):
            if isinstance(getattr(self, name), bool) or not isinstance(getattr(self, name), (int, float)):
                raise RLConfigError(f"PPOSettings.{name} must be a number, got {getattr(self, name)!r}")
        if not self.learning_rate > 0:
            raise RLConfigError(f"PPOSettings.learning_rate must be > 0, got {self.learning_rate}")
        if self.kl_target is not None and (not isinstance(self.kl_target, (int, float)) or not self.kl_target > 0):
            raise RLConfigError(f"PPOSettings.kl_target must be > 0 or None (constant learning rate), got {self.kl_target!r}")
        if self.policy not in POLICIES:
            raise RLConfigError(f"PPOSettings.policy must be one of {POLICIES}, got {self.policy!r}")
        for name in ("total_steps", "n_envs", "n_steps", "batch_size", "n_epochs", "checkpoint_every", "threads", "lstm_hidden"):
            if int(getattr(self, name)) < 1:
                raise RLConfigError(f"PPOSettings.{name} must be >= 1, got {getattr(self, name)}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or not 0 <= self.seed < 2**32:
            raise RLConfigError(f"PPOSettings.seed must be a whole number in [0, 2**32), got {self.seed!r}")  # numpy's range
        for name in ("normalize_obs", "normalize_reward", "lstm_critic"):
            if not isinstance(getattr(self, name), bool):
                raise RLConfigError(f"PPOSettings.{name} must be true or false, got {getattr(self, name)!r}")
        if (self.n_envs * self.n_steps) % self.batch_size:
            raise RLConfigError(f"n_envs x n_steps = {self.n_envs * self.n_steps} must be a multiple of batch_size "
                                f"= {self.batch_size}")
        if self.activation not in ("elu", "relu", "tanh"):
            raise RLConfigError(f"activation must be 'elu', 'relu' or 'tanh', got {self.activation!r}")
        if self.max_minutes is not None and not self.max_minutes > 0:
            raise RLConfigError(f"max_minutes must be > 0 or None, got {self.max_minutes}")
        if not 0 < self.gamma <= 1 or not 0 < self.gae_lambda <= 1:
            raise RLConfigError("gamma and gae_lambda must be in (0, 1]")

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["lr_bounds"] = list(self.lr_bounds)
        d["net_arch"] = list(self.net_arch)
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], source: str = "ppo settings") -> "PPOSettings":
        reject_unknown(d, (f.name for f in fields(cls)), RLConfigError, source, "PPO setting(s)")
        kw = dict(d)
        for key in ("lr_bounds", "net_arch"):
            if key in kw:
                kw[key] = tuple(kw[key])
        return cls(**kw)
