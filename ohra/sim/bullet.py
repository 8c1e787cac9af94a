"""Small PyBullet helpers: load URDF text, and capture what the C++ side prints (warnings)."""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path
from typing import Iterator

import pybullet as pb


@contextlib.contextmanager
def captured_c_output() -> Iterator[list[str]]:
    """Capture text written to the process's stdout/stderr file descriptors (PyBullet's warnings).

    Yields a list that holds the captured text once the block exits.
    """
    out: list[str] = []
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


def load_urdf_text(text: str, client: int, **kwargs) -> int:
    """``pybullet.loadURDF`` from URDF text (PyBullet only reads files); returns the body id."""
    fd, path = tempfile.mkstemp(suffix=".urdf")
    try:
        with os.fdopen(fd, "w") as fh:
            fh.write(text)
        return pb.loadURDF(path, physicsClientId=client, **kwargs)
    finally:
        Path(path).unlink(missing_ok=True)
