"""Grasp datasets: atomic shard/manifest IO and the lazy ``GraspDataset`` reader."""

from ohra.data.dataset import GraspDataset, atomic_write_json, atomic_write_npz, shard_name

__all__ = ["GraspDataset", "atomic_write_json", "atomic_write_npz", "shard_name"]
