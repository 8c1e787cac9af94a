"""Grasp synthesis for any canonical hand: CasADi/IPOPT force-closure NLP + PyBullet filter.

The names below load on first use, so ``python -m ohra.synth --help`` (which imports this package
first) neither pays for CasADi and PyBullet nor prints PyBullet's build banner.
"""

from __future__ import annotations

import importlib
from typing import Any

MIN_GRASP_FINGERS = 2
"""Fewest fingers a hand needs for synthesis (one finger or none closes on nothing); here, not in
``pipeline``, so that code that only checks a hand does not load CasADi and PyBullet."""

_LAZY = {"GraspNLP": "ohra.synth.nlp", "NLPSettings": "ohra.synth.nlp", "SynthSettings": "ohra.synth.pipeline",
         "synthesize": "ohra.synth.pipeline", "synthesize_shard": "ohra.synth.pipeline"}

__all__ = list(_LAZY)


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'ohra.synth' has no attribute {name!r}")
