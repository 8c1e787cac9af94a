"""Cache keys of the grasp-model studies: a cached training run or evaluation is reused only when it
was made with the same settings.

A training run directory holds ``study_key.json`` (data folders and a digest of their grasps,
hands, held-out hands, steps, seed, condition); a run made with other settings, or by a script that
wrote no key, stops the study with one line naming the difference instead of being reused. An
evaluation JSON carries its key (the model's key, hands, objects, grasps per pair, seed, protocol,
original or canonical); one with another key is recomputed.
"""

from __future__ import annotations

import hashlib
import json
import re
import sys
import time
from dataclasses import asdict, fields, is_dataclass
from pathlib import Path
from typing import Any, Callable, TypeVar

from ohra.data.dataset import atomic_write_json, read_manifest
from ohra.errors import FolderInUseError

T = TypeVar("T")

KEY_FILE = "study_key.json"


def data_fingerprint(data: list[str]) -> list[str]:
    """``<folder>:<digest of its content>`` per dataset folder: the settings digest and every pair's
    (hand, object key, shard sha256). A grown or rebuilt dataset differs; the same grasps in another
    file layout (a rewritten manifest, a packed directory: ``ohra data pack``) do not."""
    out = []
    for d in data:
        man = read_manifest(Path(d) / "manifest.json")
        if man is None:  # a mistyped folder would otherwise be a key of its own, and a stamp on the run
            from ohra.errors import DatasetError

            raise DatasetError(f"--data {d}: no dataset there (no manifest.json)")
        pairs = sorted((h, k, sh.get("sha256")) for h, e in man.get("hands", {}).items() for k, sh in e.get("shards", {}).items())
        digest = hashlib.sha256(json.dumps([man.get("settings_digest"), pairs]).encode()).hexdigest()[:16]
        out.append(f"{Path(d).name}:{digest}")
    return out


def _jsonable(x: Any) -> Any:
    return json.loads(json.dumps(asdict(x) if is_dataclass(x) else x, default=str))


def train_key(data: list[str], hands: list[str], steps: int, seed: int, condition: str, test_hands: tuple = (),
              condition_noise: float = 0.0) -> dict:
    extra = {"condition_noise": float(condition_noise)} if condition_noise else {}  # earlier runs keep their keys
    return _jsonable({"data": data_fingerprint(data), "hands": list(hands), "test_hands": list(test_hands),
                      "steps": int(steps), "seed": int(seed), "condition": condition, **extra})


def _differences(old: dict, new: dict) -> str:
    keys = [k for k in sorted(set(old) | set(new)) if old.get(k) != new.get(k)]
    return ", ".join(f"{k}: {old.get(k)!r} -> {new.get(k)!r}"[:200] for k in keys)


def claim_run(run: Path, key: dict) -> bool:
    """Tie ``run`` to ``key``. True when the run is complete and may be reused; False when it must be
    trained (new, or resumed from its checkpoint). Exits with one line when ``run`` belongs to other settings."""
    f = run / KEY_FILE
    if f.exists() and not _trained(run) and not _busy(run):  # a stamp of a run that failed before training holds nothing
        f.unlink()
    if f.exists():
        old = json.loads(f.read_text())
        if old != key:
            raise SystemExit(f"{run}: cached with other settings ({_differences(old, key)}); "
                             "delete it or pass another --runs")
        return (run / "model.pt").exists()
    if _trained(run):  # weights without a key: their settings are unknown (a failed run's lock or config is not a cache)
        raise SystemExit(f"{run}: a run without {KEY_FILE} (made by an older script, settings unknown); "
                         "delete it or pass another --runs")
    run.mkdir(parents=True, exist_ok=True)
    atomic_write_json(f, key)
    return False


def _trained(run: Path) -> bool:
    """Whether ``run`` holds trained weights (a finished model or a checkpoint): a cache its key protects."""
    return (run / "model.pt").exists() or any((run / "checkpoints").glob("*.pt"))


def _busy(run: Path) -> bool:
    """Whether another process holds ``run``'s folder lock (it is training there, maybe not checkpointed yet)."""
    from ohra.io import folder_lock

    try:
        with folder_lock(run, "training run"):
            return False
    except FolderInUseError:
        return True


def when_free(get: Callable[[], T], poll_s: float = 30.0) -> T:
    """``get()``, waited for while another process trains the same run (two study processes whose
    ``--train-only`` lists overlap): it fails with ``FolderInUseError`` until the other finishes,
    then ``get()`` finds the run complete and reuses it."""
    while True:
        try:
            return get()
        except FolderInUseError as e:
            print(f"{e}; waiting {poll_s:g} s", file=sys.stderr, flush=True)
            time.sleep(poll_s)


def run_key(run: Path) -> dict:
    """The key of a claimed run (for the keys of its evaluations)."""
    return json.loads((run / KEY_FILE).read_text())


def _protocol_repr(protocol: Any, omit: tuple[str, ...] = ()) -> str:
    """A protocol as the study keys hold it: its dataclass repr, without the fields ``omit`` (nor
    ``object_point`` at "frame", what every evaluation did before the setting existed: keys made before it hold)."""
    if getattr(protocol, "object_point", None) == "frame":
        omit = (*omit, "object_point")
    return f"{type(protocol).__name__}(" + ", ".join(
        f"{f.name}={getattr(protocol, f.name)!r}" for f in fields(protocol) if f.name not in omit) + ")"


def eval_key(model_key: dict, **settings: Any) -> dict:
    prot = settings.get("protocol")
    if is_dataclass(prot):
        # canonical URDFs carry no <dynamics damping>: Protocol.urdf_joint_damping cannot change a
        # canonical evaluation, and leaving it out keeps the keys of the evaluations cached before it
        settings["protocol"] = _protocol_repr(prot, () if settings.get("original") else ("urdf_joint_damping",))
    return _jsonable({"model": model_key, **settings})


def carried_over(path: Path, key: dict, hands_unaffected: Callable[[str], bool]) -> dict | None:
    """The cached result at ``path`` when it differs from ``key`` only in having been made before
    ``Protocol.urdf_joint_damping`` existed (it ran with the URDF damping applied): its pairs of the
    hands for which ``hands_unaffected(hand)`` (their URDFs carry no damping; every hand when ``key``
    keeps the damping too) are still valid. Returns ``{"hands": [...], "result": old}`` or None."""
    from ohra.sim.protocol import URDF_DAMPING_BEFORE

    m = re.search(r", urdf_joint_damping=(True|False)\)$", str(key.get("protocol", "")))
    if m is None or not path.exists():
        return None
    old = json.loads(path.read_text())
    if old.get("key") != {**key, "protocol": key["protocol"][:m.start()] + ")"}:
        return None
    keeps = (m.group(1) == "True") == URDF_DAMPING_BEFORE
    hands = [h for h in old["key"].get("hands", []) if keeps or hands_unaffected(h)]
    return {"hands": hands, "result": old} if hands else None


def cached(path: Path, key: dict) -> dict | None:
    """The cached result at ``path`` when it was made with ``key``, else None."""
    if not path.exists():
        return None
    out = json.loads(path.read_text())
    return out if out.get("key") == key else None


def store(path: Path, key: dict, result: dict) -> dict:
    out = {**result, "key": key}
    atomic_write_json(path, out)
    return out
