"""CasADi forward kinematics generated from the canonical tree equals Pinocchio."""

from __future__ import annotations

import numpy as np
import pytest

from ohra.hands import get_hand
from ohra.canonical.kinematics import HandModel
from ohra.synth.fk import fk_function


@pytest.mark.parametrize("hand", ["leap_3333", "leap_2203", "shadow", "allegro"])
def test_casadi_fk_equals_pinocchio(hand, shadow_base, allegro_ext):
    params = {"shadow": shadow_base, "allegro": allegro_ext}.get(hand) or get_hand(hand)
    hm = HandModel.from_params(params)
    frames = list(hm.frame_names)
    f = fk_function(hm, frames)
    for q in hm.random_configurations(10, seed=11):
        out = f(q)
        for k, name in enumerate(frames):
            T = hm.frame_pose(q, name)
            assert np.allclose(np.array(out[2 * k]), T[:3, :3], atol=1e-9), name
            assert np.allclose(np.array(out[2 * k + 1]).ravel(), T[:3, 3], atol=1e-9), name
