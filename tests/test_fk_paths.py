"""Every forward-kinematics path equals Pinocchio, the reference, to 1e-9 m on random configurations.

The paths (see each module's docstring for why it stays):

- ``HandModel.frame_poses`` on a batch: vectorised numpy over the kinematic tree;
- ``ohra.synth.fk``: CasADi expressions for the grasp NLP;
- ``ohra.original.parse.canonical_keypoints``: joint origins and tips straight from parameter arrays
  for the parse fit, which changes the parameters at every residual evaluation. It mirrors the
  standard templates only (``base``/``extended``), so LEAP-template hands skip it.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from ohra.canonical.kinematics import HandModel
from ohra.canonical.params import FINGERS, JOINT_NAMES, BaseParams
from ohra.canonical.urdfgen import template_name
from ohra.hands import get_hand, registry
from ohra.synth.fk import fk_function

ATOL = 1e-9  # m (and the same bound on rotation-matrix entries)
N_CONFIGS = 8

# LEAP variants (leap template; 4, 3 and 2 fingers, some segments absent), registered hands in the
# base and extended forms (standard templates; Allegro and Shadow have unaligned thumb axes)
HANDS = [
    ("leap_3333", None), ("leap_3303", None), ("leap_2203", None),
    ("shadow_hand_right", "base"), ("barrett_hand", "base"),
    ("allegro_hand_right", "extended"), ("shadow_hand_left", "extended"), ("mano", "extended"),
]


def _params(name: str, form: str | None):
    return get_hand(name) if form is None else registry.registered_params(name, form)


def _pinocchio(hm: HandModel, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Reference (F,4,4) frame poses (order ``frame_names``) and (22,3) joint origins (canonical order)."""
    T = np.array([hm.frame_pose(q, f) for f in hm.frame_names])
    pin.forwardKinematics(hm.model, hm.data, hm._to_pin(q))
    J = np.array([hm.data.oMi[hm.model.getJointId(n)].translation for n in JOINT_NAMES])
    return T, J


def _canonical_keypoints(params, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    from ohra.original.keypoints import canonical_keypoints, ext_arrays, ext_arrays_from_base

    if isinstance(params, BaseParams):
        arr = ext_arrays_from_base(params.to_vector(), params.present_joints)
    else:
        arr = ext_arrays(params)
    return canonical_keypoints(arr, params.present_joints, q)


@pytest.mark.parametrize("name, form", HANDS, ids=[f"{n}-{f or 'variant'}" for n, f in HANDS])
def test_every_fk_path_equals_pinocchio(name, form):
    params = _params(name, form)
    hm = HandModel.from_params(params)
    Q = hm.random_configurations(N_CONFIGS, seed=17)
    ref = [_pinocchio(hm, q) for q in Q]
    T_ref = np.array([r[0] for r in ref])  # (N, F, 4, 4)

    # numpy batch
    np.testing.assert_allclose(hm.frame_poses(Q), T_ref, rtol=0, atol=ATOL)

    # CasADi, one configuration at a time as the NLP evaluates it
    frames = list(hm.frame_names)
    fk = fk_function(hm, frames)
    for q, T in zip(Q, T_ref):
        out = fk(q)
        np.testing.assert_allclose(np.array([np.array(out[2 * k]) for k in range(len(frames))]), T[:, :3, :3], rtol=0, atol=ATOL)
        np.testing.assert_allclose(np.array([np.array(out[2 * k + 1]).ravel() for k in range(len(frames))]), T[:, :3, 3], rtol=0, atol=ATOL)

    # parameter-array keypoints (standard templates only)
    if template_name(params) == "leap.urdf.j2":
        return
    J, tips = _canonical_keypoints(params, Q)
    np.testing.assert_allclose(J, np.array([r[1] for r in ref]), rtol=0, atol=ATOL)
    tip_ref = np.full((N_CONFIGS, 5, 3), np.nan)
    for i, f in enumerate(FINGERS):
        if f"{f}_tip" in hm.frame_names:
            tip_ref[:, i] = T_ref[:, frames.index(f"{f}_tip"), :3, 3]
    np.testing.assert_allclose(tips, tip_ref, rtol=0, atol=ATOL)
