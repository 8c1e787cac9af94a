"""Mirror images of canonical hands and of their grasps (left hand <-> right hand), exactly.

A hand reflected through its palm frame's x-z plane (``M = diag(1, -1, 1)``: +y, the side of a right
hand's thumb, becomes -y) is again a canonical hand. Every fixed joint placement ``(R, p)`` becomes
``(M R M, M p)``, and a rotation about an axis ``a`` by ``q`` becomes one about ``-M a`` by ``q``, which is
one about ``M a`` by ``-q``. Of the two, the mirror image takes the one its parsed left/right pairs use
(the registered Shadow, Allegro, LEAP, Inspire pairs), so a mirrored right hand reads like a parsed
left hand and the other way round:

* thumb joints 1-2 (their axes are parameters of both forms): axis ``-M a``, same angle;
* every other joint whose axis lies nearer the palm's x-z plane than its y axis (abduction axes, the
  thumb's third joint, in the base form the template's +x axes): axis ``M a`` (+x stays +x), angle
  ``-q``, limits ``[-upper, -lower]``;
* the rest (flexion axes, along y): axis ``-M a`` (+y stays +y), same angle.

:attr:`MirroredHand.signs` holds the angle factors: at joint angles ``signs * q`` every link pose of the
mirror image is ``M T M`` of the hand's at ``q``, exactly (``tests/test_mirror.py`` checks it for every
registered hand in both forms, LEAP variants and sampled hands). Mirroring twice gives the hand back.

A grasp mirrors with its object. The object is reflected through its own x-z plane (``S = diag(1, -1,
1)`` in its mesh frame); a grasp ``[t, rot6d(R), q]`` of the hand on the object becomes ``[S t,
rot6d(S R M), signs * q]`` of the mirror image on the mirrored object (``S R M`` is a rotation again). The
map is its own inverse. Physics is mirror-symmetric, so a grasp that holds one object holds the
mirrored object with the mirrored hand: a grasp model that knows right hands can grasp with a left
one through this map (:meth:`ohra.learn.grasp.model.GraspModel.sample`, ``mirror=``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ohra.canonical.params import EXT_ROW_JOINTS, JOINT_NAMES, BaseParams, ExtendedParams, Params
from ohra.errors import GraspError, ParamsError

PALM_MIRROR = np.diag([1.0, -1.0, 1.0])
"""``M``: reflection through the palm frame's x-z plane (and, as ``S``, through an object frame's)."""

BASE_FLIPPED_JOINTS = (2, 5, 9, 13, 18)
"""Joints of the base form whose axis the template fixes along +x (``thumb_joint3``, ``index_joint1``,
``middle_joint1``, ``ring_joint1``, ``little_joint1``): the mirror image turns them the other way."""

_Y_FLIP = np.array([1.0, -1.0, 1.0])  # M p, and M a
_RPY_FLIP = np.array([-1.0, 1.0, -1.0])  # (roll, pitch, yaw) of M R M
_AXIS_FLIP = np.array([-1.0, 1.0, -1.0])  # -M a


@dataclass(frozen=True)
class MirroredHand:
    """A hand's mirror image.

    Attributes:
        params: the mirror image, in the form (and template) of the hand it mirrors.
        signs: (22,) +1 / -1: the mirror image at ``signs * q`` is the hand at ``q`` reflected (and back).
    """

    params: Params
    signs: np.ndarray

    def joints(self, q: np.ndarray) -> np.ndarray:
        """Joint angles [rad] (..., 22) of one hand as the other's (the map is its own inverse).

        Raises:
            GraspError: ``q`` is not numbers with 22 in its last axis.
        """
        try:
            q = np.asarray(q, dtype=float)
        except (TypeError, ValueError):
            raise GraspError(f"joint angles: expected numbers, got {type(q).__name__}") from None
        if q.shape[-1:] != (22,):
            raise GraspError(f"joint angles: expected shape (22,) or (..., 22), got {q.shape}")
        return q * self.signs


def mirror_params(params: Params) -> MirroredHand:
    """The mirror image of ``params`` (see the module docstring): a left hand from a right one and back.

    Mirroring twice gives back the same parameters. Couplings between joints are not parameters:
    :func:`mirror_couplings` carries them.

    Raises:
        ParamsError: ``params`` is not :class:`BaseParams` or :class:`ExtendedParams`.
    """
    if not isinstance(params, (BaseParams, ExtendedParams)):
        raise ParamsError(f"mirror_params: expected BaseParams or ExtendedParams, got {type(params).__name__}")
    signs = np.ones(22)
    lo, up = np.asarray(params.joint_lowers, dtype=float), np.asarray(params.joint_uppers, dtype=float)
    d = params.to_dict()
    if isinstance(params, BaseParams):
        extra = np.asarray(params.little_extra_origin, dtype=float).copy()
        extra[:3] *= _Y_FLIP
        extra[3:] *= _RPY_FLIP
        signs[list(BASE_FLIPPED_JOINTS)] = -1.0
        d.update(finger_xyz=(np.asarray(params.finger_xyz, dtype=float) * _Y_FLIP).tolist(), little_extra_origin=extra.tolist(),
                 thumb_rpy=(np.asarray(params.thumb_rpy, dtype=float) * _RPY_FLIP).tolist(),
                 thumb_axes=(np.asarray(params.thumb_axes, dtype=float) * _AXIS_FLIP).tolist())
        form: type = BaseParams
    else:
        o = np.asarray(params.joint_origins, dtype=float).copy()
        o[:, :3] *= _Y_FLIP
        o[:, 3:] *= _RPY_FLIP
        a = np.asarray(params.joint_axes, dtype=float)
        # M a (angle reversed) where the axis lies nearer the x-z plane than y; never for the thumb's first two
        turn = (a[:, 0] ** 2 + a[:, 2] ** 2 > a[:, 1] ** 2) & (np.arange(12) > 1)
        rows = np.array([JOINT_NAMES.index(j) for j in EXT_ROW_JOINTS])
        signs[rows[turn]] = -1.0
        d.update(joint_origins=o.tolist(), joint_axes=np.where(turn[:, None], a * _Y_FLIP, a * _AXIS_FLIP).tolist())
        form = ExtendedParams
    # + 0.0: an absent joint's limits stay 0, not -0
    d.update(joint_lowers=(np.where(signs > 0, lo, -up) + 0.0).tolist(), joint_uppers=(np.where(signs > 0, up, -lo) + 0.0).tolist())
    out = form.from_dict(d)
    signs.setflags(write=False)
    return MirroredHand(out, signs)


def mirror_couplings(couplings, signs: np.ndarray) -> tuple:
    """Joint couplings (``q[slot] = m * q[driver] + b``, :class:`ohra.canonical.couplings.Coupling`) of a hand as
    couplings of its mirror image, whose angles are ``signs * q``: ``m`` becomes ``s_slot * s_driver * m`` and ``b``
    becomes ``s_slot * b``."""
    from dataclasses import replace

    from ohra.canonical.params import JOINT_INDEX

    s = np.asarray(signs, dtype=float)
    return tuple(replace(c, multiplier=float(s[JOINT_INDEX[c.slot]] * s[JOINT_INDEX[c.driver]] * c.multiplier),
                         offset=float(s[JOINT_INDEX[c.slot]] * c.offset) + 0.0) for c in couplings)


def mirror_grasps(grasps: np.ndarray, signs: np.ndarray) -> np.ndarray:
    """Grasps ``[t (3), rot6d (6), q (22)]`` (n, 31) of a hand on an object as grasps of its mirror image
    on the mirrored object (both reflected through their frames' x-z planes; the map is its own inverse).

    Args:
        grasps: (31,) or (n, 31): palm position [m] and rot6d in the object frame, joint angles [rad].
        signs: (22,) :attr:`MirroredHand.signs` of the hand.

    Returns:
        Same shape: ``[S t, rot6d(S R M), signs * q]``.

    Raises:
        GraspError: grasps that are not numbers or not 31 each; ``signs`` not 22 values of +1 / -1.
    """
    try:
        g = np.asarray(grasps, dtype=float)
        s = np.asarray(signs, dtype=float)
    except (TypeError, ValueError):
        raise GraspError(f"mirror_grasps: expected numeric grasps and signs, got {type(grasps).__name__} and "
                         f"{type(signs).__name__}") from None
    if g.shape[-1:] != (31,) or g.ndim not in (1, 2):
        raise GraspError(f"mirror_grasps: expected grasps of shape (31,) or (n, 31), got {g.shape}")
    if s.shape != (22,):
        raise GraspError(f"mirror_grasps: expected 22 joint signs, got shape {s.shape}")
    if not np.all(np.abs(s) == 1.0):
        bad = int(np.flatnonzero(np.abs(s) != 1.0)[0])
        raise GraspError(f"mirror_grasps: joint signs are +1 or -1 (MirroredHand.signs), got signs[{bad}] = {s[bad]:g}")
    out = g.copy()
    # S R M: columns S c1 (M e1 = e1) and -S c2 (M e2 = -e2); S negates the y entry of each
    out[..., 0:3] *= _Y_FLIP
    out[..., 3:6] *= _Y_FLIP
    out[..., 6:9] *= _AXIS_FLIP
    out[..., 9:] = out[..., 9:] * s + 0.0  # + 0.0: no -0 for an absent joint
    return out


__all__ = ["PALM_MIRROR", "BASE_FLIPPED_JOINTS", "MirroredHand", "mirror_params", "mirror_couplings", "mirror_grasps"]
