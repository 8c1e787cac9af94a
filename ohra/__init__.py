"""ohra: one canonical form for every dexterous robot hand, and cross-embodiment grasping on it.

The public API is re-exported here; see the README for a tour.
"""

from __future__ import annotations

__version__ = "0.1.0"

from ohra.original.action import ActionMap, SlotMap
from ohra.errors import (
    AssetsNotFoundError,
    CheckpointError,
    DatasetError,
    GraspError,
    HandNotFoundError,
    MappingError,
    ObjectError,
    OhraError,
    ParamsError,
    ParseError,
    SpecError,
)
from ohra.hands import get_couplings, get_hand, list_hands, resolve_hand
from ohra.canonical.couplings import Coupling
from ohra.canonical.kinematics import Capsules, HandModel
from ohra.canonical.params import FINGERS, JOINT_NAMES, BaseParams, ExtendedParams, load_params
from ohra.canonical.urdfgen import render, write


def load_original(name: str):
    """The original (non-canonical) model of a registered hand; needs the hand assets."""
    from ohra.hands import registry  # the parser's registry owns original-hand loading

    return registry.load_original(name)


__all__ = [
    "__version__", "ActionMap", "SlotMap", "BaseParams", "ExtendedParams", "load_params", "FINGERS",
    "JOINT_NAMES", "HandModel", "Capsules", "render", "write", "get_hand", "list_hands", "load_original",
    "get_couplings", "resolve_hand", "Coupling",
    "OhraError", "ParamsError", "MappingError", "SpecError", "ParseError", "HandNotFoundError",
    "AssetsNotFoundError", "ObjectError", "GraspError", "CheckpointError", "DatasetError",
]
