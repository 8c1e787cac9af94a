"""Grasp datasets as training tensors: object split, object clouds, robot-balanced batches.

:class:`TrainingData` reads one or more dataset directories (:class:`ohra.data.GraspDataset`),
drops the held-out test objects (by name *and* mesh hash, so a renamed copy of a test object is
held out too; the split is checked disjoint), resolves every training object to an
:class:`~ohra.objects.model.ObjectModel` (built-ins by name, meshes by the manifest's ``source``,
or from a mapping the caller gives) and pre-samples a pool of surface points per object.

:func:`make_batch` draws step ``s`` of a run from ``numpy.random.default_rng([seed, s])`` alone:
robot-balanced (each row picks a hand uniformly, then one of that hand's grasps uniformly, as the
reference did), every distinct object of the batch encoded ``rotated_copies`` times under
uniformly random rotations that are applied to its cloud and to the grasps assigned to it.
"""

from __future__ import annotations

import functools
import hashlib
import json
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
import torch

from ohra.canonical.params import BaseParams, ExtendedParams, load_params
from ohra.data import GraspDataset, read_manifest
from ohra.errors import DatasetError, ObjectError, ObjectWarning, OhraError, user_stacklevel
from ohra.learn.grasp.config import GraspTrainConfig
from ohra.objects.model import ObjectModel
from ohra.objects.procedural import same_procedural_object

SURFACE_SEED = 0


def object_key(name: str, mesh_hash: str) -> str:
    return f"{name}-{mesh_hash[:8]}"


@functools.lru_cache(maxsize=16)
def _parsed_manifest(path: str, mtime_ns: int, size: int) -> dict:
    return read_manifest(path) or {}


def _read_manifest(root: Path) -> dict:
    """A dataset's manifest, parsed once per file version: the manifests of the zero-shot data run to
    several MB and a training set asks for the params of each of its ~70 hands."""
    path = root / "manifest.json"
    st = path.stat()
    return _parsed_manifest(str(path), st.st_mtime_ns, st.st_size)


def _manifest_params(root: Path, hand: str) -> BaseParams | ExtendedParams:
    """The hand's params as stored in the dataset manifest (registered hands as a fallback)."""
    try:
        d = _read_manifest(root)["hands"][hand].get("params")
    except (OSError, KeyError, json.JSONDecodeError):
        d = None
    if d:
        try:
            return load_params(d)
        except OhraError as exc:
            raise DatasetError(f"{root / 'manifest.json'}: params of hand {hand!r} are invalid ({exc})") from None
    from ohra.hands import get_hand

    return get_hand(hand)


def _procedural_name(name: str) -> tuple[str, str] | None:
    """(family, seed) of a procedural object's default name ``family-seed``, else None."""
    from ohra.objects.procedural import FAMILIES

    family, _, seed = name.rpartition("-")
    return (family, seed) if family in FAMILIES and seed.isdigit() else None


def _locate(root: Path, src: str) -> Path:
    """The object file a manifest names: as written, relative to the dataset, or, for a dataset made
    on another machine, the same trailing path under this machine's object root (``OHRA_OBJECTS_ROOT``;
    the caller checks the mesh hash, so a wrong match cannot pass)."""
    from ohra.paths import objects_root

    p = Path(src)
    if p.exists():
        return p
    if (root / src).exists():
        return root / src
    parts = p.parts[1:] if p.is_absolute() else p.parts
    for i in range(len(parts)):
        cand = objects_root().joinpath(*parts[i:])
        if cand.exists():
            return cand
    return p


def _procedural_entry(name: str, info: Mapping) -> Mapping:
    """``info`` with a legacy ``builtin`` source of a procedural shape named ``procedural:FAMILY:SEED``."""
    legacy = _procedural_name(name) if info.get("source") == "builtin" else None
    return dict(info, source=f"procedural:{legacy[0]}:{legacy[1]}") if legacy else info


def load_dataset_object(root: Path, name: str, info: dict, given: Mapping[str, ObjectModel]) -> ObjectModel:
    """The object ``name`` of the grasp dataset in ``root``, as its manifest entry ``info`` describes it.

    ``given[name]`` is used when present; otherwise the model is rebuilt from ``info["source"]``
    (``procedural:FAMILY:SEED``, ``builtin``, or a mesh/URDF path, relative paths looked up beside
    the dataset and under :func:`ohra.paths.objects_root`). Raises :class:`DatasetError` naming
    ``root`` and the object when it cannot be loaded, or when its mesh hash differs from
    ``info["mesh_hash"]`` (the object the grasps were made for has changed; for a procedural object
    the recorded geometry decides, see :func:`~ohra.objects.procedural.same_procedural_object`).
    """
    want = str(info.get("mesh_hash", ""))
    if name in given:
        obj = given[name]
    else:
        src = str(info.get("source", ""))
        try:
            procedural = _procedural_name(name) if src == "builtin" else None  # datasets before sources named them
            if src.startswith("procedural:") or procedural:
                family, seed = src.split(":")[1:3] if src.startswith("procedural:") else procedural
                obj = ObjectModel.procedural(family, int(seed))
            elif src == "builtin":
                obj = ObjectModel.builtin(name)
            elif src:
                obj = ObjectModel.load(_locate(root, src), name=name, scale=info.get("scale"),
                                       body=str(info.get("body_choice", "auto")))
            else:
                raise ObjectError("the manifest gives no source")
        except OhraError as exc:
            raise DatasetError(f"{root}: cannot load training object {name!r} ({exc}); pass it in `objects`") from None
    if want and obj.mesh_hash != want and not same_procedural_object(_procedural_entry(name, info), {
            "source": obj._source_spec(), "faces": len(obj.mesh.faces), "extents_m": obj.extents, "volume_m3": obj.volume}):
        raise DatasetError(f"{root}: object {name!r} has mesh hash {obj.mesh_hash}, the dataset was made with {want}")
    return obj


def params_key(params: BaseParams | ExtendedParams) -> str:
    """Content hash of a hand's canonical parameters (values rounded to 1e-9: float noise is not a new hand)."""
    v = np.round(np.asarray(params.to_vector(), dtype=float), 9) + 0.0  # + 0.0: no -0.0
    return hashlib.sha256(type(params).__name__.encode() + v.tobytes()).hexdigest()[:16]


def recorded_test_objects(roots: Sequence[Path]) -> set[str]:
    """Object keys a dataset's recipe split off for testing (``manifest.json`` ``split.test``): training holds
    them out like ``GraspTrainConfig.test_objects``."""
    out: set[str] = set()
    for r in roots:
        try:
            split = json.loads((Path(r) / "manifest.json").read_text()).get("split") or {}
        except (OSError, ValueError):
            continue  # GraspDataset reports an unreadable manifest
        if isinstance(split, dict) and isinstance(split.get("test"), list):
            out |= {str(k) for k in split["test"]}
    return out


def _test_hand_keys(roots: Sequence[Path], names: Sequence[str]) -> dict[str, str]:
    """Test hand name -> params key: from a dataset manifest that holds it, else the registry."""
    from ohra.hands import get_hand

    keys = {}
    for n in names:
        for root in roots:
            try:
                if n in _read_manifest(root).get("hands", {}):
                    keys[n] = params_key(_manifest_params(root, n))
                    break
            except (OSError, json.JSONDecodeError):
                continue
        else:
            try:
                keys[n] = params_key(get_hand(n))
            except OhraError as exc:
                raise DatasetError(f"test hand {n!r}: not in the data and not a known hand ({exc})") from None
    return keys


def check_disjoint(train: Mapping[str, str], test: Mapping[str, str]) -> None:
    """Raise :class:`DatasetError` if a training object (name -> mesh hash) is also a test object
    by name or by mesh hash."""
    names = sorted(set(train) & set(test))
    hashes = sorted(set(train.values()) & {h for h in test.values() if h})
    if names or hashes:
        raise DatasetError(f"train and test objects overlap: names {names}, mesh hashes {hashes}")


@dataclass
class TrainingData:
    """Training grasps as arrays, with their hands and objects (rows aligned)."""

    t: np.ndarray  # (G, 3) palm position in the object frame [m]
    rot6d: np.ndarray  # (G, 6)
    q: np.ndarray  # (G, 22) [rad]
    hand_idx: np.ndarray  # (G,) into hands
    obj_idx: np.ndarray  # (G,) into objects
    hands: list[str]
    params: list[BaseParams | ExtendedParams]
    objects: list[ObjectModel]
    surface: list[np.ndarray]  # per object (P, 3) float32 surface points [m]
    test_objects: dict[str, str]  # name -> mesh hash ('' when the test object is not in the data)
    test_grasps: dict[tuple[str, str], np.ndarray]  # (hand, object) -> (M, 31) held-out grasps
    test_models: dict[str, ObjectModel]  # held-out objects that could be loaded (for held-out losses)
    test_hands: dict[str, str] = field(default_factory=dict)  # held-out hand name -> params key

    @classmethod
    def load(cls, paths: str | Path | Sequence[str | Path], cfg: GraspTrainConfig,
             objects: Mapping[str, ObjectModel] | None = None) -> "TrainingData":
        roots = [Path(paths)] if isinstance(paths, (str, Path)) else [Path(p) for p in paths]
        if not roots:
            raise DatasetError("no dataset directory given")
        ds = GraspDataset(roots, hands=list(cfg.hands) or None)
        if not ds.entries:
            raise DatasetError(f"{', '.join(map(str, roots))}: no grasps for hands {list(cfg.hands) or 'any'}")
        known = {h for _, h, _, _ in ds.entries}
        missing = [h for h in cfg.hands if h not in known]
        if missing:
            raise DatasetError(f"hand(s) {missing} have no grasps in {', '.join(map(str, roots))}")
        recorded = recorded_test_objects(roots)  # a recipe's split: never trained on, whatever cfg says
        test_names = set(cfg.test_objects) | recorded
        test = {n: "" for n in test_names}
        for _, _, o, sh in ds.entries:
            if o in test_names:
                test[o] = str(sh.get("object", {}).get("mesh_hash", ""))
        test_hashes = {h for h in test.values() if h}
        absent = sorted(n for n in cfg.test_objects if not test[n])
        if absent:  # an evaluation object absent by design, or a typo that would let the object meant be trained on
            warnings.warn(f"test object(s) {', '.join(absent)} are in none of the datasets (nothing to hold out by that "
                          "name; check the spelling if they should be)", ObjectWarning, stacklevel=user_stacklevel())
        test_hand_keys = _test_hand_keys(roots, cfg.test_hands)
        if set(cfg.test_hands) & set(cfg.hands):
            raise DatasetError(f"hand(s) {sorted(set(cfg.test_hands) & set(cfg.hands))} are both training and test hands")
        cap = cfg.max_per_pair or None
        hand_keys: dict[str, str] = {}
        hands: list[str] = []
        params: list = []
        obj_keys: list[str] = []
        objs: list[ObjectModel] = []
        rows, h_idx, o_idx, held, held_src = [], [], [], {}, {}
        for (root, h, o, sh), (_, _, shard) in zip(ds.entries, ds):  # iteration follows the entries
            g = np.asarray(shard, dtype=np.float64)[:cap]
            mesh_hash = str(sh.get("object", {}).get("mesh_hash", ""))
            if o in test_names or mesh_hash in test_hashes:
                held[(h, o)] = g
                held_src[o] = (root, sh.get("object", {}))
                continue
            if len(g) == 0:
                continue
            if h not in hand_keys:
                hand_keys[h] = params_key(_manifest_params(root, h))
            if h in test_hand_keys or hand_keys[h] in test_hand_keys.values():
                continue  # a test hand, under its own or another name
            if h not in hands:
                hands.append(h)
                params.append(_manifest_params(root, h))
            key = object_key(o, mesh_hash)
            if key not in obj_keys:
                obj_keys.append(key)
                objs.append(load_dataset_object(root, o, sh.get("object", {}), objects or {}))
            rows.append(g)
            h_idx.append(np.full(len(g), hands.index(h)))
            o_idx.append(np.full(len(g), obj_keys.index(key)))
        if not rows:
            held_out = [f"test objects {sorted(test_names)}"] * bool(test_names) + [f"test hands {list(cfg.test_hands)}"] * bool(cfg.test_hands)
            raise DatasetError(f"no training grasps left after holding out the {' and the '.join(held_out) or 'empty shards'}")
        check_disjoint({o.name: o.mesh_hash for o in objs}, test)
        leaked = sorted(h for h in hands if h in test_hand_keys or hand_keys[h] in test_hand_keys.values())
        if leaked:  # unreachable by construction; the check states the guarantee
            raise DatasetError(f"test hand(s) {leaked} are in the training data")
        g = np.concatenate(rows)
        surface = [np.asarray(o.sample_surface(cfg.surface_pool, seed=SURFACE_SEED)[0], dtype=np.float32) for o in objs]
        test_models = {}
        for o, (root, info) in held_src.items():
            try:
                test_models[o] = load_dataset_object(root, o, info, objects or {})
            except DatasetError:
                pass  # only the held-out losses need it
        return cls(g[:, :3], g[:, 3:9], g[:, 9:], np.concatenate(h_idx), np.concatenate(o_idx), hands, params,
                   objs, surface, test, held, test_models, test_hand_keys)

    def __len__(self) -> int:
        return len(self.t)

    def digest(self) -> str:
        """Content hash of the training arrays and object clouds (a resumed run must see the same data)."""
        h = hashlib.sha256()
        for a in (self.t, self.rot6d, self.q, self.hand_idx, self.obj_idx, *self.surface):
            h.update(np.ascontiguousarray(a).tobytes())
        h.update(json.dumps(self.hands).encode())
        return h.hexdigest()[:16]

    def translation_scale(self) -> float:
        """RMS palm-position coordinate [m]: translations are divided by it before diffusion."""
        return float(np.sqrt(np.mean(self.t**2)))

    def summary(self) -> dict:
        counts = {h: int((self.hand_idx == i).sum()) for i, h in enumerate(self.hands)}
        return {"grasps": len(self), "per_hand": counts, "train_objects": {o.name: o.mesh_hash for o in self.objects},
                "test_objects": dict(self.test_objects), "test_hands": dict(self.test_hands),
                "test_grasps": {f"{h}/{o}": int(len(g)) for (h, o), g in self.test_grasps.items()}}


@dataclass
class Batch:
    clouds: torch.Tensor  # (K, N, 3) object clouds (rotated copies)
    cloud_idx: torch.Tensor  # (B,) row -> cloud
    hand: torch.Tensor  # (B, H) hand conditions
    rot6d: torch.Tensor  # (B, 6)
    t_norm: torch.Tensor  # (B, 3) normalised translation
    q: torch.Tensor  # (B, 22)
    present: torch.Tensor  # (B, 22) bool
    generator: torch.Generator  # noise of the diffusion loss (then of the penetration term's palm shift)
    # the rows as stored, before the batch's rotation (the penetration term looks the object up in its own frame)
    hand_idx: torch.Tensor | None = None  # (B,) into TrainingData.hands
    obj_idx: torch.Tensor | None = None  # (B,) into TrainingData.objects
    t_obj: torch.Tensor | None = None  # (B, 3) [m] palm position in the object mesh frame
    R_obj_palm: torch.Tensor | None = None  # (B, 3, 3) palm rotation in the object mesh frame
    R_cloud: torch.Tensor | None = None  # (B, 3, 3) the rotation applied to the row's cloud and grasp

    def to(self, device: torch.device | str) -> "Batch":
        """The batch with its tensors on ``device`` (the generator stays on the CPU)."""
        if torch.device(device).type == "cpu":
            return self
        move = {f: (v.to(device) if isinstance(v, torch.Tensor) else v) for f, v in vars(self).items()}
        return Batch(**move)


def _rows(data: TrainingData, cfg: GraspTrainConfig, rng: np.random.Generator) -> np.ndarray:
    """Robot-balanced row indices of one batch (optionally from a random pool of objects)."""
    n_obj = len(data.objects)
    pool_mask = np.ones(len(data), bool)
    if 0 < cfg.objects_per_step < n_obj:
        pool = rng.choice(n_obj, cfg.objects_per_step, replace=False)
        pool_mask = np.isin(data.obj_idx, pool)
    cands = [np.flatnonzero(pool_mask & (data.hand_idx == i)) for i in range(len(data.hands))]
    live = [c for c in cands if len(c)]
    which = rng.integers(len(live), size=cfg.batch_size)
    return np.array([live[w][rng.integers(len(live[w]))] for w in which])


def make_batch(data: TrainingData, cfg: GraspTrainConfig, n_points: int, step: int, hand_table: torch.Tensor,
               present_table: torch.Tensor, t_scale: float) -> Batch:
    """Batch of training step ``step`` (see the module docstring); deterministic in (cfg.seed, step)."""
    from ohra.learn.grasp.model import random_rotations

    rng = np.random.default_rng([cfg.seed, step])
    rows = _rows(data, cfg, rng)
    copies = max(cfg.rotated_copies, 1)
    objs = np.unique(data.obj_idx[rows])
    clouds, rots = [], []
    for o in objs:
        pool = data.surface[o]
        for _ in range(copies):
            pts = pool[rng.choice(len(pool), n_points, replace=False)].astype(np.float64)
            if cfg.point_noise > 0:
                pts = pts + rng.normal(0.0, cfg.point_noise, pts.shape)
            R = random_rotations(1, rng)[0] if cfg.rotated_copies > 0 else np.eye(3)
            clouds.append(pts @ R.T)
            rots.append(R)
    copy_of = rng.integers(copies, size=len(rows))
    cloud_idx = np.searchsorted(objs, data.obj_idx[rows]) * copies + copy_of
    R = np.stack(rots)[cloud_idx]  # (B, 3, 3)
    t = np.einsum("bij,bj->bi", R, data.t[rows])
    r6 = data.rot6d[rows]
    r6 = np.concatenate([np.einsum("bij,bj->bi", R, r6[:, :3]), np.einsum("bij,bj->bi", R, r6[:, 3:])], axis=1)
    hi = torch.from_numpy(data.hand_idx[rows])
    gen = torch.Generator().manual_seed(int(rng.integers(2**62)))
    f32 = lambda a: torch.from_numpy(np.asarray(a, dtype=np.float32))  # noqa: E731
    hand = hand_table[hi]
    if cfg.condition_noise > 0:  # drawn last: runs without it keep their batches
        hand = hand + f32(rng.normal(0.0, cfg.condition_noise, tuple(hand.shape)))
    from ohra.rotations import rot6d_to_matrix

    return Batch(f32(np.stack(clouds)), torch.from_numpy(cloud_idx), hand, f32(r6), f32(t / t_scale),
                 f32(data.q[rows]), present_table[hi], gen, hi, torch.from_numpy(data.obj_idx[rows]), f32(data.t[rows]),
                 f32(rot6d_to_matrix(data.rot6d[rows])), f32(R))


__all__ = ["TrainingData", "Batch", "make_batch", "check_disjoint", "object_key", "load_dataset_object"]
