"""A tiny grasp dataset written in the synthesiser's format, and tiny grasp-model settings.

The grasps are random but well formed (palm around the object, valid rotations, joints inside the
limits): enough to exercise data loading, batching, training, checkpoints and sampling in a
second, not to learn grasping.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from ohra.data.dataset import atomic_write_json, atomic_write_npz, shard_name
from ohra.hands import get_hand
from ohra.objects.model import ObjectModel
from ohra.rotations import matrix_to_rot6d
from scipy.spatial.transform import Rotation

HANDS = ("allegro_hand_left", "barrett_hand", "shadow_hand_right")
OBJECTS = ("sphere", "box", "cylinder", "capsule")


def random_grasps(params, obj: ObjectModel, n: int, rng: np.random.Generator) -> np.ndarray:
    """(n, 31) float32 grasps: palm 3 cm outside the bounding sphere, random rotation, joints in limits."""
    d = rng.normal(size=(n, 3))
    t = d / np.linalg.norm(d, axis=1, keepdims=True) * (obj.radius + 0.03)
    R = Rotation.random(n, random_state=int(rng.integers(2**31))).as_matrix()
    lo, up = np.asarray(params.joint_lowers), np.asarray(params.joint_uppers)
    q = lo + rng.random((n, 22)) * (up - lo)
    return np.concatenate([t, matrix_to_rot6d(R), q], axis=1).astype(np.float32)


def write_dataset(root: Path, hands=HANDS, objects=OBJECTS, per_pair=6, seed: int = 0,
                  renamed: dict[str, str] | None = None, counts: dict[str, int] | None = None,
                  procedural: tuple[tuple[str, int], ...] = ()) -> Path:
    """A dataset directory like ``python -m ohra.synth`` writes. ``renamed``: extra shards of an
    object under another name (same mesh); ``counts``: grasps per pair for some hands;
    ``procedural``: (family, seed) shapes added to the objects."""
    rng = np.random.default_rng(seed)
    manifest = {"format": "ohra-grasps/2", "hands": {}}
    items = [(o, o) for o in objects] + list((renamed or {}).items())
    for h in hands:
        params = get_hand(h)
        entry = manifest["hands"].setdefault(h, {"params": params.to_dict(), "shards": {}})
        models = [(name, ObjectModel.builtin(b)) for name, b in items]
        models += [(f"{f}-{k}", ObjectModel.procedural(f, k)) for f, k in procedural]
        for name, obj in models:
            g = random_grasps(params, obj, (counts or {}).get(h, per_pair), rng)
            path = root / h / shard_name(name, obj.mesh_hash)
            atomic_write_npz(path, {"grasps": g, "grasps_post": g})
            info = obj.describe() | {"name": name}
            entry["shards"][name] = {"file": str(path.relative_to(root)), "object": info, "n_grasps": len(g),
                                     "sha256": hashlib.sha256(path.read_bytes()).hexdigest()[:16]}
    atomic_write_json(root / "manifest.json", manifest)
    return root


def tiny_model_config(**kw):
    from ohra.learn.grasp import GraspModelConfig

    base = dict(n_points=64, encoder_channels=(16, 32), object_dim=32, denoiser_hidden=(64, 32), time_embed_dim=16,
                joint_hidden=32, joint_blocks=1)
    return GraspModelConfig(**(base | kw))


def tiny_train_config(**kw):
    from ohra.learn.grasp import GraspTrainConfig

    base = dict(steps=6, batch_size=16, surface_pool=256, checkpoint_every=3, log_every=2, threads=1,
                test_objects=("capsule",))
    return GraspTrainConfig(**(base | kw))
