"""Finger-object penetration as a differentiable training term for the joint network.

The joint network is trained by regression on the data's joints, given the data's palm pose. Its
errors (0.12-0.19 rad RMS on unseen objects, benchmarks/README.md *Where the loss is*) sink fingers into the object:
the shipped model's deepest finger starts 6-8 mm inside, the data's 0.5 mm, and a sunk finger is
pushed out in simulation with an impulse that knocks the object away. This term penalises that
directly: for the predicted joints (clamped to the hand's limits) at the grasp's palm pose, points
along each finger capsule core (:func:`ohra.learn.fk_torch.base_fk`, the canonical tree) are looked
up in a signed-distance grid of the object (trilinear, differentiable in the points), and

    P = mean over rows of  sum over points  (max(0, -clearance - (d(p) - r)) / 1 cm)^2

with ``d`` the object body's signed distance (positive outside) and ``r`` the capsule radius, as
:func:`ohra.learn.grasp.refine.refine_grasps` measures it at test time. With ``shift`` > 0 the palm
(and the translation the joint network sees) is moved by Gaussian noise of that standard deviation
first, so the network learns joints that clear the object from palm positions near, not only at,
the data's: at inference the palm comes from the diffusion model, ~1 cm from where the data's would
be for the same rotation.

The penetration term is one-sided, and it cleared the fingers off the object (stop 45: fingers 3-10 mm
outside, success 7 % against 45 %): fingers must touch, not clear. :func:`contact_gap` is two-sided:
per finger link, the nearest point of the predicted joints' capsule to the object is pulled to the
distance the data's joints have there, both capped at ``reach`` (1 cm), so links that touch in the data
touch in the prediction, links that are clear stay at least ``reach`` clear, and neither is pushed
inside:

    C = mean over rows of  sum over links  ((min(m_hat, reach) - min(m_data, reach)) / 1 cm)^2

with ``m`` a link's nearest signed distance (capsule surface, negative inside) at the row's palm (the
prediction's possibly shifted as above, the data's never). At the data's own joints C is 0, so the term
agrees with the joint regression at its optimum and weighs the joint errors by what they do to contact.

That form (``form="capped"``, stop 46's first arms) has no gradient for a link the data has on the
surface but the prediction holds beyond ``reach``: it costs a constant (1 cm)^2 there. ``form="target"``
caps only what the data has clear: a link the data has within ``reach`` is pulled to the data's distance
from wherever it is, one the data has beyond ``reach`` only kept at least ``reach`` clear:

    gap = m_hat - m_data            where m_data < reach
          min(m_hat, reach) - reach  elsewhere

Base-form hands only (the torch FK covers that tree): the unified model's hands.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
import torch

from ohra.canonical.params import BaseParams
from ohra.learn.fk_torch import base_fk, link_presence
from ohra.learn.grasp.config import GraspConfigError
from ohra.objects.model import ObjectModel
from ohra.transforms import rpy_to_matrix

UNIT_M = 0.01  # penetration is measured in centimetres in the loss
SAMPLES_PER_CAPSULE = 5
CONTACT_FORMS = ("capped", "target")


@dataclass
class SDFGrids:
    """Signed distances [m] of K objects sampled on regular grids (G per axis) over each object's
    mesh bounding box grown by ``margin`` [m]; trilinear lookups, differentiable in the points (within 1 mm
    of the exact distance near the surface of the built-in shapes at 48 per axis: tests; the error grows
    with the cell, i.e. with the object's size over the resolution). Not :meth:`ObjectModel.sdf` (numpy,
    one object, cubic cells, for the solver): a batch's rows look up different objects in one gather, so
    every object shares one G^3 layout."""

    values: torch.Tensor  # (K, G, G, G) float32, object mesh frame
    lower: torch.Tensor  # (K, 3) [m] grid corner
    spacing: torch.Tensor  # (K, 3) [m] grid step per axis
    resolution: int

    @classmethod
    def from_objects(cls, objects: Sequence[ObjectModel], resolution: int = 48, margin: float = 0.02) -> "SDFGrids":
        g = int(resolution)
        vals, lows, steps = [], [], []
        for obj in objects:
            b = np.asarray(obj.mesh.bounds, dtype=float)
            lo, hi = b[0] - margin, b[1] + margin
            axes = [np.linspace(lo[i], hi[i], g) for i in range(3)]
            pts = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
            vals.append(np.asarray(obj.signed_distance(pts), dtype=np.float32).reshape(g, g, g))
            lows.append(lo)
            steps.append((hi - lo) / (g - 1))
        f32 = lambda a: torch.from_numpy(np.asarray(a, dtype=np.float32))  # noqa: E731
        return cls(f32(np.stack(vals)), f32(np.stack(lows)), f32(np.stack(steps)), g)

    def __call__(self, obj_idx: torch.Tensor, points: torch.Tensor) -> torch.Tensor:
        """Signed distances (M,) [m] of points (M, 3) [m] in the frames of objects ``obj_idx`` (M,)."""
        g = self.resolution
        lo, step = self.lower[obj_idx], self.spacing[obj_idx]
        raw = (points - lo) / step
        u = raw.clamp(0.0, g - 1 - 1e-4)
        # a point beyond the grid: the value at the nearest grid point plus the way there (the grid's edge
        # lies ``margin`` or more outside the object, so this stays an outside distance); exactly 0 within
        beyond = torch.linalg.vector_norm(points - (lo + u * step), dim=-1)
        beyond = torch.where((raw != u).any(dim=-1), beyond, torch.zeros_like(beyond))
        i0 = u.detach().floor().long()
        f = u - i0
        flat = self.values.reshape(-1)
        base = obj_idx.long() * g**3
        out = beyond
        for dx in (0, 1):
            wx = f[:, 0] if dx else 1 - f[:, 0]
            for dy in (0, 1):
                wy = f[:, 1] if dy else 1 - f[:, 1]
                for dz in (0, 1):
                    wz = f[:, 2] if dz else 1 - f[:, 2]
                    idx = base + ((i0[:, 0] + dx) * g + (i0[:, 1] + dy)) * g + (i0[:, 2] + dz)
                    out = out + wx * wy * wz * flat[idx]
        return out


class FingerCapsules:
    """The finger capsules of a fixed set of base-form hands, differentiable in the joints."""

    def __init__(self, params: Sequence[BaseParams], names: Sequence[str] = ()):
        bad = [names[i] if i < len(names) else str(i) for i, p in enumerate(params) if not isinstance(p, BaseParams)]
        if bad:
            raise GraspConfigError(f"the penetration loss needs base-form hands (the torch FK's tree); {bad} are not: "
                                   "train without it (penetration_weight 0)")
        f32 = lambda a: torch.from_numpy(np.asarray(a, dtype=np.float32))  # noqa: E731
        self.finger_xyz = f32([p.finger_xyz for p in params])
        self.lengths = f32([p.finger_lengths for p in params])
        self.thumb_rot = f32(rpy_to_matrix(np.array([p.thumb_rpy for p in params], dtype=float)))
        self.thumb_axes = f32([p.thumb_axes for p in params])
        self.extra = f32([p.little_extra_origin for p in params])
        self.present = torch.from_numpy(np.stack([np.asarray(p.present_joints, dtype=bool) for p in params]))
        self.radius = f32([p.finger_radius for p in params])
        self.lower = f32([p.joint_lowers for p in params])
        self.upper = f32([p.joint_uppers for p in params])
        # (H, 15): capsule length per (finger, segment) link; 0 where the link carries no geometry
        seg = torch.stack([self.lengths[:, 0]] + [self.lengths[:, 1]] * 4, dim=1)  # (H, 5, 3)
        self.link_len = (seg * link_presence(self.present).to(seg.dtype)).reshape(len(params), 15)

    def points(self, hand_idx: torch.Tensor, q: torch.Tensor, samples: int = SAMPLES_PER_CAPSULE
               ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Points along the capsule cores (B, 15*S, 3) in the palm frame [m], their radii (B, 15*S) [m]
        and a mask of the links that carry geometry (B, 15*S), for joints q (B, 22) clamped to the limits."""
        h = hand_idx.long()
        qc = torch.maximum(torch.minimum(q, self.upper[h]), self.lower[h])
        R, p = base_fk(self.finger_xyz[h], self.lengths[h], self.thumb_rot[h], self.thumb_axes[h], self.extra[h],
                       self.present[h], qc)
        keep = [f * 4 + s for f in range(5) for s in range(3)]  # link frames, not the tips
        R, p = R[:, keep], p[:, keep]  # (B, 15, 3, 3), (B, 15, 3)
        z = R[..., :, 2]
        r = self.radius[h][:, None]
        L = self.link_len[h]
        u = torch.linspace(0.0, 1.0, samples, dtype=q.dtype)
        along = r[..., None] + u * (L - 2 * r)[..., None]  # (B, 15, S): from r to L - r along z
        pts = p[:, :, None] + z[:, :, None] * along[..., None]  # (B, 15, S, 3)
        b = len(q)
        return (pts.reshape(b, -1, 3), r.expand(b, 15 * samples), (L > 0)[..., None].expand(b, 15, samples).reshape(b, -1))


def _distances(caps: FingerCapsules, sdf: SDFGrids, hand_idx: torch.Tensor, obj_idx: torch.Tensor, q: torch.Tensor,
               t_obj: torch.Tensor, R_obj_palm: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Signed distances (B, 15*S) [m] of the capsule surfaces at the core points (negative inside) and the
    mask of the points on links that carry geometry."""
    pts, r, mask = caps.points(hand_idx, q)
    world = torch.einsum("bij,bpj->bpi", R_obj_palm, pts) + t_obj[:, None]
    b, n, _ = world.shape
    return sdf(obj_idx.long().repeat_interleave(n), world.reshape(-1, 3)).reshape(b, n) - r, mask


def penetration(caps: FingerCapsules, sdf: SDFGrids, hand_idx: torch.Tensor, obj_idx: torch.Tensor, q: torch.Tensor,
                t_obj: torch.Tensor, R_obj_palm: torch.Tensor, clearance: float = 0.001
                ) -> tuple[torch.Tensor, torch.Tensor]:
    """The term P (see the module docstring; scalar) and each row's deepest finger point (B,) [m]
    (signed: negative inside), for joints q (B, 22) at palm poses (t_obj (B, 3) [m], R_obj_palm
    (B, 3, 3)) in the frames of objects ``obj_idx``."""
    d, mask = _distances(caps, sdf, hand_idx, obj_idx, q, t_obj, R_obj_palm)
    d = torch.where(mask, d, torch.full_like(d, 1.0))
    depth = torch.relu(-clearance - d) / UNIT_M
    return (depth**2).sum(dim=1).mean(), d.min(dim=1).values


def link_distances(caps: FingerCapsules, sdf: SDFGrids, hand_idx: torch.Tensor, obj_idx: torch.Tensor, q: torch.Tensor,
                   t_obj: torch.Tensor, R_obj_palm: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Per finger link (thumb, index, middle, ring, little x proximal, middle, distal), the nearest signed
    distance of its capsule to the object (B, 15) [m] (negative inside; +inf on links without geometry)
    and the mask of the links with geometry (B, 15)."""
    d, mask = _distances(caps, sdf, hand_idx, obj_idx, q, t_obj, R_obj_palm)
    b = len(q)
    d = torch.where(mask, d, torch.full_like(d, float("inf")))
    return d.reshape(b, 15, -1).min(dim=2).values, mask.reshape(b, 15, -1)[..., 0]


def contact_gap(caps: FingerCapsules, sdf: SDFGrids, hand_idx: torch.Tensor, obj_idx: torch.Tensor, q: torch.Tensor,
                t_obj: torch.Tensor, q_data: torch.Tensor, t_obj_data: torch.Tensor, R_obj_palm: torch.Tensor,
                reach: float = 0.01, form: str = "capped") -> torch.Tensor:
    """The two-sided term C (see the module docstring; scalar) for predicted joints q (B, 22) with the palm
    at ``t_obj`` (B, 3) [m] against the data's joints ``q_data`` at the data's palm ``t_obj_data``, both
    rotated by ``R_obj_palm`` (B, 3, 3) in the frames of objects ``obj_idx``; ``reach`` [m]: distances
    beyond it count as ``reach`` (clear is clear); ``form``: ``"capped"`` (both sides capped) or
    ``"target"`` (only the data's clear links capped)."""
    if form not in CONTACT_FORMS:
        raise GraspConfigError(f"contact form must be one of {CONTACT_FORMS}, got {form!r}")
    m, mask = link_distances(caps, sdf, hand_idx, obj_idx, q, t_obj, R_obj_palm)
    with torch.no_grad():
        target, _ = link_distances(caps, sdf, hand_idx, obj_idx, q_data, t_obj_data, R_obj_palm)
    if form == "capped":
        gap = (m.clamp(max=reach) - target.clamp(max=reach)) / UNIT_M
    else:
        near = target < reach
        gap = torch.where(near, m - torch.where(near, target, torch.zeros_like(target)), m.clamp(max=reach) - reach) / UNIT_M
    gap = torch.where(mask, gap, torch.zeros_like(gap))
    return (gap**2).sum(dim=1).mean()


__all__ = ["SDFGrids", "FingerCapsules", "penetration", "link_distances", "contact_gap", "UNIT_M", "CONTACT_FORMS"]
