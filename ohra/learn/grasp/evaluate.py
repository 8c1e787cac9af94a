"""Evaluation of a grasp model with the paper's protocol, in PyBullet.

Per (hand, unseen object): ``n`` = 100 grasps, each with its own uniformly random wrist rotation,
sampled from the model and run through the six-direction test (:class:`ohra.sim.GraspEvaluator`).
Reported: success rate, diversity, sampling time per grasp and simulation time. With
``original=True`` the same grasps (same seeds) are replayed on the hand's *original* URDF through
its action map, as ``ohra eval --original`` does, so canonical and original results compare grasp
for grasp. With ``inertials="original"`` the canonical hand's fingers carry the original URDF's
finger masses (:meth:`ohra.sim.SimHand.with_finger_masses`) instead of the template's 1000 kg/m^3
capsules: the geometry stays canonical, only the fingers' mass and inertia change.

Diversity (of the successful grasps, and of all sampled grasps):

* ``approach_spread``: 1 - |mean of the unit vectors from the object origin to the palm| (0: every
  grasp from the same side; ~1: from all around);
* ``palm_normal_spread``: the same for the palm normal (+x of the palm frame) in the object frame;
* ``joint_std_rad``: standard deviation of each movable joint across grasps, averaged [rad];
* ``reference``: the reference code's number, the mean over the 29 dimensions
  ``[t, quaternion xyzw, q]`` of their standard deviations (mixes metres, quaternion components
  and radians; kept for comparison with the paper).

Evaluation objects must be unseen: an object the model was trained on (same name or same mesh)
is refused unless ``allow_seen=True``.
"""

from __future__ import annotations

import json
import time
import warnings
import zlib
from collections import Counter
from dataclasses import asdict, dataclass, field
from functools import lru_cache
from glob import escape as glob_escape
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from ohra.errors import DatasetError, GraspError, HandNotFoundError, ParamsError, require_seed
from ohra.learn.grasp.condition import HandLike, hand_key, resolve_hand
from ohra.learn.grasp.model import GraspModel, ObjectLike, resolve_object
from ohra.learn.grasp.refine import RefineSettings, as_refine_settings


INERTIALS = ("capsule", "original")  # finger masses of the canonical hand: template capsules, or the original URDF's
COLLISIONS = ("own", "canonical")  # collision shapes of the original hand: its URDF's, or the canonical capsules (hybrid)


def _spread(v: np.ndarray) -> float:
    u = v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-12)
    return float(1.0 - np.linalg.norm(u.mean(axis=0)))


def diversity(grasps: np.ndarray, movable: np.ndarray) -> dict[str, float] | None:
    """Spread of (N, 31) grasps (see the module docstring); None for fewer than two grasps."""
    if len(grasps) < 2:
        return None
    from ohra.rotations import matrix_to_quat, rot6d_to_matrix

    q = grasps[:, 9:]
    quat = matrix_to_quat(rot6d_to_matrix(grasps[:, 3:9]))
    ref = np.concatenate([grasps[:, :3], quat, q], axis=1).std(axis=0).mean()
    return {
        "approach_spread": _spread(grasps[:, :3]),
        "palm_normal_spread": _spread(grasps[:, 3:6]),
        "joint_std_rad": float(q[:, movable].std(axis=0).mean()) if movable.any() else 0.0,
        "reference": float(ref),
    }


@dataclass
class PairResult:
    """Outcome on one (hand, object) pair."""

    hand: str
    object: str
    object_hash: str
    original: bool
    seed: int
    success: np.ndarray  # (n,) bool
    grasps: np.ndarray  # (n, 31) sampled grasps
    sample_seconds: float  # model time for the n grasps
    sim_seconds: float
    diversity_success: dict | None
    diversity_all: dict | None
    refine_seconds: float = 0.0  # test-time refinement of the n grasps (0 when off)
    mirrored: bool = False  # sampled as the hand's mirror image on the mirrored object (GraspModel.sample)

    @property
    def success_rate(self) -> float:
        return float(self.success.mean()) if len(self.success) else 0.0

    def __repr__(self) -> str:  # the dataclass default prints the (n, 31) grasps
        return (f"PairResult({self.hand!r}, {self.object!r}, {int(self.success.sum())}/{len(self.success)} succeed"
                f"{', original URDF' if self.original else ''})")

    def to_dict(self) -> dict[str, Any]:
        n = len(self.success)
        return {"hand": self.hand, "object": self.object, "object_hash": self.object_hash, "original": self.original,
                "seed": self.seed, "n": n, "successes": int(self.success.sum()), "success_rate": self.success_rate,
                "sample_ms_per_grasp": 1e3 * self.sample_seconds / max(n, 1),
                "refine_ms_per_grasp": 1e3 * self.refine_seconds / max(n, 1), "sim_seconds": self.sim_seconds,
                "diversity_success": self.diversity_success, "diversity_all": self.diversity_all, "mirrored": self.mirrored}


@dataclass
class GraspEvalReport:
    pairs: list[PairResult]
    meta: dict = field(default_factory=dict)

    def __repr__(self) -> str:  # per hand, not every pair's grasps and the model's metadata
        hands = "; ".join(f"{h} {100 * r['success_rate']:.1f} % of {r['n']}" for h, r in self.per_hand().items())
        return f"GraspEvalReport({len(self.pairs)} pairs: {hands or 'none'})"

    def per_hand(self) -> dict[str, dict[str, float]]:
        """Pooled success rate and mean sampling time per hand."""
        out: dict[str, dict[str, float]] = {}
        for h in dict.fromkeys(p.hand for p in self.pairs):
            ps = [p for p in self.pairs if p.hand == h]
            succ = np.concatenate([p.success for p in ps])
            n = len(succ)
            out[h] = {"n": n, "success_rate": float(succ.mean()) if n else 0.0,
                      "pair_rates": [p.success_rate for p in ps],
                      "sample_ms_per_grasp": 1e3 * sum(p.sample_seconds for p in ps) / max(n, 1),
                      "refine_ms_per_grasp": 1e3 * sum(p.refine_seconds for p in ps) / max(n, 1)}
        return out

    def to_dict(self) -> dict[str, Any]:
        return {**self.meta, "per_hand": self.per_hand(), "pairs": [p.to_dict() for p in self.pairs]}

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=1)


def pair_seed(seed: int, hand: str, object_hash: str) -> int:
    """Seed of one (hand, object) pair: stable across runs, independent of evaluation order."""
    rng = np.random.default_rng([int(seed), zlib.crc32(hand.encode()), zlib.crc32(object_hash.encode())])
    return int(rng.integers(2**62))


def hand_label(hand: HandLike, params: Any) -> str:
    """The name an evaluated hand goes by in :class:`PairResult` (and so :meth:`GraspEvalReport.per_hand`,
    the JSON report and :func:`pair_seed`): a name or path as given (a :class:`~pathlib.Path` as its
    string), params by content, :func:`~ohra.learn.grasp.condition.hand_key` (as ``meta["condition_hand"]``
    names them): different hands never share a label, and a hand's label does not depend on its place in
    the list."""
    if isinstance(hand, (str, Path)):
        return str(hand)
    return hand_key(params)


def seed_label(hand: HandLike, params: Any) -> str:
    """What a hand's pair seeds (:func:`pair_seed`) are drawn from: a registered hand's or LEAP variant's name, and
    for a hand given as a file (spec YAML, params JSON) its content (:func:`hand_key`), so that ``mirror.json``,
    ``./mirror.json`` and its absolute path sample and score alike (the label as typed seeded them apart)."""
    if isinstance(hand, (str, Path)):
        from ohra.hands.leap.variants import is_variant
        from ohra.hands.registry import registered_hands

        text = str(hand)
        if text in registered_hands() or is_variant(text):
            return text
    return hand_key(params)


def check_unseen(model: GraspModel, objects: Sequence[Any]) -> None:
    """Refuse objects the model was trained on: by name, by mesh hash, or, for its procedural training objects
    (``family-seed``, which can be made again), by shape: a copy exported to a mesh file (vertices off by float
    rounding) has another name and hash but is the same object."""
    train = model.meta.get("train_objects", {})
    shapes = None
    for o in objects:
        seen = o.name if o.name in train else next((n for n, h in train.items() if h == o.mesh_hash), None)
        if seen is None:
            if shapes is None:
                shapes = _training_shapes(train)
            sig = _shape_signature(o)
            seen = next((n for n, t in shapes.items() if _same_shape(sig, t)), None)
        if seen is not None:
            alias = f" (as {seen!r})" if seen != o.name else ""
            raise DatasetError(f"object {o.name!r} (mesh {o.mesh_hash}) is in the model's training set{alias}; "
                               "evaluation needs unseen objects (allow_seen=True, or --allow-seen, to override)")


def _training_shapes(train: dict) -> dict[str, np.ndarray]:
    """Shape signatures of the training objects that can be made or found again: those named ``family-seed``
    of a procedural family, built-in objects, and mesh objects found by name under the objects root (``$OHRA_OBJECTS_ROOT``, a
    folder or file ``NAME`` there or one level down, e.g. ``ycb/CrackerBox``) whose mesh hash is the one
    trained on. A training object found nowhere is still refused by name and hash."""
    from ohra.objects.model import ObjectModel, builtin_object_names
    from ohra.objects.procedural import FAMILIES

    out = {}
    for name, mesh_hash in train.items():
        family, _, seed = name.rpartition("-")
        if family in FAMILIES and seed.isdigit():
            out[name] = _shape_signature(ObjectModel.procedural(family, int(seed)))
        elif name in builtin_object_names():  # made again like a procedural one, if it is the one trained on
            obj = ObjectModel.builtin(name)
            if obj.mesh_hash == str(mesh_hash):
                out[name] = _shape_signature(obj)
        else:
            sig = _found_shape(name, str(mesh_hash))
            if sig is not None:
                out[name] = sig
    return out


def _found_shape(name: str, mesh_hash: str) -> np.ndarray | None:
    """Signature of the training mesh object ``name`` under the objects root, if it is there unchanged."""
    from ohra.paths import objects_root

    root = objects_root()
    if not root.is_dir() or not name or "/" in name or name.startswith("."):
        return None
    for path in [root / name, *sorted(root.glob(f"*/{glob_escape(name)}"))]:
        if path.exists():
            sig = _file_shape(str(path.resolve()), path.stat().st_mtime_ns, mesh_hash)
            if sig is not None:
                return sig
    return None


@lru_cache(maxsize=64)
def _file_shape(path: str, mtime_ns: int, mesh_hash: str) -> np.ndarray | None:
    """Signature of the object at ``path`` when its mesh hash is ``mesh_hash`` (else None), once per process."""
    from ohra.objects.model import ObjectModel

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # its mesh and body notes were given when it was trained on
            obj = ObjectModel.load(path)
    except Exception:  # noqa: BLE001 - an unreadable file is not the trained object
        return None
    return _shape_signature(obj) if obj.mesh_hash == mesh_hash else None


def _shape_signature(obj: Any) -> np.ndarray:
    """Sorted bounding-box extents [m] and surface area [m^2]: equal for a mesh and its re-export."""
    m = obj.mesh
    return np.concatenate([np.sort(np.asarray(m.extents, dtype=float)), [float(m.area)]])


SCALED_COPY = (0.9, 1.1)
"""A uniformly scaled copy of a training object whose scale lies in this range is refused as seen: the same shape
re-exported with a rounding or unit slip (x1.001) is not an unseen object."""


def _same_shape(a: np.ndarray, b: np.ndarray) -> bool:
    """Same extents and area (a re-export), or the same proportions at a scale within :data:`SCALED_COPY`."""
    if np.allclose(a, b, rtol=1e-5, atol=1e-7):
        return True
    s = a[2] / b[2] if b[2] > 0 else 0.0  # ratio of the largest extents
    if not SCALED_COPY[0] <= s <= SCALED_COPY[1]:
        return False
    # extents scale with s, the area with s^2
    return bool(np.allclose(a / np.array([s, s, s, s * s]), b, rtol=1e-5, atol=1e-7))


def evaluate_model(model: GraspModel, hands: Sequence[HandLike], objects: Sequence[ObjectLike], n: int = 100,
                   seed: int = 0, original: bool = False, workers: int = 1, protocol: Any = None,
                   progress: bool = False, allow_seen: bool = False, inertials: str = "capsule",
                   condition_hand: HandLike | None = None, refine: bool | RefineSettings = False,
                   collisions: str = "own", centre: bool = False, candidates: int = 1,
                   resume_dir: str | Path | None = None, mirror: bool | str = "auto") -> GraspEvalReport:
    """Sample ``n`` grasps per (hand, object) and run the six-direction test (module docstring).

    Every hand and object is checked before the first simulation.

    Args:
        model: the grasp model.
        hands: hands as :meth:`GraspModel.sample` takes them (or one such hand); with ``original=True`` or
            ``inertials="original"`` a hand with an original URDF: a registered name, a spec YAML, or a params JSON
            beside its spec.
        objects: objects as :func:`~ohra.learn.grasp.model.resolve_object` takes them (or one such object);
            unseen in training.
        n: grasps per pair, >= 1, each with its own uniformly random wrist rotation.
        seed: base seed; each pair's seed is :func:`pair_seed` of it, the hand (:func:`seed_label`: a registered
            hand's or variant's name, else the content hash of its params, however its file is spelled) and the
            mesh hash.
        original: replay the grasps on the hand's original URDF through its action map.
        workers: simulation processes per pair (:meth:`ohra.sim.GraspEvaluator.evaluate`).
        protocol: a :class:`ohra.sim.Protocol` or a preset name (``"reference"``, ``"strict"``,
            ``"isaac-step"``, ``"isaac-drive"``); None for the default.
        progress: show the simulation's progress bar.
        allow_seen: also evaluate objects the model was trained on.
        inertials: ``"capsule"`` (template finger masses) or ``"original"`` (the original URDF's finger
            masses on the canonical hand; ignored with ``original=True``).
        condition_hand: tell the model this hand instead of the true one (paper Table 9: does the
            condition matter?); the grasps keep the true hand's joint limits and run on the true hand.
        refine: test-time finger refinement, as in :meth:`GraspModel.sample`.
        collisions: ``"own"``, or ``"canonical"`` (needs ``original=True``): replay on the *hybrid*
            hand, the original URDF (kinematics, limits, masses, inertias, action map) carrying the
            canonical collision shapes (:mod:`ohra.sim.hybrid`), to tell what the original's link
            shapes do from what the rest of it does.
        centre: sample each object centred on its bounding box (:meth:`GraspModel.sample`); the
            grasps and the simulation stay in the mesh frame.
        candidates: draw this many grasps per wrist rotation and keep the one whose fingers lie nearest
            the object's surface (:meth:`GraspModel.sample`); 1: the first draw.
        mirror: sample a hand as its mirror image on the mirrored object and mirror the grasps back
            (:meth:`GraspModel.sample`): True, False or ``"auto"`` (default: when the mirror image lies nearer the
            model's training hands); decided for every hand before the first simulation and recorded per pair
            (``PairResult.mirrored``, ``meta["mirrored_hands"]``).
        resume_dir: a folder where each finished pair is stored (atomically, keyed by the model's weights, the
            hand, the object and every setting); a pair found there is taken as it is instead of sampled and
            simulated again, so an interrupted evaluation continues where it stopped with the same result.

    Returns:
        :class:`GraspEvalReport`: one :class:`PairResult` per (hand, object), hand-major, labelled by
        :func:`hand_label`, each with the
        sampled grasps (n, 31) (palm frame in the object mesh frame [m]; joints [rad]), their success
        (n,), timings [s] and diversity; ``meta`` holds the settings and the model's metadata.

    Raises:
        GraspError: ``n`` not a positive integer; ``seed`` not a whole number >= 0; ``protocol`` neither a
            Protocol nor a preset name; a hand or object given twice; no hands or no objects; an unknown ``inertials`` or
            ``collisions``; ``collisions="canonical"`` without ``original``; ``original`` or
            ``inertials="original"`` with a hand that has no original URDF (a LEAP variant, bare params, a params
            JSON without its spec); ``workers`` not an
            integer >= 1; ``mirror`` none of True, False, ``"auto"``.
        ObjectError: an object cannot be resolved to one object.
        DatasetError: an object is in the model's training set (by name or mesh hash) and not
            ``allow_seen``.
        HandNotFoundError: an unknown hand name or a missing params file.
        ParamsError: the model cannot be conditioned on a hand (e.g. no base form for a
            ``vae``-conditioned model).
    """
    from ohra.hands.registry import registered_hands
    from ohra.sim import GraspEvaluator, SimHand
    from ohra.canonical.params import ExtendedParams

    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise GraspError(f"n must be a positive integer, got {n!r}")
    seed = require_seed(seed, GraspError)
    protocol = _as_protocol(protocol)
    # one hand or object given by itself (a name is a sequence of letters, not of hands)
    hands = [hands] if isinstance(hands, (str, Path)) or not isinstance(hands, Sequence) else list(hands)
    objects = [objects] if isinstance(objects, (str, Path)) or not isinstance(objects, Sequence) else list(objects)
    if not hands or not objects:
        raise GraspError("evaluation needs at least one hand and one object")
    if isinstance(workers, bool) or not isinstance(workers, (int, np.integer)) or workers < 1:
        raise GraspError(f"workers must be an integer >= 1, got {workers!r}")
    if inertials not in INERTIALS:
        raise GraspError(f"inertials must be one of {INERTIALS}, got {inertials!r}")
    if collisions not in COLLISIONS:
        raise GraspError(f"collisions must be one of {COLLISIONS}, got {collisions!r}")
    if collisions != "own" and not original:
        raise GraspError("collisions='canonical' replays on the original URDF's hybrid: it needs original=True")
    objs = [resolve_object(o) for o in objects]
    hashes = Counter(o.mesh_hash for o in objs)
    twice = sorted({o.name for o in objs if hashes[o.mesh_hash] > 1})
    if twice:  # its grasps would be counted twice in every pooled rate
        raise GraspError(f"object(s) {twice} given more than once")
    if not allow_seen:
        check_unseen(model, objs)
    # every hand is checked before the first simulation: a hand the model cannot condition on (a LEAP
    # variant for a VAE-conditioned model) or without an original URDF fails now, not after minutes of
    # evaluating the hands before it
    resolved, originals = [], {}
    what = "original=True (--original)" if original else "inertials='original' (--inertials original)"
    for hand in hands:
        if (original or inertials == "original") and not isinstance(hand, (str, Path)):
            raise GraspError(f"{what} needs the hand's original URDF: give the hand by name, spec YAML or params JSON "
                             f"beside its spec, not as {type(hand).__name__}")
        params = resolve_hand(hand)
        if original or inertials == "original":
            # a registered name, a spec YAML or a params JSON beside its spec, as ohra eval --original takes them
            registered = isinstance(hand, str) and hand in registered_hands()
            form = None if registered else ("extended" if isinstance(params, ExtendedParams) else "base")
            try:
                originals[hand_label(hand, params)] = SimHand.original_of(str(hand), form, purpose=what)
            except HandNotFoundError as exc:  # a LEAP variant, a params JSON without its spec
                raise GraspError(str(exc)) from None
        told = params if condition_hand is None else resolve_hand(condition_hand)  # the hand the model is told
        try:
            model.condition.vector(told)
        except ParamsError as exc:
            who = hand if condition_hand is None else condition_hand
            raise ParamsError(f"hand {str(who) if isinstance(who, (str, Path)) else type(who).__name__!r}: {exc}") from None
        resolved.append((hand_label(hand, params), params, _couplings(hand), told, model.mirrors(told, mirror),
                         seed_label(hand, params)))
    twice = sorted(name for name, k in Counter(name for name, *_ in resolved).items() if k > 1)
    if twice:
        raise GraspError(f"hand(s) {twice} given more than once")
    by_content: dict[str, list[str]] = {}
    for name, params, *_ in resolved:  # one hand by two spellings (a name and its params JSON) would count twice
        by_content.setdefault(hand_key(params), []).append(name)
    same = [names for names in by_content.values() if len(names) > 1]
    if same:
        raise GraspError(f"hands {same[0]} are the same hand (identical canonical parameters), given more than once")
    for obj in objs:  # before the first simulation (once each: sampling does not repeat them)
        model.object_warnings(obj, centre)
    pairs = []
    resume = Path(resume_dir) if resume_dir is not None else None
    resumed = 0
    settings = _resume_settings(model, n, original, inertials, collisions, protocol, refine, centre, candidates,
                                condition_hand) if resume is not None else None
    for name, params, couplings, told, flip, seeded_by in resolved:
        movable = np.asarray(params.movable_joints)
        hybrid = None
        if original and collisions == "canonical":  # one fit per hand, shared by its objects
            from ohra.sim.hybrid import with_canonical_collisions

            hybrid, _ = with_canonical_collisions(originals[name], SimHand.from_params(params, name=str(name)))
        for obj in objs:
            s = pair_seed(seed, seeded_by, obj.mesh_hash)
            if resume is not None:
                path = resume / f"{_pair_key(settings, str(name), params, obj, s, model.condition.vector(told), flip)}.npz"
                done = _load_pair(path)
                if done is not None:
                    pairs.append(done)
                    resumed += 1
                    continue
            timing: dict = {}
            grasps = model.sample(params, obj, int(n), seed=s, timing=timing, condition_hand=condition_hand, refine=refine,
                                  centre=centre, candidates=candidates, mirror=flip, name=str(name))
            if couplings:  # what the simulation runs (it drives coupled joints by their drivers), stored as such
                from ohra.canonical.couplings import project

                grasps[:, 9:] = project(couplings, grasps[:, 9:])
            if hybrid is not None:
                sim_hand = hybrid
            else:
                # a coupled hand (Inspire) drives its coupled joints with their drivers, as ohra eval and synthesis do
                sim_hand = originals[name] if original else SimHand.from_params(params, name=str(name), couplings=couplings)
            if inertials == "original" and not original:
                sim_hand = sim_hand.with_finger_masses(originals[name].finger_masses)
            t0 = time.perf_counter()
            with GraspEvaluator(sim_hand, obj, protocol) as ev, warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)
                rep = ev.evaluate(grasps, workers=workers, progress=progress)
            ok = rep.success
            pairs.append(PairResult(str(name), obj.name, obj.mesh_hash, bool(original), s, ok, grasps,
                                    timing["seconds"], time.perf_counter() - t0,
                                    diversity(grasps[ok], movable), diversity(grasps, movable), timing.get("refine_seconds", 0.0),
                                    flip))
            if resume is not None:
                _save_pair(path, pairs[-1])
    cond = None if condition_hand is None else (condition_hand if isinstance(condition_hand, str) else hand_key(resolve_hand(condition_hand)))
    ref = None if (rs := as_refine_settings(refine)) is None else asdict(rs)
    meta = {"n_per_pair": int(n), "seed": int(seed), "original": bool(original), "inertials": inertials, "collisions": collisions,
            "condition_hand": cond,
            "refine": ref, "centre": bool(centre), "candidates": int(candidates),
            "mirror": mirror if isinstance(mirror, str) else bool(mirror),
            "mirrored_hands": sorted({p.hand for p in pairs if p.mirrored}),
            "model": str(model.path),
            "model_meta": model.meta, "protocol": protocol.__dict__ if protocol is not None else "default",
            "resumed_pairs": resumed}
    return GraspEvalReport(pairs, meta)


def _resume_settings(model: GraspModel, n: int, original: bool, inertials: str, collisions: str, protocol: Any,
                     refine: Any, centre: bool, candidates: int, condition_hand: Any) -> dict:
    """Everything a pair's outcome depends on besides its hand, object and seed (the resume key)."""
    import hashlib

    from ohra.sim.hands import ORIGINAL_SQUEEZE

    h = hashlib.sha256()
    for k, v in model.net.state_dict().items():  # the weights themselves, not the path they came from
        h.update(k.encode())
        h.update(v.detach().cpu().numpy().tobytes())
    rs = as_refine_settings(refine)
    cond = None if condition_hand is None else hand_key(resolve_hand(condition_hand))
    return {"model": h.hexdigest()[:16], "t_scale": float(model.t_scale), "n": int(n), "original": bool(original), "inertials": inertials, "collisions": collisions,
            "protocol": json.dumps(protocol.__dict__ if protocol is not None else "default", sort_keys=True, default=str),
            "refine": None if rs is None else json.dumps(asdict(rs), sort_keys=True, default=str), "centre": bool(centre),
            "candidates": int(candidates), "condition_hand": cond, "format": 1,
            **({"squeeze": ORIGINAL_SQUEEZE} if original else {})}  # an original pair made before the twin is not reused


def _pair_key(settings: dict, name: str, params: Any, obj: Any, seed: int, condition: np.ndarray,
              mirrored: bool = False) -> str:
    import hashlib

    # "mirrored" only when true: pairs stored before the option keep their keys (they were not mirrored)
    body = json.dumps({**settings, **({"mirrored": True} if mirrored else {}), "hand": name, "params": hand_key(params), "mesh": obj.mesh_hash,
                       # what the model was told of the hand (its VAE latent or normalised parameters)
                       "condition": hashlib.sha256(np.asarray(condition, dtype=np.float64).tobytes()).hexdigest(),
                       "body": getattr(obj, "body_hash", ""), "seed": int(seed)}, sort_keys=True, default=str)
    return hashlib.sha256(body.encode()).hexdigest()[:20]


def _save_pair(path: Path, p: PairResult) -> None:
    from ohra.io import write_npz

    info = {k: getattr(p, k) for k in ("hand", "object", "object_hash", "original", "seed", "sample_seconds",
                                        "sim_seconds", "diversity_success", "diversity_all", "refine_seconds", "mirrored")}
    write_npz(path, {"success": np.asarray(p.success, dtype=bool), "grasps": np.asarray(p.grasps),
                     "info": np.array(json.dumps(info, default=float))})


def _load_pair(path: Path) -> PairResult | None:
    """A pair stored by :func:`_save_pair`, or None when absent or unreadable (it is then evaluated again)."""
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as d:
            info = json.loads(str(d["info"]))
            return PairResult(info["hand"], info["object"], info["object_hash"], bool(info["original"]), int(info["seed"]),
                              np.asarray(d["success"], dtype=bool), np.asarray(d["grasps"]), float(info["sample_seconds"]),
                              float(info["sim_seconds"]), info["diversity_success"], info["diversity_all"],
                              float(info.get("refine_seconds", 0.0)), bool(info.get("mirrored", False)))
    except Exception:  # a damaged or foreign file: evaluate the pair again
        return None


def _as_protocol(protocol: Any):
    """A :class:`~ohra.sim.Protocol`, a preset name (``"reference"``, ``"strict"``, ...) or None (the default)."""
    from ohra.sim import Protocol

    if protocol is None or isinstance(protocol, Protocol):
        return protocol
    if isinstance(protocol, str):
        try:
            return Protocol.preset(protocol)
        except ValueError as exc:
            raise GraspError(str(exc)) from None
    raise GraspError(f"protocol must be an ohra.sim.Protocol, a preset name or None, got {type(protocol).__name__}")


def _couplings(hand: Any) -> tuple:
    """The couplings of a hand given by name or file (registered, spec or params JSON); none for params."""
    if not isinstance(hand, (str, Path)):
        return ()
    from ohra.hands import get_couplings

    return get_couplings(hand)


__all__ = ["COLLISIONS", "evaluate_model", "GraspEvalReport", "PairResult", "diversity", "hand_label", "pair_seed", "seed_label",
           "check_unseen"]
