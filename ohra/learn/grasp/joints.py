"""Joint network: the 22 canonical joint angles [rad] given the wrist pose and the conditions.

Input ``[condition (object feature, hand condition, rot6d), translation (normalised, 3)]``; a
residual MLP (pre-activation blocks, like the reference's nflows ``ResidualNet`` but wider) outputs
the 22 angles. At inference they are clamped to the hand's joint limits, which also zeroes every
absent joint (limits (0, 0)); the reference sent unclamped joints to the simulator.
"""

from __future__ import annotations

import torch
from torch import nn


class _Block(nn.Module):
    def __init__(self, width: int):
        super().__init__()
        self.net = nn.Sequential(nn.ReLU(), nn.Linear(width, width), nn.ReLU(), nn.Linear(width, width))

    def forward(self, h: torch.Tensor) -> torch.Tensor:
        return h + self.net(h)


class JointNet(nn.Module):
    """Residual MLP: (B, in_dim) -> (B, 22) joint angles [rad] (unclamped)."""

    def __init__(self, in_dim: int, hidden: int = 256, blocks: int = 2, n_joints: int = 22):
        super().__init__()
        self.inp = nn.Linear(in_dim, hidden)
        self.blocks = nn.Sequential(*[_Block(hidden) for _ in range(int(blocks))])
        self.out = nn.Sequential(nn.ReLU(), nn.Linear(hidden, n_joints))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.out(self.blocks(self.inp(x)))


def clamp_joints(q: torch.Tensor, lower: torch.Tensor, upper: torch.Tensor) -> torch.Tensor:
    """Clamp (B, 22) angles into [lower, upper] (each (22,) or (B, 22)); absent joints (0, 0) become 0."""
    return torch.maximum(torch.minimum(q, upper), lower)


__all__ = ["JointNet", "clamp_joints"]
