"""Grasp datasets: atomic shard/manifest writes and the lazy :class:`GraspDataset` reader.

A dataset is a directory with ``manifest.json`` and one ``.npz`` shard per (hand, object) under
``<hand>/``. ``grasps`` in a shard are (M,31) float32 ``[t, rot6d, q22]`` post-simulation grasps.
"""

from __future__ import annotations

import hashlib
import json
import re
from pathlib import Path
from typing import Iterator

import numpy as np

from ohra.errors import DatasetError
from ohra.io import write_json, write_npz


def shard_name(obj_name: str, mesh_hash: str) -> str:
    safe = re.sub(r"[^A-Za-z0-9_.-]", "_", obj_name)
    return f"{safe}-{mesh_hash[:8]}.npz"


def atomic_write_npz(path: str | Path, arrays: dict[str, np.ndarray]) -> None:
    """Write ``arrays`` to ``path`` atomically (never a partial shard); see :mod:`ohra.io`."""
    write_npz(path, arrays)


def atomic_write_json(path: str | Path, data: dict) -> None:
    """Write ``data`` as JSON atomically (a manifest is whole or absent); see :mod:`ohra.io`."""
    write_json(path, data, indent=1)


class GraspDataset:
    """Lazy reader of a grasp dataset directory (filter by hand/object, cap per pair, merge)."""

    def __init__(self, path: str | Path, hands: list[str] | None = None, objects: list[str] | None = None,
                 max_per_pair: int | None = None):
        self.roots = [Path(path)] if not isinstance(path, (list, tuple)) else [Path(p) for p in path]
        self.entries: list[tuple[Path, str, str, dict]] = []
        for root in self.roots:
            man = root / "manifest.json"
            if not man.is_file():
                raise DatasetError(f"{root}: no manifest.json (not an ohra grasp dataset)")
            try:
                manifest = json.loads(man.read_text())
            except json.JSONDecodeError as exc:
                raise DatasetError(f"{man}: malformed JSON ({exc})") from None
            for hand, entry in manifest.get("hands", {}).items():
                if hands and hand not in hands:
                    continue
                for obj, sh in entry.get("shards", {}).items():
                    if objects and obj not in objects:
                        continue
                    self.entries.append((root, hand, obj, sh))
        self.max_per_pair = max_per_pair

    @classmethod
    def merge(cls, *datasets: "GraspDataset") -> "GraspDataset":
        out = cls.__new__(cls)
        out.roots = [r for d in datasets for r in d.roots]
        out.entries = [e for d in datasets for e in d.entries]
        out.max_per_pair = min((d.max_per_pair for d in datasets if d.max_per_pair), default=None)
        return out

    @property
    def pairs(self) -> list[tuple[str, str]]:
        return [(h, o) for _, h, o, _ in self.entries]

    def load_shard(self, hand: str, obj: str) -> dict[str, np.ndarray]:
        for root, h, o, sh in self.entries:
            if (h, o) == (hand, obj):
                return self._read(root, sh)
        raise DatasetError(f"no shard for hand {hand!r} and object {obj!r}")

    def _read(self, root: Path, sh: dict) -> dict[str, np.ndarray]:
        path = root / sh["file"]
        if not path.is_file():
            raise DatasetError(f"shard listed in the manifest is missing: {path}")
        digest = hashlib.sha256(path.read_bytes()).hexdigest()[:16]
        if sh.get("sha256") and digest != sh["sha256"]:
            raise DatasetError(f"{path}: content hash {digest} does not match the manifest ({sh['sha256']})")
        with np.load(path) as z:
            data = {k: z[k] for k in z.files}
        g = data.get("grasps")
        if g is None or g.ndim != 2 or g.shape[1] != 31 or len(g) != sh.get("n_grasps", len(g)):
            raise DatasetError(f"{path}: grasps have shape {None if g is None else g.shape}, manifest says ({sh.get('n_grasps')}, 31)")
        return data

    def __iter__(self) -> Iterator[tuple[str, str, np.ndarray]]:
        for root, h, o, sh in self.entries:
            g = self._read(root, sh)["grasps"]
            yield h, o, g[: self.max_per_pair] if self.max_per_pair else g

    def grasps(self) -> np.ndarray:
        parts = [g for _, _, g in self]
        return np.concatenate(parts) if parts else np.zeros((0, 31), np.float32)

    def __len__(self) -> int:
        return sum(min(sh["n_grasps"], self.max_per_pair or sh["n_grasps"]) for _, _, _, sh in self.entries)
