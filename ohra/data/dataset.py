"""Grasp datasets: atomic shard/manifest writes and the lazy :class:`GraspDataset` reader.

A dataset is a directory with ``manifest.json`` and one ``.npz`` shard per (hand, object) under
``<hand>/``, or, once packed (:mod:`ohra.data.pack`), one ``.npz`` per hand holding its shards' rows. In format ``ohra-grasps/2`` a shard's ``grasps`` are the (M,31) float32
``[t, rot6d, q22]`` vectors exactly as the simulator evaluated them (the *pre-test* grasps, which
passed the six-direction test and its robustness trials), and ``grasps_post`` the same grasps
after the nominal test (hand pose relative to the settled object, settled joints: what the
reference datasets store; the settled joints can lie outside the hand's limits, which PyBullet
holds as soft constraints, by up to ~0.3 rad in the committed datasets). :class:`GraspDataset` returns the pre-test grasps unless asked for
``which="post"``. Format 1 shards hold only post-test ``grasps``.

Shards are byte-deterministic (fixed zip timestamps), so the same seed gives the same bytes on
any backend, and their sha256 in the manifest tells a complete shard from a damaged one.
"""

from __future__ import annotations

import hashlib
import io
import json
import re
import zipfile
from pathlib import Path
from typing import Iterator

import numpy as np

from ohra.errors import DatasetError
from ohra.io import write_bytes, write_json


def shard_name(obj_name: str, mesh_hash: str) -> str:
    safe = re.sub(r"[^A-Za-z0-9_.-]", "_", obj_name)
    return f"{safe}-{mesh_hash[:8]}.npz"


def npz_bytes(arrays: dict[str, np.ndarray]) -> bytes:
    """A compressed ``.npz`` of ``arrays`` whose bytes depend only on the arrays (``np.savez``
    stamps each member with the current time)."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for key, val in arrays.items():
            info = zipfile.ZipInfo(f"{key}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            with zf.open(info, "w", force_zip64=True) as fh:
                np.lib.format.write_array(fh, np.asanyarray(val), allow_pickle=False)
    return buf.getvalue()


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically, honouring the umask (see :mod:`ohra.io`)."""
    write_bytes(path, data)


def atomic_write_npz(path: str | Path, arrays: dict[str, np.ndarray]) -> None:
    """Write ``arrays`` to ``path`` atomically (never a partial shard), byte-identical for equal arrays."""
    write_bytes(path, npz_bytes(arrays))


def file_digest(path: str | Path) -> str:
    """SHA-256 of a file's bytes (16 hex, as manifests store it)."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()[:16]


def atomic_write_json(path: str | Path, data: dict) -> None:
    """Write ``data`` as JSON atomically (a manifest is whole or absent); see :mod:`ohra.io`."""
    write_json(path, data, indent=1)


class GraspDataset:
    """Lazy reader of grasp dataset directories (filter by hand/object, cap per pair, merge).

    Args:
        path: a dataset directory or a list of them.
        hands, objects: keep only these hand names / object names or manifest keys.
        max_per_pair: at most this many grasps per (hand, object) pair (0 or None: no cap, as in training).
        which: ``"pre"`` (default): the grasps exactly as evaluated, which passed the test and
            its robustness trials; ``"post"``: the same grasps after the nominal test.
        split: ``"train"`` or ``"test"``: only objects of that side of the recipe's split.

    Raises:
        DatasetError: a directory without a manifest; ``which`` or ``split`` unknown; a named hand or object in
            none of the directories; one hand name with different params (params hash) in two directories.
    """

    def __init__(self, path: str | Path, hands: list[str] | None = None, objects: list[str] | None = None,
                 max_per_pair: int | None = None, which: str = "pre", split: str | None = None):
        listed = isinstance(path, (list, tuple))
        bad = [p for p in (path if listed else [path]) if not isinstance(p, (str, Path))]
        if bad or (listed and not path):
            got = f"{type(bad[0]).__name__}{' in the list' if listed else ''}" if bad else "an empty list"
            raise DatasetError(f"GraspDataset: expected a dataset folder path or a list of them, got {got}")
        if split not in (None, "train", "test"):
            raise DatasetError(f"split must be 'train', 'test' or None, got {split!r}")
        if which not in ("pre", "post"):
            raise DatasetError(f"which must be 'pre' or 'post', got {which!r}")
        if max_per_pair is not None and (isinstance(max_per_pair, bool) or not isinstance(max_per_pair, (int, np.integer))
                                         or max_per_pair < 0):
            raise DatasetError(f"max_per_pair must be a whole number >= 0 (0 or None: no cap), got {max_per_pair!r}")
        # one name by itself is one hand / object, not a sequence of letters
        hands = [hands] if isinstance(hands, str) else hands
        objects = [objects] if isinstance(objects, str) else objects
        self.roots = unique_dirs([path] if not isinstance(path, (list, tuple)) else path)
        self.which = which
        self.entries: list[tuple[Path, str, str, dict]] = []
        seen_hands: set[str] = set()
        object_keys: set[str] = set()
        object_names: set[str] = set()
        hand_params: dict[str, dict[str, Path]] = {}  # hand -> params hash -> first folder holding it
        for root in self.roots:
            manifest = require_manifest(root)
            fmt = manifest.get("format", "ohra-grasps/1")
            if split and split not in manifest.get("split", {}):
                raise DatasetError(f"{root}: the manifest records no object split (build the dataset from a recipe)")
            side = set(manifest["split"][split]) if split else None
            for hand, entry in manifest.get("hands", {}).items():
                seen_hands.add(hand)
                selected = not hands or hand in hands
                if selected and entry.get("params_hash"):
                    hand_params.setdefault(hand, {}).setdefault(str(entry["params_hash"]), root)
                for key, sh in entry.get("shards", {}).items():
                    name = sh.get("object", {}).get("name", key)
                    object_keys.add(key)
                    object_names.add(name)
                    if not selected or (objects and key not in objects and name not in objects) or (side is not None and key not in side):
                        continue
                    self.entries.append((root, hand, key, {**sh, "_format": fmt, "_name": name}))
        unknown = [h for h in (hands or []) if h not in seen_hands]
        if unknown:  # a typo would otherwise read as an empty dataset
            raise DatasetError(f"hand(s) {unknown} not in {', '.join(map(str, self.roots))}; it holds "
                               f"{', '.join(sorted(seen_hands)) or 'no hands'}")
        unknown = [o for o in (objects or []) if o not in object_keys and o not in object_names]
        if unknown:
            held = sorted(object_names)
            raise DatasetError(f"object(s) {unknown} not in {', '.join(map(str, self.roots))} (by name or key); it holds "
                               f"{len(held)} object(s): {', '.join(held[:12]) + (' ...' if len(held) > 12 else '') or 'none'}")
        for hand, by_hash in hand_params.items():
            if len(by_hash) > 1:  # e.g. a spec's base form in one folder and its extended form in another
                where = "; ".join(f"{h} in {r}" for h, r in by_hash.items())
                raise DatasetError(f"hand {hand!r} has different params in these folders ({where}): their grasps are not "
                                   "one hand's; read the folders apart, or keep one form of the hand")
        self.max_per_pair = max_per_pair

    @classmethod
    def merge(cls, *datasets: "GraspDataset") -> "GraspDataset":
        """One dataset over the shards of several, read alike: their ``which`` and ``max_per_pair`` must agree
        (a merged dataset reads every shard one way; taking the first's silently changed the others').

        Raises:
            DatasetError: no datasets, or datasets read with different ``which`` or ``max_per_pair``.
        """
        if not datasets:
            raise DatasetError("merge needs at least one dataset")
        for attr in ("which", "max_per_pair"):
            values = [getattr(d, attr) for d in datasets]
            if any(v != values[0] for v in values):
                raise DatasetError(f"merge: the datasets are read with different {attr} ({values}); open them alike")
        out = cls.__new__(cls)
        out.roots = [r for d in datasets for r in d.roots]
        out.entries = [e for d in datasets for e in d.entries]
        out.max_per_pair = datasets[0].max_per_pair
        out.which = datasets[0].which
        return out

    @property
    def pairs(self) -> list[tuple[str, str]]:
        """(hand, object key) of every shard."""
        return [(h, o) for _, h, o, _ in self.entries]

    def load_shard(self, hand: str, obj: str) -> dict[str, np.ndarray]:
        """All arrays of the shard of ``hand`` and ``obj`` (a manifest key or an unambiguous object name)."""
        hits = [e for e in self.entries if e[1] == hand and e[2] == obj] or \
               [e for e in self.entries if e[1] == hand and e[3]["_name"] == obj]
        if len(hits) > 1:
            raise DatasetError(f"object name {obj!r} names {len(hits)} shards of hand {hand!r}; use one of their keys: "
                               + ", ".join(e[2] for e in hits))
        if not hits:
            raise DatasetError(f"no shard for hand {hand!r} and object {obj!r}")
        return self._read(hits[0][0], hits[0][3])

    def _read(self, root: Path, sh: dict, keys: tuple[str, ...] | None = None) -> dict[str, np.ndarray]:
        """The shard's arrays (only ``keys`` when given: a shard holds ~18 arrays and a training set
        reads thousands of shards for their grasps), after checking its hash and the grasp shapes."""
        if "pack" in sh:  # a packed directory (ohra.data.pack): the pack's hash is checked once per file
            from ohra.data.pack import read_row

            path = root / sh["pack"]["file"]
            data = read_row(root, sh, keys)
        else:
            path = root / sh["file"]
            if not path.is_file():
                raise DatasetError(f"shard listed in the manifest is missing: {path}")
            digest = file_digest(path)
            if sh.get("sha256") and digest != sh["sha256"]:
                raise DatasetError(f"{path}: content hash {digest} does not match the manifest ({sh['sha256']})")
            try:
                with np.load(path) as z:
                    data = {k: z[k] for k in z.files if keys is None or k in keys}
            except Exception as exc:  # zipfile / numpy raise several types for damaged files
                raise DatasetError(f"{path}: cannot read shard ({exc})") from None
        for key in ("grasps", "grasps_post") if sh["_format"] != "ohra-grasps/1" else ("grasps",):
            g = data.get(key)
            if g is None or g.ndim != 2 or g.shape[1] != 31 or len(g) != sh.get("n_grasps", len(g)):
                raise DatasetError(f"{path}: {key} have shape {None if g is None else g.shape}, manifest says ({sh.get('n_grasps')}, 31)")
        return data

    def _grasps(self, root: Path, sh: dict) -> np.ndarray:
        data = self._read(root, sh, keys=("grasps", "grasps_post"))
        if sh["_format"] == "ohra-grasps/1":
            if self.which == "pre":
                raise DatasetError(f"{root / sh['file']}: format 1 shards store post-test grasps only; use which='post'")
            return data["grasps"]
        return data["grasps" if self.which == "pre" else "grasps_post"]

    def __iter__(self) -> Iterator[tuple[str, str, np.ndarray]]:
        for root, h, o, sh in self.entries:
            g = self._grasps(root, sh)
            yield h, o, g[: self.max_per_pair] if self.max_per_pair else g

    def grasps(self) -> np.ndarray:
        """(M,31) float32 grasps of all selected pairs (see ``which``)."""
        parts = [g for _, _, g in self]
        return np.concatenate(parts) if parts else np.zeros((0, 31), np.float32)

    def __len__(self) -> int:
        return sum(min(sh["n_grasps"], self.max_per_pair or sh["n_grasps"]) for _, _, _, sh in self.entries)

    def __repr__(self) -> str:
        roots = ", ".join(repr(str(r)) for r in self.roots)
        hands = len({h for _, h, _, _ in self.entries})
        cap = f", max_per_pair={self.max_per_pair}" if self.max_per_pair else ""
        return f"GraspDataset([{roots}]: {hands} hands, {len(self.entries)} pairs, {len(self)} grasps, which={self.which!r}{cap})"


def unique_dirs(paths) -> list[Path]:
    """``paths`` as Paths, each folder once (``d`` and ``./d/`` are one folder: given twice, every grasp or total
    would count twice), in the order given."""
    seen, out = set(), []
    for p in map(Path, paths):
        if p.resolve() not in seen:
            seen.add(p.resolve())
            out.append(p)
    return out


def require_manifest(root: str | Path) -> dict:
    """The manifest of the dataset directory ``root``; :class:`DatasetError` if it has none."""
    if Path(root).is_file():
        raise DatasetError(f"{root} is a file; give the dataset's folder" + (" (the folder holding it)"
                                                                           if Path(root).name == "manifest.json" else ""))
    if not Path(root).exists():
        raise DatasetError(f"dataset folder not found: {root}")
    manifest = read_manifest(Path(root) / "manifest.json")
    if manifest is None:
        raise DatasetError(f"{root}: no manifest.json (not an ohra grasp dataset)")
    return manifest


def read_manifest(path: str | Path) -> dict | None:
    """The manifest at ``path`` (None if absent); :class:`DatasetError` naming the file if it is not
    a readable manifest (truncated JSON, not an object, no ``hands``)."""
    path = Path(path)
    if not path.is_file():
        return None
    try:
        data = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise DatasetError(f"{path}: corrupt manifest ({exc}); delete it (and the shards) or write to another directory") from None
    if not isinstance(data, dict) or not isinstance(data.get("hands"), dict):
        raise DatasetError(f"{path}: not an ohra grasp manifest (no 'hands' object); delete it or write to another directory")
    table = data.pop("objects", None) or {}
    for hand, entry in data["hands"].items():
        for key, sh in entry.get("shards", {}).items():
            ref = sh.get("object")
            if isinstance(ref, str):  # a description stored once in the "objects" table (ohra.data.manifest)
                if ref not in table:
                    raise DatasetError(f"{path}: {hand}/{key} names object {ref!r}, which the manifest's objects table lacks")
                sh["object"] = table[ref]
    return data
