"""What PyBullet's C side prints: captured (:func:`captured_c_output`), and discarded on import
(:func:`import_pybullet`).

The C extension writes ``pybullet build time: ...`` to the process's stdout/stderr once per process: in the CLI
it broke the "an error is one line on stderr" rule, and under a vectorised trainer every subprocess worker printed
it again. Every ``ohra.sim`` module reaches PyBullet through this package, whose ``__init__`` calls
:func:`import_pybullet` first, so the first import (the one that prints) happens here with the output discarded.
This module does not import PyBullet itself.
"""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
from types import ModuleType
from typing import Iterator


@contextlib.contextmanager
def captured_c_output() -> Iterator[list[str]]:
    """Capture text written to the process's stdout/stderr file descriptors (PyBullet's warnings).

    Yields a list that holds the captured text once the block exits.
    """
    out: list[str] = []
    sys.stdout.flush()
    sys.stderr.flush()
    with tempfile.TemporaryFile(mode="w+b") as tmp:
        saved = [os.dup(1), os.dup(2)]
        try:
            os.dup2(tmp.fileno(), 1)
            os.dup2(tmp.fileno(), 2)
            yield out
        finally:
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            for fd in saved:
                os.close(fd)
            tmp.seek(0)
            out.append(tmp.read().decode("utf-8", "replace"))


def import_pybullet() -> ModuleType | None:
    """``import pybullet`` with what it writes during the import discarded; None if PyBullet is not
    installed (the command that needs it says so). Later calls are free."""
    if "pybullet" in sys.modules:
        return sys.modules["pybullet"]
    with captured_c_output():
        try:
            import pybullet
        except ImportError:
            return None
    return pybullet
