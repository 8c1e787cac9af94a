"""Import PyBullet without the ``pybullet build time: ...`` line its C extension writes on import.

That line lands on the process's stdout/stderr once per process: in the CLI it broke the "an error is one
line on stderr" rule, and under a vectorised trainer every subprocess worker printed it again. Every
``ohra.sim`` module reaches PyBullet through this package, whose ``__init__`` calls :func:`import_pybullet`
first, so the first import (the one that prints) happens here with the output discarded.
"""

from __future__ import annotations

import os
import sys
from types import ModuleType


def import_pybullet() -> ModuleType | None:
    """``import pybullet`` with what it writes to file descriptors 1 and 2 during the import discarded;
    None if PyBullet is not installed (the command that needs it says so). Later calls are free."""
    if "pybullet" in sys.modules:
        return sys.modules["pybullet"]
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 1)
            os.dup2(null.fileno(), 2)
            try:
                import pybullet
            except ImportError:
                return None
    finally:
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in saved:
            os.close(fd)
    return pybullet
