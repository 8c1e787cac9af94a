"""Atomic file writes that honour the umask: every file ``ohra`` writes for a user goes through here.

A write goes to a temporary file in the target's folder (so the final rename never crosses a file
system), is flushed and fsync'ed, gets the mode a plain ``open(path, "w")`` would give
(``0o666 & ~umask``), and is renamed over the target with :func:`os.replace`. A reader therefore sees
either the old file or the complete new one, never a partial file; a write that fails (an exception
in the writer, a full disk, Ctrl-C) leaves the target untouched and removes the temporary file.

The mode matters because :func:`tempfile.mkstemp` creates files 0600: renamed as they are, datasets,
URDFs and HTML written by one user would be unreadable to the others.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from pathlib import Path
from typing import IO, Any, Callable, Iterator, Mapping

import numpy as np


def umask_mode() -> int:
    """The mode bits of a newly created regular file: ``0o666`` minus the process umask.

    The umask can only be read by setting it; it is restored at once (process-wide, so not meant to
    race with threads creating files at the same instant).
    """
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


def check_suffix(path: str | Path, suffix: str, flag: str = "-o") -> Path:
    """``path`` when its file name ends in ``suffix`` (any case) after a name of its own; else
    :class:`~ohra.errors.OutputPathError` naming ``flag`` (``-o .npz`` is a hidden file without a suffix)."""
    from ohra.errors import OutputPathError

    path = Path(path)
    if str(path) == os.devnull:  # output discarded on purpose
        return path
    if path.suffix.lower() != suffix.lower():
        hint = f" (a file name is needed before {suffix})" if path.name.lower() == suffix.lower() else ""
        raise OutputPathError(f"{flag} must end in {suffix}, got {path}{hint}")
    return path


def check_output(path: str | Path, folder: bool = False) -> Path:
    """``path`` if a file (``folder=True``: a folder) can be written there, checked before any work is done:
    not an existing folder (a file), no parent component that is a file, and the nearest existing folder
    writable.

    Raises:
        OutputPathError: naming the path as given (not a temporary file beside it).
    """
    from ohra.errors import OutputPathError

    path = Path(path)
    if folder and path.exists() and not path.is_dir():
        raise OutputPathError(f"{path} is a file; give a folder for this output")
    if not folder and path.is_dir():
        raise OutputPathError(f"{path} is a folder; give a file path for this output")
    for parent in path.parents:
        if parent.exists():
            if not parent.is_dir():
                raise OutputPathError(f"{path}: {parent} is a file, not a folder")
            if not os.access(parent, os.W_OK | os.X_OK):  # found now, not after minutes of work
                raise OutputPathError(f"{path}: cannot write into {parent} (permission denied)")
            break
    return path


@contextlib.contextmanager
def atomic_path(path: str | Path, suffix: str = ".tmp") -> Iterator[Path]:
    """A temporary path beside ``path`` to write to; on a clean exit it replaces ``path``.

    For writers that need a file name rather than a handle (``savefig``, ``imsave``, external tools).
    ``suffix`` lets such writers infer the format from the name (e.g. ``".png"``). Parent folders are
    created. On an exception the temporary file is removed and ``path`` is left as it was.
    """
    path = check_output(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(dir=str(path.parent), prefix=f".{path.name}.", suffix=suffix)
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        yield tmp
        with open(tmp, "rb+") as fh:  # the writer may have closed its own handle: sync through ours
            os.fsync(fh.fileno())
        os.chmod(tmp, umask_mode())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def atomic_write(path: str | Path, write: Callable[[IO[bytes]], Any]) -> Path:
    """Call ``write(fh)`` on a binary handle to a temporary file, then replace ``path``; returns ``path``."""
    path = Path(path)
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        write(fh)
    return path


def write_bytes(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically."""
    return atomic_write(path, lambda fh: fh.write(data))


def write_text(path: str | Path, text: str, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` atomically (``encoding`` default UTF-8, newlines as given)."""
    return write_bytes(path, text.encode(encoding))


def write_json(path: str | Path, data: Any, indent: int | None = 1) -> Path:
    """Write ``data`` as JSON plus a final newline; values JSON cannot hold are written with ``str``."""
    return write_text(path, json.dumps(data, indent=indent, default=str) + "\n")


def write_npz(path: str | Path, arrays: Mapping[str, np.ndarray]) -> Path:
    """Write ``arrays`` as a compressed ``.npz`` atomically (the name is used as given, no ``.npz`` added)."""
    return atomic_write(path, lambda fh: np.savez_compressed(fh, **arrays))


LOCK_NAME = ".ohra.lock"


@contextlib.contextmanager
def folder_lock(folder: str | Path, what: str = "folder") -> Iterator[Path]:
    """Hold the exclusive lock of ``folder`` (created if missing) while the block runs.

    Two processes training into one run folder, or building one dataset, would overwrite each
    other's checkpoints and manifest without either noticing; the second one fails at once instead.
    The lock is an advisory ``flock`` on ``folder/.ohra.lock`` (the holder's PID is written there for
    the message); the kernel drops it when the holder exits, however it exits, so a killed job leaves
    no stale lock. ``what`` names the folder's content in the error (``"training run"``, ``"dataset"``).

    A folder this call created is removed again if the block leaves nothing but the lock in it (a job that
    failed its checks before writing anything leaves no empty run folder).

    Raises:
        FolderInUseError: another process holds the lock (its PID in the message).
        OutputPathError: ``folder`` is a file, or lies under one.
    """
    from ohra.errors import FolderInUseError

    folder = check_output(folder, folder=True)  # a file there: one line naming it, not FileExistsError
    created = not folder.exists()
    folder.mkdir(parents=True, exist_ok=True)
    try:
        import fcntl
    except ImportError:  # no flock (Windows): run unguarded rather than refuse to run
        yield folder
        return
    path = folder / LOCK_NAME
    fh = open(path, "a+")
    held = False
    try:
        try:
            fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            fh.seek(0)
            holder = fh.read().strip() or "unknown"
            raise FolderInUseError(f"{folder}: another process (pid {holder}) is writing this {what}; "
                                   f"wait for it to finish or choose another folder") from None
        held = True
        fh.seek(0)
        fh.truncate()
        fh.write(f"{os.getpid()}\n")
        fh.flush()
        yield folder
    finally:
        fh.close()  # releases the lock
        if held and created and folder.is_dir() and [p.name for p in folder.iterdir()] == [LOCK_NAME]:
            # the job failed before writing anything (bad data, a hand not in it): leave no empty run folder
            path.unlink(missing_ok=True)
            try:
                folder.rmdir()
            except OSError:  # another process wrote into it meanwhile
                pass


__all__ = ["folder_lock", "umask_mode", "atomic_path", "atomic_write", "write_bytes", "write_text", "write_json", "write_npz"]
