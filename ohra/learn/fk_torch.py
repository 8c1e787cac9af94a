"""Batched, differentiable forward kinematics of the base-form canonical hand in torch.

A mirror of the numpy batch FK of :class:`ohra.canonical.kinematics.HandModel` (same tree, same
joint placements as ``urdf/templates/base.urdf.j2``), but batched over *hands* as well as
configurations, and differentiable in the hand parameters: the VAE's fingertip loss runs it on the
decoder's output. ``tests/test_learn_fk_torch.py`` holds it to HandModel (Pinocchio) frame by frame.

Frames, in the palm frame (metres): for each finger (thumb, index, middle, ring, little) the
``proximal``, ``middle`` and ``distal`` link frames and the ``tip`` (:data:`FRAMES`). A link's frame
sits at its joint, z along the segment; the tip is at the end of the finger's last present segment.
Frames of absent fingers are computed too (they collapse onto the finger base); mask them with
:func:`finger_presence`.
"""

from __future__ import annotations

from typing import Sequence

import torch

from ohra.canonical.params import FINGERS

SEGMENT_FRAMES = ("proximal", "middle", "distal", "tip")
FRAMES: tuple[str, ...] = tuple(f"{f}_{s}" for f in FINGERS for s in SEGMENT_FRAMES)
_START = (5, 9, 13, 18)  # joint1 of index, middle, ring, little in the canonical 22-vector


def rotation_about(axis: torch.Tensor, angle: torch.Tensor) -> torch.Tensor:
    """Rodrigues: (B, 3) axes (unit, or zero for 'no rotation') and (B,) angles -> (B, 3, 3)."""
    x, y, z = axis.unbind(-1)
    zero = torch.zeros_like(x)
    K = torch.stack([zero, -z, y, z, zero, -x, -y, x, zero], dim=-1).reshape(axis.shape[:-1] + (3, 3))
    s, c = torch.sin(angle)[..., None, None], torch.cos(angle)[..., None, None]
    eye = torch.eye(3, dtype=axis.dtype, device=axis.device).expand_as(K)
    return eye + s * K + (1.0 - c) * (K @ K)


def rpy_matrix(rpy: torch.Tensor) -> torch.Tensor:
    """URDF fixed-axis rpy (B, 3) -> ``Rz(yaw) Ry(pitch) Rx(roll)`` (B, 3, 3)."""
    eye = torch.eye(3, dtype=rpy.dtype, device=rpy.device)
    ex, ey, ez = (eye[i].expand(rpy.shape[:-1] + (3,)) for i in range(3))
    return rotation_about(ez, rpy[..., 2]) @ rotation_about(ey, rpy[..., 1]) @ rotation_about(ex, rpy[..., 0])


def link_presence(present: torch.Tensor) -> torch.Tensor:
    """(B, 22) joint presence -> (B, 5, 3) float: which (proximal, middle, distal) links carry
    geometry (template rules: thumb j1|j2, j3|j4, j5; others j1|j2, j3, j4; little without j0)."""
    p = present.bool()
    t = torch.stack([p[:, 0] | p[:, 1], p[:, 2] | p[:, 3], p[:, 4]], dim=-1)
    rows = [t]
    for s in _START:
        j = p[:, s : s + 4]
        rows.append(torch.stack([j[:, 0] | j[:, 1], j[:, 2], j[:, 3]], dim=-1))
    return torch.stack(rows, dim=1).to(dtype=torch.get_default_dtype() if not present.is_floating_point() else present.dtype)


def finger_presence(present: torch.Tensor) -> torch.Tensor:
    """(B, 22) joint presence -> (B, 5) bool: fingers with at least one link."""
    return link_presence(present).bool().any(dim=-1)


def _chain(R: torch.Tensor, p: torch.Tensor, lengths: torch.Tensor, links: torch.Tensor,
           axes: Sequence[torch.Tensor], q: torch.Tensor) -> tuple[list[torch.Tensor], list[torch.Tensor]]:
    """The finger from its proximal link frame (R, p) through joints 3.. of the chain.

    ``axes``/``q``: the two rotations that follow (at the start of the middle and distal links);
    a joint rotates after its offset along the parent link's z. Returns the 4 frames' rotations and
    positions (proximal, middle, distal, tip).
    """
    Rs, ps = [R], [p]
    for k in range(2):
        p = p + R[..., :, 2] * (lengths[:, k] * links[:, k])[:, None]
        R = R @ rotation_about(axes[k], q[:, k])
        Rs.append(R)
        ps.append(p)
    p = p + R[..., :, 2] * (lengths[:, 2] * links[:, 2])[:, None]
    Rs.append(R)
    ps.append(p)
    return Rs, ps


def base_fk(finger_xyz: torch.Tensor, finger_lengths: torch.Tensor, thumb_rot: torch.Tensor,
            thumb_axes: torch.Tensor, little_extra: torch.Tensor, present: torch.Tensor,
            q: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """Link and tip frames of a batch of base-form hands.

    Args:
        finger_xyz: (B, 5, 3) finger bases [m] (thumb mount, knuckles).
        finger_lengths: (B, 2, 3) thumb and shared non-thumb segment lengths [m].
        thumb_rot: (B, 3, 3) thumb mounting rotation (URDF ``thumb_rpy`` as a matrix).
        thumb_axes: (B, 2, 3) axes of thumb joints 1 and 2 in the mounting frame (zero if absent).
        little_extra: (B, 6) little metacarpal origin, xyz [m] and fixed-axis rpy [rad].
        present: (B, 22) joint presence (bool or 0/1).
        q: (B, 22) canonical joint angles [rad], default zeros.

    Returns:
        Rotations (B, 20, 3, 3) and positions (B, 20, 3) of :data:`FRAMES` in the palm frame.
    """
    B = finger_xyz.shape[0]
    dt, dev = finger_xyz.dtype, finger_xyz.device
    q = torch.zeros(B, 22, dtype=dt, device=dev) if q is None else q.to(dt)
    links = link_presence(present).to(dt)
    eye = torch.eye(3, dtype=dt, device=dev)
    ex, ey = eye[0].expand(B, 3), eye[1].expand(B, 3)
    Rs, ps = [], []
    # thumb: joints 1 and 2 at the mount (axes from the params), 3 (x) and 4 (y) after the proximal, 5 (y)
    # URDF axes need not be unit length (fitted hands store rounded ones); Pinocchio normalises them
    n = torch.linalg.vector_norm(thumb_axes, dim=-1, keepdim=True)
    a = thumb_axes / torch.where(n > 0, n, torch.ones_like(n))
    R = thumb_rot @ rotation_about(a[:, 0], q[:, 0]) @ rotation_about(a[:, 1], q[:, 1])
    p = finger_xyz[:, 0]
    chain_R, chain_p = [R], [p]
    p = p + R[..., :, 2] * (finger_lengths[:, 0, 0] * links[:, 0, 0])[:, None]
    R = R @ rotation_about(ex, q[:, 2]) @ rotation_about(ey, q[:, 3])
    chain_R.append(R)
    chain_p.append(p)
    p = p + R[..., :, 2] * (finger_lengths[:, 0, 1] * links[:, 0, 1])[:, None]
    R = R @ rotation_about(ey, q[:, 4])
    chain_R += [R, R]
    chain_p += [p, p + R[..., :, 2] * (finger_lengths[:, 0, 2] * links[:, 0, 2])[:, None]]
    Rs += chain_R
    ps += chain_p
    # other fingers: abduction (x) then flexion (y) at the knuckle, two more flexions (y)
    for f, s in zip((1, 2, 3, 4), _START):
        if f < 4:
            R0 = eye.expand(B, 3, 3)
            p0 = finger_xyz[:, f]
        else:  # little: metacarpal joint 0 (y of the tilted frame), then the knuckle undoes the tilt
            E = rpy_matrix(little_extra[:, 3:6])
            Rb = E @ rotation_about(ey, q[:, 17])
            p0 = little_extra[:, :3] + (Rb @ E.transpose(-1, -2) @ (finger_xyz[:, 4] - little_extra[:, :3])[..., None])[..., 0]
            R0 = Rb @ E.transpose(-1, -2)
        R = R0 @ rotation_about(ex, q[:, s]) @ rotation_about(ey, q[:, s + 1])
        fR, fp = _chain(R, p0, finger_lengths[:, 1], links[:, f], [ey, ey], q[:, s + 2 : s + 4])
        Rs += fR
        ps += fp
    return torch.stack(Rs, dim=1), torch.stack(ps, dim=1)


def tips(finger_xyz: torch.Tensor, finger_lengths: torch.Tensor, thumb_rot: torch.Tensor, thumb_axes: torch.Tensor,
         little_extra: torch.Tensor, present: torch.Tensor, q: torch.Tensor | None = None) -> torch.Tensor:
    """Fingertip positions (B, 5, 3) [m] (see :func:`base_fk`; absent fingers are not masked)."""
    _, p = base_fk(finger_xyz, finger_lengths, thumb_rot, thumb_axes, little_extra, present, q)
    return p[:, 3::4]
