"""Shared fixtures: published parameter files, and where the shared assets are."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ohra.canonical.params import BaseParams, ExtendedParams, load_params
from ohra.paths import hands_root, objects_root

DATA = Path(__file__).parent / "data"


@pytest.fixture
def shadow_base() -> BaseParams:
    return load_params(DATA / "shadow_hand_right_base.json")


@pytest.fixture
def allegro_ext() -> ExtendedParams:
    return load_params(DATA / "allegro_hand_right_extended.json")


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)


def _require(root: Path) -> Path:
    if not root.is_dir():
        pytest.skip(f"shared assets not found at {root}")
    return root


@pytest.fixture
def hands_dir() -> Path:
    return _require(hands_root())


@pytest.fixture
def objects_dir() -> Path:
    return _require(objects_root())
