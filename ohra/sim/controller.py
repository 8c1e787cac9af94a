"""The reference squeeze controller (OHRA ``controller.py``, survey §5.1).

Per joint: ``motion = axis_world x link_z_world`` is the direction its child link moves for a
positive rotation (the link is assumed to extend along its frame's +z, true of canonical links and
the reference's assumption for any hand); ``to_object`` points from the joint origin to the object
origin. If ``motion . to_object >= 0`` a positive rotation closes: the joint is reset ``outer`` of
the way toward its lower (opening) limit and driven ``inner`` of the way past the grasp toward its
upper (closing) limit; otherwise the reverse. The fingers therefore start slightly open and
squeeze.

A hand with coupled joints (:mod:`ohra.canonical.couplings`) passes ``couple``: the reset and the
target are projected so every coupled joint follows its driver, as the mechanism (or the original
URDF's mimic joints) would, instead of being squeezed on its own toward its own limit.
"""

from __future__ import annotations

from typing import Callable

import numpy as np


def closes_positive(axis_world: np.ndarray, link_z_world: np.ndarray, joint_pos_world: np.ndarray,
                    object_origin: np.ndarray | None = None) -> np.ndarray:
    """(J,) bool: a positive rotation of each joint moves its link toward the object origin.

    All inputs are world-frame (J,3) arrays; ``object_origin`` defaults to the world origin.
    """
    o = np.zeros(3) if object_origin is None else np.asarray(object_origin, dtype=float)
    motion = np.cross(np.asarray(axis_world, dtype=float), np.asarray(link_z_world, dtype=float))
    to_obj = o - np.asarray(joint_pos_world, dtype=float)
    to_obj = to_obj / np.maximum(np.linalg.norm(to_obj, axis=-1, keepdims=True), 1e-12)
    return (motion * to_obj).sum(axis=-1) >= 0.0


def squeeze_targets(q: np.ndarray, lower: np.ndarray, upper: np.ndarray, closes_pos: np.ndarray,
                    outer: float = 0.1, inner: float = 0.1,
                    couple: Callable[[np.ndarray], np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(q_reset, q_target) of the reference controller for joint values ``q`` (radians).

    ``couple`` maps a joint vector onto the hand's couplings (e.g. :meth:`ohra.sim.hands.SimHand.project_sim`);
    both outputs pass through it.
    """
    q, lo, up = (np.asarray(a, dtype=float) for a in (q, lower, upper))
    reset = np.where(closes_pos, q + outer * (lo - q), q + outer * (up - q))
    target = np.where(closes_pos, q + inner * (up - q), q + inner * (lo - q))
    if couple is not None:
        reset, target = couple(reset), couple(target)
    return reset, target
