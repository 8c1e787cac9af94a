"""The resume file of one evaluation: finished grasps' outcomes, kept while a long ``evaluate`` runs.

:meth:`ohra.sim.GraspEvaluator.evaluate` with ``resume=PATH`` rewrites ``PATH`` (an ``.npz``, atomically)
at most every 2 s while grasps finish and once more when the evaluation ends or is interrupted; a later call with the same grasps, hand, object, protocol and mode takes the
outcomes stored there and simulates only the rest. Outcomes do not depend on order, batch or workers (each
grasp starts from a reset world), so a resumed evaluation equals an uninterrupted one. A file made under
other inputs, or one that cannot be read, is replaced, never trusted.
"""

from __future__ import annotations

import hashlib
import io
import json
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from ohra.io import write_bytes

# one array per GraspResult field, stacked over the finished grasps
_FIELDS = ("success", "displacement", "final_distance_from_origin", "contacts", "initial_penetration", "post_grasp",
           "clamped", "early_exit", "steps")


def evaluation_key(hand: Any, obj: Any, protocol: Any, mode: str, grasps: np.ndarray) -> str:
    """What one evaluation's outcomes depend on, as a hex digest: the simulated hand (URDF text, driven joints,
    locked values, couplings), the object (mesh and simulated body), the protocol, the mode and the grasps."""
    h = hashlib.sha256()
    h.update(hand.urdf.encode())
    h.update(json.dumps([list(hand.joints), np.asarray(hand.drive).tolist(), np.asarray(hand.base, float).tolist(),
                         repr(tuple(hand.couplings))], default=str).encode())
    h.update(f"{obj.mesh_hash}|{getattr(obj, 'body_hash', '')}|{mode}".encode())
    h.update(json.dumps(asdict(protocol), sort_keys=True, default=str).encode())
    g = np.ascontiguousarray(grasps, dtype=np.float64)
    h.update(str(g.shape).encode())
    h.update(g.tobytes())
    return h.hexdigest()


class PartialEvaluation:
    """Outcomes finished so far under one :func:`evaluation_key`, written to ``path`` as they come."""

    def __init__(self, path: str | Path, key: str, interval_s: float = 2.0):
        self.path = Path(path)
        self.key = key
        self.interval_s = float(interval_s)
        self._dirty, self._written_at = False, float("-inf")
        self.replaced = False  # a file was there, made under other inputs or unreadable: it will be overwritten
        self.done: dict[int, Any] = self._read() if self.path.is_file() else {}

    def _read(self) -> dict[int, Any]:
        from ohra.sim.evaluator import GraspResult

        try:
            with np.load(self.path, allow_pickle=False) as z:
                if str(z["key"]) != self.key:
                    self.replaced = True
                    return {}
                idx = z["index"].astype(int)
                cols = {f: z[f] for f in _FIELDS}
        except Exception:  # noqa: BLE001 - a damaged file is simulated again, not an error
            self.replaced = True
            return {}
        out = {}
        for k, i in enumerate(idx):
            out[int(i)] = GraspResult(bool(cols["success"][k]), np.array(cols["displacement"][k]),
                                      float(cols["final_distance_from_origin"][k]), int(cols["contacts"][k]),
                                      float(cols["initial_penetration"][k]), np.array(cols["post_grasp"][k]),
                                      bool(cols["clamped"][k]), bool(cols["early_exit"][k]), int(cols["steps"][k]))
        return out

    def add(self, index: int, result: Any) -> None:
        """Record one finished grasp; the file is rewritten when ``interval_s`` has passed since the last write
        (each write holds every finished grasp, so writing after each of thousands would cost quadratic time)."""
        self.done[int(index)] = result
        self._dirty = True
        if time.monotonic() - self._written_at >= self.interval_s:
            self.flush()

    def flush(self) -> None:
        """Rewrite the file with every finished grasp if any came since the last write (atomically: an
        interruption during the write leaves the previous file)."""
        if not self._dirty:
            return
        idx = sorted(self.done)
        arrays = {f: np.array([getattr(self.done[i], f) for i in idx]) for f in _FIELDS}
        buf = io.BytesIO()
        np.savez(buf, key=np.array(self.key), index=np.array(idx, dtype=np.int64), **arrays)
        write_bytes(self.path, buf.getvalue())
        self._dirty, self._written_at = False, time.monotonic()

    def remove(self) -> None:
        self.path.unlink(missing_ok=True)


__all__ = ["PartialEvaluation", "evaluation_key"]
