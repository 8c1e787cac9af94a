"""Hand-made hands, objects and grasps whose evaluation outcome is known by construction."""

from __future__ import annotations

import numpy as np
import trimesh

from ohra.objects.model import ObjectModel
from ohra.canonical.params import BaseParams
from ohra.rotations import pose_to_grasp

R_F = 0.01  # finger radius [m]
Y_F = 0.04  # finger knuckles at y = +-Y_F [m]
Z_K = 0.10  # knuckle height above the palm's wrist edge [m]
L = (0.04, 0.03, 0.03)  # segment lengths [m]


def pinch_hand() -> BaseParams:
    """Index (y=+Y_F) and little (y=-Y_F) fingers, straight along +z; abduction squeezes them together."""
    lo, up = np.zeros(22), np.zeros(22)
    for s in (slice(5, 9), slice(18, 22)):
        lo[s] = (-0.5, 0.0, 0.0, 0.0)
        up[s] = (0.5, 1.5, 1.5, 1.5)
    return BaseParams(
        palm_radius=0.045, finger_radius=R_F, finger_lengths=[[0.0, 0.0, 0.0], list(L)],
        finger_xyz=[[0, 0, 0], [0.0, Y_F, Z_K], [0, 0, 0], [0, 0, 0], [0.0, -Y_F, Z_K]],
        little_extra_origin=np.zeros(6), thumb_rpy=np.zeros(3), thumb_axes=np.zeros((2, 3)),
        joint_lowers=lo, joint_uppers=up,
    )


def pinch_box(gap: float = 0.0) -> ObjectModel:
    """A box that fills the space between the two fingers, minus ``gap`` on each side [m]."""
    width = 2 * (Y_F - R_F) - 2 * gap
    return ObjectModel(trimesh.creation.box(extents=(0.03, width, 0.04)), "pinch_box", repair=False)


def pinch_grasp(dx: float = 0.0, dy: float = 0.0) -> np.ndarray:
    """Palm pose putting the box centre between the fingers' middle segments, shifted by (dx, dy)."""
    T = np.eye(4)
    T[:3, 3] = (dx, dy, -(Z_K + 0.05))
    return pose_to_grasp(T, np.zeros(22))
