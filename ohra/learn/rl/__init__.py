"""Rotation policies: Stable-Baselines3 PPO training, evaluation (Steps-to-Fall, Cumulative Rotation),
rendered episodes and meshcat replays, reward curves.

Needs the ``rl`` extra (gymnasium, stable-baselines3; torch comes from the ``learn`` extra):
``pip install ohra[learn,rl]``. The settings (:class:`PPOSettings`) import without them.
"""

from __future__ import annotations

from ohra.learn import lazy_getattr
from ohra.learn.rl.config import PPOSettings, RLConfigError

_LAZY = {
    "train_rotation": "train", "load_run": "train", "with_budget": "train", "ppo_class": "train",
    "evaluate_run": "evaluate", "evaluate_policy": "evaluate", "record_episode": "evaluate",
    "replay_html": "evaluate", "Policy": "evaluate", "EvalResult": "evaluate", "export_policy": "evaluate",
    "shipped": "evaluate", "policy_dir": "evaluate", "on_urdf": "evaluate", "output_suffix": "evaluate",
    "reward_curves": "plots", "mean_std_curve": "plots", "read_progress": "plots", "table3": "plots",
}


def require_rl():
    """Import stable-baselines3 (and torch), or raise ``MissingDependencyError`` with the install hint."""
    from ohra.learn import MissingDependencyError

    try:
        import stable_baselines3  # noqa: F401
        import torch  # noqa: F401
    except ImportError as exc:  # pragma: no cover - exercised only without the extra
        raise MissingDependencyError(
            f"rotation training needs stable-baselines3 and torch ({exc}); install them with "
            "`pip install ohra[learn,rl]` (on a CPU-only machine install the CPU wheel of torch first)") from None


__getattr__ = lazy_getattr(__name__, _LAZY, require_rl, exempt=("plots",))  # plots need only matplotlib


__all__ = ["PPOSettings", "RLConfigError", "require_rl", *_LAZY]
