"""Exceptions raised by ohra.

Every error a user can cause derives from :class:`OhraError`, so a caller (and the CLI) can catch
one type. Messages name the offending file, key or index and what was expected.
"""

from __future__ import annotations

from collections.abc import Iterable


class OhraError(Exception):
    """Base class of all ohra errors."""


class ParamsError(OhraError, ValueError):
    """Hand parameters are malformed or physically invalid."""


class MappingError(OhraError, ValueError):
    """A joint mapping between an original hand and the canonical hand is inconsistent."""


class SpecError(OhraError, ValueError):
    """A hand spec (YAML) is malformed or names things the original URDF does not have."""


class ParseError(OhraError, ValueError):
    """An original hand URDF cannot be parsed into canonical parameters."""


class HandNotFoundError(OhraError, KeyError):
    """An unknown hand name was requested from the registry."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else ""


class AssetsNotFoundError(OhraError, FileNotFoundError):
    """Original hand or object assets are not where the configuration says."""


class ObjectError(OhraError, ValueError):
    """An object mesh is missing, empty or unusable."""


class GraspError(OhraError, ValueError):
    """A grasp array has the wrong shape or invalid values."""


class CheckpointError(OhraError, ValueError):
    """A model checkpoint is missing, corrupt or incompatible."""


class DatasetError(OhraError, ValueError):
    """A grasp dataset is malformed or does not match its manifest."""


class OutputPathError(OhraError, OSError):
    """An output path cannot be written: it is a folder, or one of its parent components is a file."""


class FolderInUseError(OhraError, RuntimeError):
    """Another process is writing the same run or dataset folder (it holds the folder's lock)."""


class ObjectWarning(UserWarning):
    """Something about an object was estimated or approximated (mass properties, its simulated body)."""


class HandWarning(UserWarning):
    """Something about a hand was approximated (a canonical form that follows its original poorly)."""


def reject_unknown(keys: Iterable[str], known: Iterable[str], error: type[OhraError], source: str, what: str) -> None:
    """Raise ``error`` naming ``source`` and the keys not in ``known`` (sorted, with the known ones)
    when there are any; ``what`` names the kind of key, e.g. ``"PPO setting(s)"``. Shared by the
    ``from_dict`` constructors of the settings dataclasses."""
    names = set(known)
    unknown = sorted(set(keys) - names)
    if unknown:
        raise error(f"{source}: unknown {what} {unknown}; known: {sorted(names)}")


def require_seed(seed: object, error: type[OhraError], what: str = "seed") -> int:
    """``seed`` as an int, or ``error`` naming it: NumPy's generators take whole numbers >= 0 only (a
    negative or fractional seed would otherwise fail deep inside them with a bare ValueError)."""
    import numbers

    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or int(seed) < 0:
        raise error(f"{what} must be a whole number >= 0, got {seed!r}")
    if int(seed) >= 2**63:  # stored as int64 beside what it made (npz, JSON), and torch seeds stop at 2**64
        raise error(f"{what} must be below 2**63, got {seed!r}")
    return int(seed)


def require_whole(value: object, error: type[OhraError], what: str, least: int, most: int | None = None) -> int:
    """``value`` as an int when it is a whole number in [``least``, ``most``], or ``error`` naming ``what``: a bool,
    a float or a numeric string is refused (``int()`` would take them and truncate)."""
    import numbers

    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise error(f"{what}: expected a whole number, got {value!r}")
    if value < least:
        raise error(f"{what} must be >= {least}, got {value}")
    if most is not None and value > most:
        raise error(f"{what} must be <= {most:,}, got {value:,}")
    return int(value)


def is_finite_real(value: object) -> bool:
    """Whether ``value`` is a finite real number (Python or NumPy; a bool is not one)."""
    import math
    import numbers

    return not isinstance(value, bool) and isinstance(value, numbers.Real) and math.isfinite(value)


def is_whole(value: object) -> bool:
    """Whether ``value`` is a whole number (Python or NumPy integer; a bool or a float is not one)."""
    import numbers

    return not isinstance(value, bool) and isinstance(value, numbers.Integral)


def require_finite(value: object, error: type[OhraError], what: str, positive: bool = False) -> float:
    """``value`` as a float when it is a finite real number >= 0 (> 0 when ``positive``), or ``error`` naming ``what``."""
    import math
    import numbers

    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value):
        raise error(f"{what}: expected a finite number, got {value!r}")
    if value < 0 or (positive and value == 0):
        raise error(f"{what} must be {'positive' if positive else '>= 0'}, got {value}")
    return float(value)


def user_stacklevel() -> int:
    """The ``stacklevel`` that attributes a warning to the first frame outside ohra (and ``functools``, whose
    ``cached_property`` runs some of ohra's checks): a notebook user sees their own line, not ohra's internals.
    Call it in the argument list of ``warnings.warn``."""
    import functools
    import os
    import sys

    pkg = os.path.dirname(os.path.abspath(__file__)) + os.sep
    frame, level = sys._getframe(1), 1  # the frame that calls warnings.warn is stacklevel 1
    while frame is not None and (frame.f_code.co_filename.startswith(pkg) or frame.f_code.co_filename == functools.__file__):
        frame, level = frame.f_back, level + 1
    return level
