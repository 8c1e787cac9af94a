"""Where ohra finds data that is not part of the package.

Original hand URDFs and real object meshes live outside the repository. Their roots are
configurable with environment variables; the defaults point at ``../shared/hands`` and
``../shared/objects`` relative to the repository (or, for an installed package, the current
working directory).
"""

from __future__ import annotations

import os
from pathlib import Path

_REPO_ROOT = Path(__file__).resolve().parents[1]

HANDS_ENV = "OHRA_HANDS_ROOT"
OBJECTS_ENV = "OHRA_OBJECTS_ROOT"
CACHE_ENV = "OHRA_CACHE_DIR"


def _default(sub: str) -> Path:
    candidates = [_REPO_ROOT.parent / "shared" / sub, Path.cwd().parent / "shared" / sub]
    for c in candidates:
        if c.is_dir():
            return c
    return candidates[0]


def hands_root() -> Path:
    """Root folder of the original hand assets (``$OHRA_HANDS_ROOT`` or ``../shared/hands``)."""
    env = os.environ.get(HANDS_ENV)
    return Path(env).expanduser() if env else _default("hands")


def objects_root() -> Path:
    """Root folder of the real object meshes (``$OHRA_OBJECTS_ROOT`` or ``../shared/objects``)."""
    env = os.environ.get(OBJECTS_ENV)
    return Path(env).expanduser() if env else _default("objects")


def cache_dir() -> Path:
    """Folder for derived, re-creatable data such as convex decompositions (``$OHRA_CACHE_DIR``)."""
    env = os.environ.get(CACHE_ENV)
    base = Path(env).expanduser() if env else Path.home() / ".cache" / "ohra"
    base.mkdir(parents=True, exist_ok=True)
    return base
