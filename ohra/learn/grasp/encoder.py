"""Object encoders: a surface point cloud (B, N, 3) in the object frame [m] -> a feature (B, D).

``pointnet`` (default): a shared per-point MLP and a max-pool (Qi et al. 2017). Measured on this
machine's CPU (torch, forward + backward + Adam) it trains at ~200 clouds/s with 512 points.

``dgcnn``: the paper's encoder family (Wang et al. 2019): a static k-nearest-neighbour graph on the
points, edge convolutions on ``[x_j - x_i, x_i]`` chained block after block (max over the
neighbours after each), the concatenated block outputs projected to ``D`` and mean-pooled over the
points (the reference mean-pools its per-point features). ~3 clouds/s with 512 points and k = 20
on the same CPU, which is why it is not the default; on a GPU (``GraspTrainConfig.device``) it trains
in minutes, and with a 512-D feature it did not beat the PointNet on the unified study's data
(``benchmarks/grasp_capacity.py``: -2.8 +- 0.9 points). (The reference concatenates ``[x_j, x_i]``;
the standard relative form is used here.)

No batch normalisation: a batch holds few distinct objects (their features are shared by all the
grasps of the object), so batch statistics would be noisy and differ between training and
inference.
"""

from __future__ import annotations

import torch
from torch import nn

from ohra.learn.grasp.config import GraspModelConfig


class PointNetEncoder(nn.Module):
    """Shared MLP over points + max-pool + linear projection."""

    def __init__(self, channels: tuple[int, ...] = (64, 128, 256), out_dim: int = 256):
        super().__init__()
        layers: list[nn.Module] = []
        c_in = 3
        for c in channels:
            layers += [nn.Linear(c_in, c), nn.ReLU()]
            c_in = c
        self.point_mlp = nn.Sequential(*layers)
        self.head = nn.Sequential(nn.Linear(c_in, out_dim), nn.ReLU(), nn.Linear(out_dim, out_dim))
        self.out_dim = out_dim

    def forward(self, points: torch.Tensor) -> torch.Tensor:
        """(B, N, 3) -> (B, out_dim)."""
        return self.head(self.point_mlp(points).amax(dim=1))


def knn_indices(points: torch.Tensor, k: int) -> torch.Tensor:
    """(B, N, 3) -> (B, N, k) indices of each point's k nearest points (itself included)."""
    d2 = torch.cdist(points, points)
    return d2.topk(k, dim=-1, largest=False).indices


class DGCNNEncoder(nn.Module):
    """Static-graph edge convolutions (see module docstring)."""

    def __init__(self, channels: tuple[int, ...] = (64, 64, 128, 256), out_dim: int = 256, k: int = 20):
        super().__init__()
        self.k = int(k)
        self.blocks = nn.ModuleList()
        c_in = 6  # [x_j - x_i, x_i]
        for c in channels:
            self.blocks.append(nn.Sequential(nn.Linear(c_in, c), nn.LeakyReLU(0.2)))
            c_in = c
        self.project = nn.Sequential(nn.Linear(sum(channels), out_dim), nn.LeakyReLU(0.2), nn.Linear(out_dim, out_dim))
        self.out_dim = out_dim

    def forward(self, points: torch.Tensor) -> torch.Tensor:
        """(B, N, 3) -> (B, out_dim)."""
        b, n, _ = points.shape
        idx = knn_indices(points, self.k)  # (B, N, k)
        nbr = torch.gather(points.unsqueeze(1).expand(b, n, n, 3), 2, idx.unsqueeze(-1).expand(b, n, self.k, 3))
        centre = points.unsqueeze(2).expand(b, n, self.k, 3)
        h = torch.cat([nbr - centre, centre], dim=-1)  # (B, N, k, 6)
        pooled = []
        for block in self.blocks:
            h = block(h)
            pooled.append(h.amax(dim=2))  # (B, N, c)
        return self.project(torch.cat(pooled, dim=-1)).mean(dim=1)


def make_encoder(cfg: GraspModelConfig) -> nn.Module:
    """The encoder named by ``cfg.encoder``."""
    if cfg.encoder == "pointnet":
        return PointNetEncoder(tuple(cfg.encoder_channels), cfg.object_dim)
    return DGCNNEncoder(tuple(cfg.encoder_channels), cfg.object_dim, cfg.dgcnn_k)


__all__ = ["PointNetEncoder", "DGCNNEncoder", "make_encoder", "knn_indices"]
