"""Locations of package data: URDF templates and generated URDFs, hand specs and params, models.

All package data lives in one tree under ``ohra/`` and is read through ``importlib.resources``, so an
editable install and a wheel read the same files. The top-level ``urdf/`` folder of a checkout is a
symbolic link to ``ohra/urdf`` (the user's layout asks for it); nothing is read through it.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path


def _pkg(sub: str) -> Path:
    return Path(str(resources.files("ohra").joinpath(sub)))


def urdf_dir() -> Path:
    """Folder holding ``templates/*.urdf.j2`` and the generated canonical URDFs ``{base,extended}/``."""
    return _pkg("urdf")


def templates_dir() -> Path:
    return urdf_dir() / "templates"


def hands_data_dir() -> Path:
    """Folder of the hand registry's data: ``specs/*.yaml``, ``params/{base,extended}/*.json``, ``leap/``."""
    return _pkg("hands")


def specs_dir() -> Path:
    """Folder of the registered hands' spec files (one YAML per hand)."""
    return hands_data_dir() / "specs"


def leap_dir() -> Path:
    """Folder of the LEAP template inputs (``template.yaml``) and the derived template (``template.json``)."""
    return hands_data_dir() / "leap"
