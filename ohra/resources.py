"""Locations of package data (templates, registered hands, shipped models).

``urdf/`` at the repository root is installed as the package ``ohra.urdf`` (see ``setup.py``); in a
source checkout that is not installed, it is found next to the ``ohra`` folder.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

_PKG_DIR = Path(__file__).resolve().parent


def urdf_dir() -> Path:
    """Folder holding the URDF templates and the generated canonical URDFs."""
    try:
        p = Path(str(resources.files("ohra.urdf")))
        if (p / "templates").is_dir():
            return p
    except (ModuleNotFoundError, TypeError):
        pass
    return _PKG_DIR.parent / "urdf"


def templates_dir() -> Path:
    return urdf_dir() / "templates"


def hands_data_dir() -> Path:
    """Folder of hand specs (``*.yaml``) and registered params (``params/{base,extended}``)."""
    return _PKG_DIR / "hands"
