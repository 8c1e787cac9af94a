"""When a rotation episode ends: the object fell, left the hand, or the physics broke.

Pure functions of the object's state (world frame, metres), so each threshold is testable on both sides.
"""

from __future__ import annotations

import numpy as np


def fell(obj_pos: np.ndarray, obj_start: np.ndarray, fall_height: float) -> bool:
    """The object is more than ``fall_height`` below its start height."""
    return bool(obj_pos[2] < obj_start[2] - fall_height)


def left_hand(obj_pos: np.ndarray, obj_start: np.ndarray, max_distance: float) -> bool:
    """The object is more than ``max_distance`` from its start position."""
    return bool(np.linalg.norm(np.asarray(obj_pos) - np.asarray(obj_start)) > max_distance)


def broken(*arrays: np.ndarray) -> bool:
    """Some state value is NaN or infinite (the simulation diverged)."""
    return not np.isfinite(np.concatenate([np.ravel(a) for a in arrays])).all()


def reason(obj_pos: np.ndarray, obj_start: np.ndarray, fall_height: float, max_distance: float,
           *state: np.ndarray) -> str | None:
    """Why the episode ends now ("broken", "fell", "left"), or None while it goes on."""
    if broken(obj_pos, *state):
        return "broken"
    if fell(obj_pos, obj_start, fall_height):
        return "fell"
    if left_hand(obj_pos, obj_start, max_distance):
        return "left"
    return None
