"""Grasp datasets: atomic shard/manifest IO, the lazy ``GraspDataset`` reader, recipes and builds."""

from ohra.data.dataset import (GraspDataset, atomic_write_bytes, atomic_write_json, atomic_write_npz, file_digest, npz_bytes,
                               read_manifest, shard_name)

__all__ = ["GraspDataset", "atomic_write_bytes", "atomic_write_json", "atomic_write_npz", "file_digest", "npz_bytes",
           "read_manifest", "shard_name"]
