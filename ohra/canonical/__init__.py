"""The canonical hand: parameters, URDF generation and kinematics (the representation layer)."""

from ohra.canonical.params import FINGERS, JOINT_NAMES, BaseParams, ExtendedParams, load_params
from ohra.canonical.urdfgen import render, write
from ohra.canonical.kinematics import Capsules, HandModel

__all__ = ["BaseParams", "ExtendedParams", "load_params", "FINGERS", "JOINT_NAMES", "render", "write", "HandModel", "Capsules"]
