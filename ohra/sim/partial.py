"""The resume file of one evaluation: finished grasps' outcomes, kept while a long ``evaluate`` runs.

:meth:`ohra.sim.GraspEvaluator.evaluate` with ``resume=PATH`` rewrites ``PATH`` (an ``.npz``, atomically)
at most every 2 s while grasps finish and once more when the evaluation ends or is interrupted; a later call
with the same grasps, hand, object, protocol and mode takes the outcomes stored there and simulates only the
rest. Outcomes do not depend on order, batch or workers (each grasp starts from a reset world), so a resumed
evaluation equals an uninterrupted one. A file made under other inputs, or one that cannot be read, is
replaced, never trusted.
"""

from __future__ import annotations

import hashlib
import io
import json
import time
from dataclasses import asdict, fields
from pathlib import Path
from typing import Any

import numpy as np

from ohra.io import write_bytes

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


def _entry(v: np.ndarray) -> Any:
    """One grasp's stored value as the result holds it: a 0-d entry as its Python scalar (bool, int, float)."""
    return v.item() if v.ndim == 0 else np.array(v)


class PartialEvaluation:
    """Outcomes finished so far under one :func:`evaluation_key`, written to ``path`` as they come."""

    def __init__(self, path: str | Path, key: str, interval_s: float = 2.0):
        self.path = Path(path)
        self.key = key
        self.interval_s = float(interval_s)
        self._dirty, self._written_at = False, float("-inf")
        self.done: dict[int, Any] = self._read() if self.path.is_file() else {}

    def _read(self) -> dict[int, Any]:
        """The stored outcomes by grasp index; none when the file was made under other inputs or is damaged (it is
        then simulated again and overwritten, never trusted)."""
        from ohra.sim.evaluator import GraspResult

        names = [f.name for f in fields(GraspResult)]  # one array per field, stacked over the finished grasps
        try:
            with np.load(self.path, allow_pickle=False) as z:
                if str(z["key"]) != self.key:
                    return {}
                idx, cols = z["index"], {n: z[n] for n in names}
        except Exception:  # noqa: BLE001 - a damaged file is simulated again, not an error
            return {}
        return {int(i): GraspResult(**{n: _entry(cols[n][k]) for n in names}) for k, i in enumerate(idx)}

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
        from ohra.sim.evaluator import GraspResult

        idx = sorted(self.done)
        arrays = {f.name: np.array([getattr(self.done[i], f.name) for i in idx]) for f in fields(GraspResult)}
        buf = io.BytesIO()
        np.savez(buf, key=np.array(self.key), index=np.array(idx, dtype=np.int64), **arrays)
        write_bytes(self.path, buf.getvalue())
        self._dirty, self._written_at = False, time.monotonic()


__all__ = ["PartialEvaluation", "evaluation_key"]
