"""Packed datasets: one ``.npz`` per hand instead of one per (hand, object) pair.

A finished dataset of thousands of pairs is mostly zip overhead: a shard holds 18 arrays of a few
candidates each, ~4.6 kB on disk of which ~1.5 kB is data. :func:`pack` concatenates each hand's
shards into ``<hand>/pack-<sha8>.npz`` (every array along its first axis, with its row offsets)
and gives each manifest entry ``pack = {file, sha256, row}``; ``file`` and ``sha256`` keep naming
the pair's own shard. Packing is lossless and checked: each row re-serialised with
:func:`ohra.data.dataset.npz_bytes` must give exactly the bytes its ``sha256`` records before any
loose shard is deleted, so :func:`unpack` restores every shard byte for byte.

Readers (:class:`ohra.data.GraspDataset`, ``--resume``) take packed and loose entries alike; a
build resumed into a packed directory writes loose shards beside the packs, and packing again
folds them in. Pack only finished directories you commit: a pack is rewritten whole.
"""

from __future__ import annotations

import functools
import hashlib
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ohra.data.dataset import file_digest, npz_bytes, require_manifest
from ohra.data.manifest import ManifestWriter
from ohra.errors import DatasetError
from ohra.io import folder_lock, write_bytes

ROWS = ".rows"  # suffix of a member holding the row offsets (P+1,) of the array of the same name
KEYS = "_keys"  # member holding the object key of each row
PACK_NAME = re.compile(r"pack-[0-9a-f]{8}\.npz")  # the name pack() gives a hand's pack


@dataclass(frozen=True)
class PackReport:
    """What :func:`pack` did to one directory. Sizes in bytes, of the shard and pack files."""

    path: str
    hands: int
    packed: int  # pairs now in packs
    folded: int  # loose shards folded in by this call
    bytes_before: int
    bytes_after: int

    def line(self) -> str:
        return (f"{self.path}: {self.packed} pairs of {self.hands} hands packed ({self.folded} loose shards folded in), "
                f"{_size(self.bytes_before)} -> {_size(self.bytes_after)} of shard files")


def _size(n: int) -> str:
    """Bytes as a short size that does not read 0.0 for a small folder: 812 B, 14.2 kB, 3.4 MB."""
    return f"{n} B" if n < 1000 else f"{n / 1e3:.1f} kB" if n < 999_950 else f"{n / 1e6:.1f} MB"  # never "1000.0 kB"


@functools.lru_cache(maxsize=256)
def _pack_arrays(path: str, mtime_ns: int, size: int, sha: str) -> dict[str, np.ndarray]:
    digest = file_digest(path)
    if digest != sha:
        raise DatasetError(f"{path}: content hash {digest} does not match the manifest ({sha})")
    try:
        with np.load(path) as z:
            return {k: z[k] for k in z.files}
    except Exception as exc:  # zipfile / numpy raise several types for damaged files
        raise DatasetError(f"{path}: cannot read pack ({exc})") from None


def pack_arrays(root: Path, ref: dict) -> dict[str, np.ndarray]:
    """All arrays of the pack ``ref`` (a manifest entry's ``pack``) names under ``root``, hash-checked
    once per file version."""
    path = Path(root) / ref["file"]
    if not path.is_file():
        raise DatasetError(f"pack listed in the manifest is missing: {path}")
    st = path.stat()
    return _pack_arrays(str(path), st.st_mtime_ns, st.st_size, ref["sha256"])


def pack_complete(root: Path, ref: dict) -> bool:
    """Whether the pack ``ref`` names is present with the recorded hash (for ``--resume``)."""
    try:
        pack_arrays(root, ref)
        return True
    except DatasetError:
        return False


def read_row(root: Path, sh: dict, keys: tuple[str, ...] | None = None) -> dict[str, np.ndarray]:
    """The arrays of one packed pair (only ``keys`` when given), as its shard held them."""
    z, row = pack_arrays(root, sh["pack"]), int(sh["pack"]["row"])
    names = [k for k in z if not k.endswith(ROWS) and k != KEYS]
    if not 0 <= row < len(z[KEYS]):
        raise DatasetError(f"{Path(root) / sh['pack']['file']}: row {row} out of range (pack of {len(z[KEYS])} pairs)")
    out = {}
    for k in names:
        if keys is None or k in keys:
            o = z[k + ROWS]
            out[k] = z[k][o[row]:o[row + 1]]
    return out


def _shard_arrays(root: Path, hand: str, key: str, sh: dict) -> dict[str, np.ndarray]:
    if "pack" in sh:
        arrays = read_row(root, sh)
    else:
        path = root / sh.get("file", "")
        if not path.is_file() or not sh.get("sha256") or file_digest(path) != sh["sha256"]:
            raise DatasetError(f"{path}: shard of {hand}/{key} is missing or does not match its manifest hash; "
                               "complete the dataset (ohra data build ... --resume) before packing")
        with np.load(path) as z:
            arrays = {k: z[k] for k in z.files}
    if sh.get("sha256") and hashlib.sha256(npz_bytes(arrays)).hexdigest()[:16] != sh["sha256"]:
        raise DatasetError(f"{root / sh.get('file', '')}: {hand}/{key} does not re-serialise to its recorded bytes; not packed")
    return arrays


def _concat(hand: str, rows: list[tuple[str, dict[str, np.ndarray]]]) -> dict[str, np.ndarray]:
    names = list(rows[0][1])
    out: dict[str, np.ndarray] = {KEYS: np.array([k for k, _ in rows], dtype=str)}
    for k, arrays in rows:
        if list(arrays) != names:
            raise DatasetError(f"{hand}/{k}: arrays {sorted(arrays)} differ from the hand's other shards ({sorted(names)})")
    for n in names:
        parts = [a[n] for _, a in rows]
        if len({(p.dtype.str, p.shape[1:]) for p in parts}) > 1 or any(p.ndim == 0 for p in parts):
            raise DatasetError(f"{hand}: array {n!r} has differing dtypes or trailing shapes across shards; cannot pack")
        out[n] = np.concatenate(parts)
        out[n + ROWS] = np.concatenate([[0], np.cumsum([len(p) for p in parts])]).astype(np.int64)
    return out


def _dataset_files(root: Path, hands: dict) -> set[Path]:
    """The shard and pack files ``hands`` (a manifest's) names that exist, and any pack file left
    unlisted in a hand's folder (a build that recomputed all of a packed hand's pairs); never
    another ``.npz`` a user keeps there."""
    out: set[Path] = set()
    for hand, entry in hands.items():
        for sh in entry.get("shards", {}).values():
            out |= {root / f for f in (sh.get("file"), sh.get("pack", {}).get("file")) if f}
        if (root / hand).is_dir():
            out |= {f for f in (root / hand).iterdir() if PACK_NAME.fullmatch(f.name)}
    return {f for f in out if f.suffix == ".npz" and f.is_file()}


def pack(root: str | Path) -> PackReport:
    """Pack every hand's shards of the dataset ``root`` (see the module doc), fold loose shards into
    the packs, and delete the shard and pack files they replace (other files are left alone).
    Holds the dataset folder's lock, as a build does.

    Args:
        root: a finished dataset directory (holding ``manifest.json``).

    Returns:
        A :class:`PackReport`: hands and pairs packed, loose shards folded in, shard bytes before/after.

    Raises:
        DatasetError: no or unreadable manifest; a shard or pack missing, damaged or not
            re-serialising to its recorded bytes; shards of one hand with differing arrays, dtypes or
            trailing shapes (in all these cases nothing is changed).
        FolderInUseError: another process (a build) is writing ``root``.
    """
    root = Path(root)
    require_manifest(root)  # before the lock, which would create a missing folder
    with folder_lock(root, "dataset"):  # a build writing into root holds it
        return _pack(root, require_manifest(root))


def _pack(root: Path, manifest: dict) -> PackReport:
    hands = manifest.get("hands", {})
    old = _dataset_files(root, hands)
    before = sum(f.stat().st_size for f in old)
    new_packs, folded = {}, 0
    for hand, entry in hands.items():
        shards = entry.get("shards", {})
        if not shards:
            continue
        rows = [(key, _shard_arrays(root, hand, key, sh)) for key, sh in shards.items()]
        folded += sum("pack" not in sh for sh in shards.values())
        data = npz_bytes(_concat(hand, rows))
        sha = hashlib.sha256(data).hexdigest()[:16]
        new_packs[hand] = (f"{hand}/pack-{sha[:8]}.npz", sha, data)
    # every pack is written before the manifest points at it, and files are deleted only after
    # the manifest no longer lists them: an interruption leaves a readable dataset
    for name, sha, data in new_packs.values():
        if not ((root / name).is_file() and file_digest(root / name) == sha):
            write_bytes(root / name, data)
    for hand, (name, sha, _) in new_packs.items():
        for row, sh in enumerate(hands[hand]["shards"].values()):
            sh["pack"] = {"file": name, "sha256": sha, "row": row}
    ManifestWriter(root / "manifest.json").write(manifest)
    keep = {root / name for name, _, _ in new_packs.values()}
    for f in old - keep:
        f.unlink()
    after = sum(f.stat().st_size for f in keep)
    packed = sum(len(e.get("shards", {})) for e in hands.values())
    return PackReport(str(root), len(new_packs), packed, folded, before, after)


def unpack(root: str | Path) -> int:
    """Write every packed pair of ``root`` back to its own shard file (byte-identical to the one
    packed) and drop the packs; returns the number of shards written. Holds the dataset folder's
    lock (:class:`~ohra.errors.FolderInUseError` while a build writes ``root``)."""
    root = Path(root)
    require_manifest(root)  # before the lock, which would create a missing folder
    with folder_lock(root, "dataset"):
        return _unpack(root, require_manifest(root))


def _unpack(root: Path, manifest: dict) -> int:
    n, packs = 0, set()
    for hand, entry in manifest.get("hands", {}).items():
        for key, sh in entry.get("shards", {}).items():
            if "pack" not in sh:
                continue
            write_bytes(root / sh["file"], npz_bytes(_shard_arrays(root, hand, key, sh)))
            packs.add(root / sh.pop("pack")["file"])
            n += 1
    ManifestWriter(root / "manifest.json").write(manifest)
    for p in packs:
        p.unlink(missing_ok=True)
    return n
