"""The torch batch FK of base-form hands equals HandModel (Pinocchio) frame by frame."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from ohra.canonical.kinematics import HandModel  # noqa: E402
from ohra.canonical.params import FINGERS, BaseParams  # noqa: E402
from ohra.hands import hands_in_form  # noqa: E402
from ohra.learn.fk_torch import FRAMES, base_fk, finger_presence, tips  # noqa: E402
from ohra.learn.geometry import tips_q0  # noqa: E402
from ohra.learn.sampler import EXTRA, LENGTHS, LOWERS, THUMB_AXES, THUMB_RPY, UPPERS, XYZ, sample_vectors  # noqa: E402
from ohra.transforms import rpy_to_matrix  # noqa: E402


def _inputs(v: np.ndarray, q: np.ndarray):
    t = lambda a: torch.from_numpy(np.ascontiguousarray(a, dtype=np.float64))  # noqa: E731
    n = len(v)
    present = (v[:, LOWERS] != 0) | (v[:, UPPERS] != 0)
    return (t(v[:, XYZ].reshape(n, 5, 3)), t(v[:, LENGTHS].reshape(n, 2, 3)), t(rpy_to_matrix(v[:, THUMB_RPY])),
            t(v[:, THUMB_AXES].reshape(n, 2, 3)), t(v[:, EXTRA]), torch.from_numpy(present), t(q))


def _check(v: np.ndarray, q: np.ndarray) -> float:
    R, p = base_fk(*_inputs(v, q))
    worst = 0.0
    for i, row in enumerate(v):
        hm = HandModel.from_params(BaseParams.from_vector(row))
        names, idx = [], []
        for k, name in enumerate(FRAMES):
            f, s = name.split("_")
            if not hm.present_fingers[FINGERS.index(f)]:
                continue
            names.append(f"{f}_tip" if s == "tip" else name)
            idx.append(k)
        T = hm.frame_poses(q[i][None], names)[0]
        worst = max(worst, float(np.abs(T[:, :3, 3] - p[i, idx].numpy()).max()), float(np.abs(T[:, :3, :3] - R[i, idx].numpy()).max()))
    return worst


def test_frames_match_pinocchio_for_sampled_hands_at_random_configurations():
    v = sample_vectors(40, 5)
    rng = np.random.default_rng(0)
    lo, up = v[:, LOWERS], v[:, UPPERS]
    q = lo + rng.random(lo.shape) * (up - lo)
    assert _check(v, q) < 1e-10  # the URDF text carries 12 significant digits


def test_frames_match_pinocchio_for_registered_hands():
    hands = list(hands_in_form("base").values())
    if not hands:
        pytest.skip("no registered base-form hands in this checkout")
    v = np.stack([p.to_vector() for p in hands])
    rng = np.random.default_rng(1)
    q = v[:, LOWERS] + rng.random((len(v), 22)) * (v[:, UPPERS] - v[:, LOWERS])
    assert _check(v, q) < 1e-10  # the URDF text carries 12 significant digits
    assert _check(v, np.zeros_like(q)) < 1e-10


def test_q0_tips_match_the_numpy_shortcut_and_are_differentiable():
    v = sample_vectors(64, 9)
    args = list(_inputs(v, np.zeros((64, 22))))
    args[0] = args[0].clone().requires_grad_(True)
    t = tips(*args)
    present = finger_presence(args[5]).numpy()
    ref = tips_q0(v)
    assert np.array_equal(np.isnan(ref[..., 0]), ~present)
    assert np.abs(t.detach().numpy()[present] - ref[present]).max() < 1e-12
    t[torch.from_numpy(present)].sum().backward()
    assert torch.isfinite(args[0].grad).all() and args[0].grad.abs().sum() > 0
