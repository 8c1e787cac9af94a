"""Learning on canonical hands: the synthetic hand sampler, the morphology encodings (the 70-D
``rot6d70`` of the shipped model, :mod:`ohra.learn.encoding_rot6d`; the paper's 66-D ``reference66``,
whose functions are re-exported here), the morphology VAE (32-D latent space; encode, decode and
interpolate hands) and the cross-embodiment grasp model (:mod:`ohra.learn.grasp`).

The sampler and the encoding need only numpy and import eagerly. Everything that needs torch
(the VAE model, training, ``load_vae``, ``encode``/``decode``/``interpolate``) is imported on first
use; without torch those names raise :class:`MissingDependencyError` telling you to install the
``learn`` extra (``pip install ohra[learn]``).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Collection, Mapping
from typing import Any

from ohra.errors import OhraError
from ohra.learn.encoding import (
    AXIS_CATEGORIES,
    CONT_DIM,
    ENCODING_DIM,
    AxisSnapWarning,
    OutOfSupportWarning,
    LatentError,
    Standardizer,
    decode_params,
    decode_vectors,
    encode_params,
    encode_vectors,
)
from ohra.learn.config import TrainConfig
from ohra.learn.encodings import ENCODINGS, get_encoding
from ohra.learn.sampler import SamplerConfig, sample_hand, sample_params, sample_vectors


class MissingDependencyError(OhraError, ImportError):
    """An optional dependency (torch, for ``ohra.learn``) is not installed."""


def require_torch():
    """The ``torch`` module, or :class:`MissingDependencyError` with the install hint."""
    try:
        import torch
    except ImportError as exc:  # pragma: no cover - exercised only without torch
        raise MissingDependencyError(
            f"ohra.learn needs PyTorch for the VAE ({exc}); install it with `pip install ohra[learn]` "
            "(on a CPU-only machine install the CPU wheel of torch first)"
        ) from None
    return torch


# name -> submodule providing it (imported lazily, because they need torch)
_LAZY = {
    "MorphologyVAE": "vae",
    "VAEConfig": "vae",
    "vae_loss": "vae",
    "train": "train_vae",
    "VAEBundle": "morph",
    "load_vae": "morph",
    "encode": "morph",
    "decode": "morph",
    "interpolate": "morph",
    "Interpolation": "morph",
    "load_grasp_model": "grasp.model",
    "GraspModel": "grasp.model",
    "train_grasp": "grasp.train",
}


def lazy_getattr(package: str, lazy: Mapping[str, str], require: Callable[[], object],
                 exempt: Collection[str] = ()) -> Callable[[str], Any]:
    """A module-level ``__getattr__`` for ``package`` (PEP 562) that imports each name of ``lazy``
    from its submodule (``lazy[name]``, relative to ``package``) on first use, after ``require()``
    has checked the optional dependency (raising :class:`MissingDependencyError`); submodules in
    ``exempt`` need no check. Keeps torch out of ``import ohra.learn`` and its subpackages."""

    def __getattr__(name: str) -> Any:
        if name in lazy:
            if lazy[name] not in exempt:
                require()
            return getattr(importlib.import_module(f"{package}.{lazy[name]}"), name)
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    return __getattr__


__getattr__ = lazy_getattr(__name__, _LAZY, require_torch)


__all__ = [
    "sample_vectors", "sample_params", "sample_hand", "SamplerConfig", "encode_vectors", "encode_params",
    "decode_vectors", "decode_params", "Standardizer", "AxisSnapWarning", "OutOfSupportWarning", "LatentError", "ENCODING_DIM",
    "CONT_DIM", "AXIS_CATEGORIES", "TrainConfig", "ENCODINGS", "get_encoding", "MissingDependencyError", "require_torch",
    *_LAZY,
]
