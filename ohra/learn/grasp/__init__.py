"""The cross-embodiment grasp model (torch, ``learn`` extra).

One model for every canonical hand: a point-cloud object encoder, a hand condition (the frozen
VAE's mean latent, or normalised raw parameters), conditional diffusion over the wrist translation
(x0 prediction, DDIM 10 steps) given the wrist rotation, and an MLP for the 22 joints, clamped to
the hand's limits. Train with :func:`train_grasp` (``ohra train grasp``), sample with
:meth:`GraspModel.sample` (``ohra grasp sample``), evaluate in PyBullet with :func:`evaluate_model`
(``ohra grasp eval``).

Settings import without torch; everything else imports torch on first use.
"""

from __future__ import annotations

from ohra.learn import lazy_getattr, require_torch
from ohra.learn.grasp.config import CONDITIONS, ENCODERS, GraspConfigError, GraspModelConfig, GraspTrainConfig

_LAZY = {
    "GraspModel": "model",
    "GraspNet": "model",
    "load_grasp_model": "model",
    "HandCondition": "condition",
    "DDIMScheduler": "diffusion",
    "TrainingData": "data",
    "train_grasp": "train",
    "GraspTrainResult": "train",
    "evaluate_model": "evaluate",
    "GraspEvalReport": "evaluate",
}


__getattr__ = lazy_getattr(__name__, _LAZY, require_torch)


__all__ = ["GraspModelConfig", "GraspTrainConfig", "GraspConfigError", "ENCODERS", "CONDITIONS", *_LAZY]
