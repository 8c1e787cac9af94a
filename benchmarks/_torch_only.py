"""Train grasp models on a machine that has torch but not ohra's simulation stack (a GPU box).

``ohra.canonical`` imports Pinocchio and Coal at module level, and a few modules reachable from the
training path import CasADi or PyBullet, although training itself calls none of them (it reads the
committed datasets, the object meshes and the VAE). On a machine where those wheels are not installed
(GPU images usually lack them, and they are hundreds of MB), :func:`stand_in_for_missing` puts an
empty module in their place whose every attribute access raises ``ImportError`` naming the package:
a code path that does need one fails loudly instead of silently doing something else.

Never used by the library or the tests; benchmark scripts call it only under ``--torch-only``.
"""

from __future__ import annotations

import importlib.util
import sys
import types

SIM_STACK = ("pinocchio", "coal", "casadi", "pybullet", "pybullet_data")


class _Missing(types.ModuleType):
    def __getattr__(self, attr: str):
        if attr.startswith("__"):
            raise AttributeError(attr)
        raise ImportError(f"{self.__name__}.{attr}: {self.__name__} is not installed on this machine "
                          "(--torch-only stands in an empty module; this code path needs the real package)")


def stand_in_for_missing(names: tuple[str, ...] = SIM_STACK, force: bool = False) -> list[str]:
    """Register an empty stand-in for each of ``names`` that cannot be imported (every one of them when
    ``force``: a test of this path on a machine that has them). Returns the names stood in for."""
    done = []
    for name in names:
        if name in sys.modules and not force:
            continue
        if force or importlib.util.find_spec(name) is None:
            sys.modules[name] = _Missing(name)
            done.append(name)
    return done
