"""Reading a run's saved files (SB3 zips, pickled statistics, starting states) with errors that name the file.

A truncated or foreign ``model.zip``, ``vecnormalize.pkl`` or checkpoint fails inside zipfile, pickle or torch
with a message about bytes; :func:`load_checked` turns that into one :class:`ohra.errors.CheckpointError`
naming the file and what it should have been.
"""

from __future__ import annotations

import pickle
import zipfile
from pathlib import Path
from typing import Callable, TypeVar

from ohra.errors import CheckpointError

T = TypeVar("T")

# what a damaged file raises on the way through zipfile, pickle, numpy and torch
READ_ERRORS = (OSError, EOFError, ValueError, KeyError, IndexError, TypeError, AttributeError, ImportError,
               RuntimeError, pickle.UnpicklingError, zipfile.BadZipFile, UnicodeDecodeError)


def load_checked(path: str | Path, what: str, load: Callable[[], T]) -> T:
    """``load()``, or a :class:`CheckpointError` naming ``path`` as not a readable ``what`` when it fails.

    Args:
        path: the file ``load`` reads (for the message).
        what: what the file should be, e.g. "SB3 PPO policy (.zip)".
        load: reads and returns it.
    """
    try:
        return load()
    except CheckpointError:
        raise
    except READ_ERRORS as exc:
        first = (str(exc).strip().splitlines() or [""])[0][:200]
        raise CheckpointError(f"{path} is not a readable {what} ({type(exc).__name__}: {first}); the file is damaged "
                              "or not from an ohra rotation run: train or export the run again") from None


def load_pickle(path: str | Path, what: str):
    """The object pickled in ``path`` (an SB3 VecNormalize's statistics), via :func:`load_checked`."""
    def read():
        with open(path, "rb") as fh:
            return pickle.load(fh)

    return load_checked(path, what, read)
