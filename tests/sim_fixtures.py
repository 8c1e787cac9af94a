"""Hand-made hands, objects and grasps whose evaluation outcome is known by construction."""

from __future__ import annotations

import numpy as np
import trimesh

from ohra import ActionMap
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


# -- a rigid cage: a "hand" that holds a cube against every push but one ------------------------------
CUBE = 0.03  # cube edge [m]
CAGE_INNER = CUBE / 2 + 0.001  # half-width of the cage's inside: 1 mm clearance [m]
CAGE_WALL = 0.01  # wall thickness [m]
_INERTIAL = ('<inertial><mass value="0.1"/>'
             '<inertia ixx="1e-4" iyy="1e-4" izz="1e-4" ixy="0" ixz="0" iyz="0"/></inertial>')


def cube() -> ObjectModel:
    return ObjectModel(trimesh.creation.box(extents=(CUBE,) * 3), "cube", repair=False)


def cage_hand(open_side: np.ndarray | None) -> tuple[str, ActionMap]:
    """URDF and action map of a fixed box with five walls around the origin, open toward the unit
    vector ``open_side`` (None: closed on all six sides). Its palm frame is the URDF root, so the
    grasp ``pose_to_grasp(np.eye(4), 0)`` puts the :func:`cube` in the middle. One hinge, 30 cm away,
    gives the action map a joint to drive; it never comes near the cube."""
    walls = []
    for axis in range(3):
        for sign in (1.0, -1.0):
            normal = np.zeros(3)
            normal[axis] = sign
            if open_side is not None and np.allclose(normal, open_side):
                continue
            size = np.full(3, 2 * (CAGE_INNER + CAGE_WALL))
            size[axis] = CAGE_WALL
            xyz = normal * (CAGE_INNER + CAGE_WALL / 2)
            walls.append(f'<collision><origin xyz="{xyz[0]} {xyz[1]} {xyz[2]}"/>'
                         f'<geometry><box size="{size[0]} {size[1]} {size[2]}"/></geometry></collision>')
    urdf = (f'<robot name="cage"><link name="palm">{_INERTIAL}{"".join(walls)}</link>'
            f'<link name="flag">{_INERTIAL}<collision><geometry><sphere radius="0.005"/></geometry></collision></link>'
            '<joint name="hinge" type="revolute"><parent link="palm"/><child link="flag"/><origin xyz="0 0 -0.3"/>'
            '<axis xyz="1 0 0"/><limit lower="-0.1" upper="0.1" effort="1" velocity="1"/></joint></robot>')
    return urdf, ActionMap.from_urdf(urdf, {"index_joint1": "hinge"})


def palm_at(xyz=(0.0, 0.0, 0.0)) -> np.ndarray:
    """Grasp with the palm (unrotated) at ``xyz`` in the object frame and all canonical joints 0."""
    T = np.eye(4)
    T[:3, 3] = xyz
    return pose_to_grasp(T, np.zeros(22))
