"""Hand conditions of the grasp model: one fixed vector per hand.

``vae`` (the unified model): the mean latent of the frozen morphology VAE, encoder in eval mode, so
the condition of a hand never changes (the reference sampled a latent and ran the encoder's
BatchNorm in training mode, so its conditions drifted while training and were noisy at test time).
The VAE's weights are stored inside the grasp checkpoint: retraining or replacing the shipped VAE
later cannot silently change the conditions a trained grasp model expects. The VAE reads base-form
hands only (LEAP variants have no base form: use ``params`` for them).

``params`` (zero-shot studies): the hand's extended-form parameter vector (173 numbers; base hands
are converted exactly), its 22 presence flags and a LEAP-template flag (196 numbers), standardised
with the mean and spread of the training hands. Few training hands make some spreads zero; those
are floored by unit (1 cm for lengths, 0.5 for angles [rad], axes and flags) so an unseen hand that
differs there gives a bounded input instead of a division by zero. The statistics are stored in
the checkpoint.
"""

from __future__ import annotations

import hashlib
from functools import lru_cache
from pathlib import Path
from typing import Any, Sequence, Union

import numpy as np
import torch

from ohra.canonical.params import BaseParams, ExtendedParams, Params
from ohra.errors import CheckpointError, ParamsError

HandLike = Union[str, Path, BaseParams, ExtendedParams]
PARAMS_DIM = 173 + 22 + 1

# unit of each of the 196 entries: "m" lengths/positions, "rad" angles, "1" axes and flags
_UNITS = np.array(
    ["m"] * (1 + 5 + 15)  # palm radius, finger radii, finger lengths
    + (["m"] * 3 + ["rad"] * 3) * 12  # joint origins: xyz, rpy
    + ["1"] * 36  # joint axes
    + ["rad"] * 44  # lower, upper limits
    + ["1"] * 23  # presence flags, leap-template flag
)
SCALE_FLOOR = {"m": 0.01, "rad": 0.5, "1": 0.5}


def resolve_hand(hand: HandLike) -> Params:
    """Params of a registered hand name, a LEAP variant name, a params JSON path, or params."""
    if isinstance(hand, (BaseParams, ExtendedParams)):
        return hand
    if not isinstance(hand, (str, Path)):
        raise ParamsError(f"hand: expected a name, a params JSON path or params, got {type(hand).__name__}")
    key = str(hand)
    if isinstance(hand, Path) or key.endswith(".json") or Path(key).exists():
        from ohra.hands import get_hand

        return get_hand(key)  # a file: read it every time (it may change)
    return _named_hand(key)


@lru_cache(maxsize=64)
def _named_hand(name: str) -> Params:
    """Registered hands and LEAP variants by name (cached: ``get_hand`` reads files, ~10 ms; the
    cached params never leave this module's callers, which do not modify them)."""
    from ohra.hands import get_hand

    return get_hand(name)


def params_vector(params: Params) -> np.ndarray:
    """(196,) raw condition vector: extended parameters, presence flags, LEAP-template flag."""
    ext = params.to_extended() if isinstance(params, BaseParams) else params
    flags = ext.present_joints.astype(float)
    leap = 1.0 if getattr(ext, "template", "extended") == "leap" else 0.0
    return np.concatenate([ext.to_vector(), flags, [leap]])


def hand_key(params: Params) -> str:
    """Content hash of a hand's parameters (cache key)."""
    kind = type(params).__name__ + getattr(params, "template", "")
    return hashlib.sha256(kind.encode() + np.asarray(params.to_vector(), dtype=float).tobytes()).hexdigest()[:16]


class HandCondition:
    """Maps hands to condition vectors (see the module docstring); ``dim`` numbers per hand."""

    def __init__(self, kind: str, vae: Any = None, mean: np.ndarray | None = None, scale: np.ndarray | None = None):
        if kind not in ("vae", "params"):
            raise ParamsError(f"hand condition: expected 'vae' or 'params', got {kind!r}")
        self.kind = kind
        self.vae = vae
        self.mean = None if mean is None else np.asarray(mean, dtype=float)
        self.scale = None if scale is None else np.asarray(scale, dtype=float)
        self._cache: dict[str, np.ndarray] = {}
        if kind == "vae" and vae is None:
            raise CheckpointError("a 'vae' hand condition needs a VAE")
        if kind == "params" and (self.mean is None or self.scale is None or self.mean.shape != (PARAMS_DIM,)
                                 or self.scale.shape != (PARAMS_DIM,) or np.any(self.scale <= 0)):
            raise CheckpointError(f"a 'params' hand condition needs mean and positive scale of shape ({PARAMS_DIM},)")

    # -- construction --------------------------------------------------------------------------------
    @classmethod
    def fit(cls, kind: str, hands: Sequence[Params], vae_path: str | Path | None = None) -> "HandCondition":
        """A condition for training on ``hands`` (``params``: statistics from them; ``vae``: the
        shipped VAE, or the one at ``vae_path``)."""
        if kind == "vae":
            from ohra.learn.morph import load_vae

            return cls("vae", vae=load_vae(vae_path))
        if kind != "params":
            raise ParamsError(f"hand condition: expected 'vae' or 'params', got {kind!r}")
        if not hands:
            raise ParamsError("a 'params' hand condition needs at least one training hand")
        x = np.stack([params_vector(h) for h in hands])
        floor = np.array([SCALE_FLOOR[u] for u in _UNITS])
        return cls("params", mean=x.mean(axis=0), scale=np.maximum(x.std(axis=0), floor))

    @property
    def dim(self) -> int:
        return int(self.vae.latent_dim) if self.kind == "vae" else PARAMS_DIM

    # -- use -------------------------------------------------------------------------------------------
    @staticmethod
    def vae_form(params: Params) -> BaseParams:
        """The base form the VAE reads; a hand without one is a :class:`ParamsError` naming the way out."""
        from ohra.learn.encoding import as_base

        try:
            return as_base(params)
        except ParamsError as exc:
            raise ParamsError(f"{exc}; a grasp model with condition='params' can use such hands "
                              "(the shipped one: load_grasp_model('leap'), --model leap)") from None

    def vector(self, hand: HandLike) -> np.ndarray:
        """(dim,) condition of one hand (cached by parameter content)."""
        params = resolve_hand(hand)
        key = hand_key(params)
        if key not in self._cache:
            if self.kind == "vae":
                base = self.vae_form(params)
                # the VAE's own encoding (rot6d70 or reference66); fitted hands carry thumb axes a few
                # degrees off the basis axes: it snaps them without a warning per hand
                x = self.vae.encoding.encode_vectors(base.to_vector()[None], warn=False)
                mu, _ = self.vae.encode_encodings(x)
                self._cache[key] = np.asarray(mu[0], dtype=float)
            else:
                self._cache[key] = (params_vector(params) - self.mean) / self.scale
        return self._cache[key]

    # -- persistence -----------------------------------------------------------------------------------
    def state(self) -> dict[str, Any]:
        """What a checkpoint stores (tensors and plain values only: loadable with ``weights_only``)."""
        if self.kind == "vae":
            from ohra.learn.train_vae import model_payload

            return {"kind": "vae", "vae": model_payload(self.vae.model, self.vae.standardizer)}
        return {"kind": "params", "mean": torch.tensor(self.mean), "scale": torch.tensor(self.scale)}

    @classmethod
    def from_state(cls, state: dict[str, Any], where: str = "checkpoint") -> "HandCondition":
        try:
            kind = state["kind"]
            if kind == "vae":
                from ohra.learn.morph import VAEBundle, bundle_from_payload

                model, std = bundle_from_payload(state["vae"], where)
                return cls("vae", vae=VAEBundle(model, std))
            return cls("params", mean=np.asarray(state["mean"]), scale=np.asarray(state["scale"]))
        except (KeyError, TypeError) as exc:
            raise CheckpointError(f"{where}: hand condition is incomplete ({type(exc).__name__}: {exc})") from None


__all__ = ["HandCondition", "params_vector", "resolve_hand", "hand_key", "PARAMS_DIM"]
