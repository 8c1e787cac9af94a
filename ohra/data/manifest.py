"""The manifest of a grasp dataset directory: opening it for a run, resuming, object keys.

Rules (what ``--resume`` and a repeated run may assume):

- One directory holds one set of synthesis settings. A run whose settings differ from the
  manifest's is refused with the differing keys named (``DatasetError``) unless ``overwrite``,
  which deletes the shards the old manifest lists and starts a new manifest: no shard is left
  behind that no manifest lists. The same holds for a hand whose parameters changed.
- With the same settings, a run recomputes the pairs it is given and keeps every other pair;
  with ``resume`` it skips a pair whose shard (or pack, :mod:`ohra.data.pack`) exists, has the
  sha256 the manifest records and was made from the same object (mesh and body hash). A truncated
  or edited shard is recomputed.
- A manifest that is not valid JSON is an error naming the file, never silently replaced.
- A directory without a manifest is built into only if it holds nothing but hidden entries and folders
  named after the run's hands (an interrupted first run's shards): files of anything else would be mixed
  into the dataset and, with ``overwrite``, sit beside shards that get deleted (``DatasetError``).
- Objects are keyed by name; objects sharing a name (``a/mug.stl`` and ``b/mug.stl``) get the
  name plus their mesh hash prefix, so each has its own manifest entry.

The file is plain JSON with one shard entry per line (:func:`manifest_json`): a run rewrites the
manifest after every pair, and re-encoding thousands of unchanged entries with ``indent`` (Python's
pure-Python encoder) cost 0.4 CPU-s per pair at 2,700 pairs, 10 % of the synthesis itself.
:class:`ManifestWriter` encodes each shard entry once; a new pair adds one line to the file.
"""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

from ohra.data.dataset import file_digest, read_manifest
from ohra.io import write_text
from ohra.errors import DatasetError
from ohra.objects.procedural import same_procedural_object

FORMAT = "ohra-grasps/2"


def object_keys(objects) -> list[str]:
    """Unique manifest keys for ``objects`` (in order): the name, or name-<mesh hash> on a clash."""
    counts = Counter(o.name for o in objects)
    keys = [o.name if counts[o.name] == 1 else f"{o.name}-{o.mesh_hash[:8]}" for o in objects]
    dup = [k for k, c in Counter(keys).items() if c > 1]
    if dup:
        raise DatasetError(f"object(s) {', '.join(dup)} given twice with the same mesh; list each object once")
    return keys


def rekey_shards(shards: dict, objects, keys: list[str], descs: list[dict]) -> None:
    """Move a hand's shard entries to the keys :func:`object_keys` gives now, in place: an object keyed by its
    name alone until a same-named object joined the run (``thing`` -> ``thing-2c9679e7``), or back. Without it a
    resumed run listed the same shard under both keys and counted its grasps twice."""
    for obj, key, desc in zip(objects, keys, descs):
        if key in shards:
            continue
        for alias in (obj.name, f"{obj.name}-{desc['mesh_hash'][:8]}"):
            sh = shards.get(alias)
            if alias != key and sh is not None and sh.get("object", {}).get("mesh_hash") == desc["mesh_hash"]:
                shards[key] = shards.pop(alias)
                break


def _flatten(d: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update(_flatten(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = v
    return out


# settings stored under another name than a recipe key or command-line option gives them
SETTING_NAMES = {"grasps_per_object": "grasps_per_object (a recipe's grasps_per_pair, --grasps-per-object)"}


def settings_diff(old: dict, new: dict) -> list[str]:
    """``key: old -> new`` for every setting that differs (nested keys dotted; a setting a recipe names otherwise
    is named both ways)."""
    a, b = _flatten(old), _flatten(new)
    return [f"{SETTING_NAMES.get(k, k)}: {a.get(k, '(absent)')} -> {b.get(k, '(absent)')}"
            for k in sorted(set(a) | set(b)) if a.get(k) != b.get(k)]


def remove_listed_shards(root: Path, manifest: dict) -> int:
    """Delete the shard files ``manifest`` lists under ``root``; returns how many existed."""
    n = 0
    for entry in manifest.get("hands", {}).values():
        for sh in entry.get("shards", {}).values():
            for f in (root / sh.get("file", ""), root / sh.get("pack", {}).get("file", "")):
                if f.is_file() and f.suffix == ".npz":
                    f.unlink()
                    n += 1
    return n


def check_unrelated(root: Path, hand_names) -> None:
    """Refuse ``root`` when it has no manifest and holds files that are not this run's (module rules)."""
    if (root / "manifest.json").exists() or not root.is_dir():
        return
    names = set(hand_names)
    foreign = sorted(p.name + ("/" if p.is_dir() else "") for p in root.iterdir()
                     if not p.name.startswith(".") and not (p.is_dir() and p.name in names))
    if foreign:
        shown = ", ".join(foreign[:4]) + (f" and {len(foreign) - 4} more" if len(foreign) > 4 else "")
        raise DatasetError(f"{root} is not empty and holds no grasp dataset (no manifest.json; found {shown}); "
                           "write the dataset to a new or empty directory")


def open_manifest(root: Path, settings: dict, digest: str, overwrite: bool, header: dict) -> dict:
    """The manifest a run into ``root`` continues (see the module rules); ``header`` adds version
    and format fields to a new one."""
    man_path = root / "manifest.json"
    old = read_manifest(man_path)
    if old is not None and old.get("settings_digest") != digest:
        if not overwrite:
            diff = settings_diff(old.get("settings", {}), settings)
            raise DatasetError(f"{man_path} was written with other settings ({'; '.join(diff[:4]) or 'format changed'}"
                               f"{' ...' if len(diff) > 4 else ''}); write to another directory or pass --overwrite "
                               "to delete its shards and start again")
        remove_listed_shards(root, old)
        old = None
    manifest = {**header, "format": FORMAT, "settings": json.loads(json.dumps(settings, default=str)),
                "settings_digest": digest, "hands": {}}
    if old is not None:
        manifest["hands"] = old.get("hands", {})
        for k in ("split", "recipe", "core_hours"):
            if k in old:
                manifest[k] = old[k]
    return manifest


def hand_entry(root: Path, manifest: dict, name: str, params_dict: dict, phash: str, overwrite: bool) -> dict:
    """The manifest entry of hand ``name``; a changed hand is an error unless ``overwrite``
    (then its old shards are deleted)."""
    entry = manifest["hands"].get(name)
    if entry is not None and entry.get("params_hash") != phash:
        if not overwrite:
            raise DatasetError(f"hand {name!r} in {root / 'manifest.json'} has other parameters (hash {entry.get('params_hash')} "
                               f"vs {phash}); write to another directory or pass --overwrite")
        remove_listed_shards(root, {"hands": {name: entry}})
        entry = None
    if entry is None:
        entry = manifest["hands"][name] = {"params": params_dict, "params_hash": phash, "shards": {}}
    return entry


def shard_complete(root: Path, sh: dict | None, obj_desc: dict) -> bool:
    """Whether a manifest shard entry can be kept on resume: same object (same hashes, or the same
    procedural object made on another CPU), file present, same sha256."""
    if not sh:
        return False
    o = sh.get("object", {})
    same = o.get("mesh_hash") == obj_desc["mesh_hash"] and o.get("body_hash") == obj_desc["body_hash"]
    if not (same or same_procedural_object(o, obj_desc)):
        return False
    if "pack" in sh:
        from ohra.data.pack import pack_complete

        return pack_complete(root, sh["pack"])
    f = root / sh.get("file", "")
    return f.is_file() and bool(sh.get("sha256")) and file_digest(f) == sh["sha256"]


def _block(value, pad: str) -> str:
    """``value`` as indented JSON whose continuation lines start with ``pad`` (small sections)."""
    return json.dumps(value, indent=1, default=str).replace("\n", "\n" + pad)


def _object_table(manifest: dict) -> dict[str, dict]:
    """Object key -> the description the first shard of that key carries (every hand of a dataset
    grasps the same objects: storing each description once makes a 71-hand manifest 5x smaller)."""
    table: dict[str, dict] = {}
    for entry in manifest.get("hands", {}).values():
        for key, sh in entry.get("shards", {}).items():
            if isinstance(sh.get("object"), dict):
                table.setdefault(key, sh["object"])
    return table


def manifest_json(manifest: dict, cache: dict | None = None) -> str:
    """The manifest as JSON text: top-level sections indented, each hand's fields on one line
    each, each shard entry compact on its own line (keys in insertion order).

    Object descriptions are stored once, in a top-level ``objects`` table keyed by object key; a
    shard whose description equals its key's table entry names the key (``"object": "box-3"``),
    any other keeps its own. :func:`ohra.data.dataset.read_manifest` puts them back in place, so
    readers see one description per shard either way.

    ``cache`` maps ``(hand, key)`` to ``(entry, table description, text)``; an entry that is the
    same object as the cached one, under the same table description, is not encoded again (shard
    entries are replaced, never edited, once written)."""
    table = _object_table(manifest)
    out = ["{"]
    items = list(manifest.items())
    if table:
        at = next((i for i, (k, _) in enumerate(items) if k == "hands"), len(items))
        items.insert(at, ("objects", table))
    top = items
    for i, (k, v) in enumerate(top):
        comma = "," if i < len(top) - 1 else ""
        if k == "objects" and v is table:  # one object description per line
            rows = [f"  {json.dumps(key)}: {json.dumps(d, default=str)}" for key, d in v.items()]
            out += [' "objects": {', ",\n".join(rows), " }" + comma]
            continue
        if k != "hands" or not isinstance(v, dict):
            out.append(f" {json.dumps(k)}: {_block(v, ' ')}{comma}")
            continue
        out.append(f' "hands": {{')
        hands = list(v.items())
        for j, (hand, entry) in enumerate(hands):
            out.append(f"  {json.dumps(hand)}: {{")
            fields = list(entry.items())
            for m, (fk, fv) in enumerate(fields):
                fcomma = "," if m < len(fields) - 1 else ""
                if fk != "shards" or not isinstance(fv, dict):
                    out.append(f"   {json.dumps(fk)}: {json.dumps(fv, default=str)}{fcomma}")
                    continue
                out.append('   "shards": {')
                shards = list(fv.items())
                for n, (key, sh) in enumerate(shards):
                    desc = table.get(key)
                    hit = cache.get((hand, key)) if cache is not None else None
                    if hit is not None and hit[0] is sh and hit[1] is desc:
                        text = hit[2]
                    else:
                        obj = sh.get("object")
                        stored = {**sh, "object": key} if desc is not None and (obj is desc or obj == desc) else sh
                        text = f"    {json.dumps(key)}: {json.dumps(stored, default=str)}"
                        if cache is not None:
                            cache[(hand, key)] = (sh, desc, text)
                    out.append(text + ("," if n < len(shards) - 1 else ""))
                out.append("   }" + fcomma)
            out.append("  }" + ("," if j < len(hands) - 1 else ""))
        out.append(" }" + comma)
    out.append("}")
    return "\n".join(out) + "\n"


class ManifestWriter:
    """Writes one directory's manifest atomically, encoding each shard entry only once."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self._cache: dict = {}

    def write(self, manifest: dict) -> None:
        write_text(self.path, manifest_json(manifest, self._cache))
