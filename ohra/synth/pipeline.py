"""Grasp dataset synthesis: NLP multistarts per (hand, object), PyBullet filter with robustness
trials, byte-deterministic shards written by the driver.

Dataset layout (``ohra.data.dataset``, rules in ``ohra.data.manifest``): ``OUT/<hand>/<object>-<meshhash>.npz``
shards plus ``OUT/manifest.json``. A shard holds, over every solver candidate tried: ``raw`` (N,31)
float32, the solutions exactly as simulated (:func:`ohra.synth.robust.as_stored`); ``post`` (N,31)
after the nominal test; ``sim_success`` (N,) nominal verdicts; ``robust_trials`` (N,) perturbed
trials run (they stop at the first failure) and ``robust_success`` (N,) nominal and all trials
passed; solver status codes, constraint violation, iterations, Ferrari-Canny ``q1``, solver
``contacts``, ``min_distance`` (finger capsules to the body, negative = penetration), ``prefiltered``
(converged but too deep inside the body to simulate: ``SynthSettings.max_penetration_m``), and from the
simulator the initial ``penetration``, links in contact after the squeeze (``sim_contacts``) and the
final displacement. ``grasps`` (M,31) float32 = ``raw[robust_success]`` (pre-test) and
``grasps_post`` = ``post[robust_success]``. Without the filter both are the converged solutions.

A pair stops early once ``SynthSettings.cap`` grasps are kept (the starts are in a fixed seeded
order, so the shard is the same prefix whatever else runs).
"""

from __future__ import annotations

import hashlib
import json
import os
import time
from collections import Counter
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from ohra import __version__
from ohra.canonical.kinematics import HandModel
from ohra.canonical.params import BaseParams, ExtendedParams, Params
from ohra.data.backends import check_backend, run_tasks
from ohra.data.dataset import atomic_write_bytes, npz_bytes, shard_name
from ohra.data.manifest import (ManifestWriter, check_unrelated, hand_entry, object_keys, open_manifest, rekey_shards,
                                shard_complete)
from ohra.errors import ObjectError, OhraError, is_finite_real, is_whole, require_seed
from ohra.io import folder_lock
from ohra.synth import MIN_GRASP_FINGERS
from ohra.objects.model import ObjectModel
from ohra.objects.resolve import GRASPABLE_EXTENT_M, size_problem
from ohra.rotations import grasp_to_pose
from ohra.sim import GraspEvaluator, Protocol
from ohra.sim.hands import SimHand
from ohra.synth.init import initial_poses
from ohra.synth.nlp import GraspNLP, NLPSettings, SUCCESS_STATUSES
from ohra.synth.quality import ferrari_canny
from ohra.synth.robust import RobustnessSettings, as_stored, perturb

# solver_status codes in the shards; "Self_Collision" marks a converged solution whose fingers
# intersect in the exact (Coal) capsule check, which the NLP's sphere samples can miss
STATUS_CODES = {s: i for i, s in enumerate(SUCCESS_STATUSES + ("Maximum_Iterations_Exceeded", "Infeasible_Problem_Detected",
                                                                 "Restoration_Failed", "Error_In_Step_Computation", "other",
                                                                 "Self_Collision"))}
STATUS_NAMES = {i: s for s, i in STATUS_CODES.items()}


@dataclass(frozen=True)
class SynthSettings:
    """Everything that decides a shard's content (its digest keys the dataset directory).

    ``grasps_per_object``: solver starts per (hand, object) pair; ``cap``: stop a pair once this
    many grasps are kept (None: try every start); ``object_extent_m``: the graspable range of an
    object's largest extent [m] (outside it, synthesis refuses the object);
    ``max_penetration_m``: a converged candidate whose finger capsules sink deeper than this into
    the body (``min_distance``, exact capsule samples, not the solver's) is not simulated (marked
    ``prefiltered``): on Shadow 59 % of converged candidates did, 62 % of its simulation failures,
    and none of its verified grasps (``benchmarks/bench_levers.py``); None turns it off.
    """

    grasps_per_object: int = 8
    seed: int = 0
    filter: bool = True
    cap: int | None = None
    max_penetration_m: float | None = 0.001
    robustness: RobustnessSettings = field(default_factory=RobustnessSettings)
    object_extent_m: tuple[float, float] = GRASPABLE_EXTENT_M
    nlp: NLPSettings = field(default_factory=NLPSettings)
    protocol: Protocol = field(default_factory=Protocol)

    def __post_init__(self) -> None:
        if not is_whole(self.grasps_per_object) or self.grasps_per_object < 1:
            raise OhraError(f"grasps per object must be a whole number >= 1, got {self.grasps_per_object!r}")
        if self.cap is not None and (not is_whole(self.cap) or self.cap < 1):
            raise OhraError(f"cap must be a whole number >= 1 (or None), got {self.cap!r}")
        m = self.max_penetration_m
        if m is not None and not is_finite_real(m):  # negative: that much clearance demanded
            raise OhraError(f"max_penetration_m must be a finite distance [m] (or None), got {m!r}")
        lo, hi = self.object_extent_m
        if not (np.isfinite(lo) and np.isfinite(hi) and 0 < lo < hi):
            raise OhraError(f"object_extent_m must be (smallest, largest) [m] with 0 < smallest < largest, got {self.object_extent_m!r}")
        require_seed(self.seed, OhraError)  # a recipe's seed is held to the same (ohra data build refused -1, synth ran it)

    def to_dict(self) -> dict:
        d = json.loads(json.dumps(asdict(self), default=str))
        # Synthesis simulates canonical URDFs only, which carry no <dynamics damping>: the setting
        # cannot change a shard, and leaving it out keeps the digests of datasets made before it.
        d["protocol"].pop("urdf_joint_damping", None)
        if d["protocol"].get("object_point") == "frame":  # the behaviour before the setting existed
            d["protocol"].pop("object_point")
        return d

    def digest(self) -> str:
        return hashlib.sha256(json.dumps(self.to_dict(), sort_keys=True).encode()).hexdigest()[:12]


def params_hash(params: Params) -> str:
    return hashlib.sha256(params.to_json().encode()).hexdigest()[:16]


def _shard_seed(seed: int, hand: str, obj_hash: str) -> int:
    return int.from_bytes(hashlib.sha256(f"{seed}:{hand}:{obj_hash}".encode()).digest()[:4], "little")


def finger_object_distance(hand: HandModel, obj: ObjectModel, grasps: np.ndarray, per_capsule: int = 9) -> np.ndarray:
    """(N,) smallest signed distance [m] from any finger capsule to the object's body at each grasp
    (negative: penetration), from the body's exact or densely sampled surface, not the solver's grid."""
    if len(grasps) == 0:
        return np.zeros(0)
    T, q = grasp_to_pose(np.asarray(grasps, dtype=float))
    caps = hand.capsules(q)
    s = np.linspace(0.0, 1.0, per_capsule)[:, None, None]
    pts = caps.p0[:, None] + s * (caps.p1 - caps.p0)[:, None]  # (N, S, K, 3) palm frame
    world = np.einsum("nij,nskj->nski", T[:, :3, :3], pts) + T[:, None, None, :3, 3]
    d = obj.signed_distance(world.reshape(-1, 3)).reshape(world.shape[:3]) - caps.radius
    return d.min(axis=(1, 2))


def check_hand_for_synthesis(name: str, params: Params) -> None:
    # the name is the hand's folder in the dataset: a path ("my/hand.yaml", "/abs/x") would write elsewhere
    if not isinstance(name, str) or name in ("", ".", "..") or "/" in name or "\\" in name:
        raise OhraError(f"hand name {name!r} cannot name a dataset folder: use a plain name without '/' "
                        "(a spec YAML's hand is named by its 'name:' key)")
    if params.num_fingers < MIN_GRASP_FINGERS:
        raise OhraError(f"hand {name!r} has {params.num_fingers} finger(s); grasp synthesis needs at least two")


def hand_span(hand: HandModel, n: int = 512) -> float:
    """Largest distance [m] between two fingertips over ``n`` seeded configurations."""
    tips = hand.fingertips(hand.random_configurations(n, seed=0))  # (n, 5, 3)
    present = np.flatnonzero(np.asarray(hand.params.present_fingers, dtype=bool))
    t = tips[:, present]
    return float(np.linalg.norm(t[:, :, None] - t[:, None, :], axis=-1).max())


def diagnose(hand: HandModel, obj: ObjectModel, status: list[int]) -> str:
    """Why no start converged: the solver statuses and how the object's size compares with the hand's."""
    counts = ", ".join(f"{n} {STATUS_NAMES[s]}" for s, n in Counter(status).most_common())
    ext = np.sort(obj.extents)
    span = hand_span(hand)
    why = ""
    if ext[0] > span:
        why = f"; the object's smallest extent {100 * ext[0]:.1f} cm exceeds the hand's largest fingertip span {100 * span:.1f} cm"
    elif ext[-1] < 0.2 * span:
        why = f"; the object ({100 * ext[-1]:.1f} cm) is small for a hand spanning {100 * span:.1f} cm"
    return f"no start converged ({counts}){why}"


class _Verifier:
    """The nominal six-direction test plus the robustness trials, on one reused evaluator."""

    def __init__(self, name: str, params: Params, obj: ObjectModel, settings: SynthSettings, hand: HandModel, seed: int):
        # the hand's couplings drive the filter's controller too (coupled joints follow their drivers)
        self.ev = GraspEvaluator(SimHand.from_params(params, name, couplings=settings.nlp.couplings), obj, settings.protocol)
        self.rob, self.hand, self.seed = settings.robustness, hand, seed

    def __call__(self, k: int, g: np.ndarray) -> tuple[object, int, bool]:
        """(nominal result, trials run, robust) of candidate ``k``'s stored vector ``g``."""
        res = self.ev.evaluate(g[None], mode="filter").results[0]
        if not res.success:
            return res, 0, False
        rng = np.random.default_rng([self.seed, self.rob.seed, k])  # per candidate: early stops change nothing else
        trials = perturb(g, self.rob, rng, self.hand.lower, self.hand.upper, self.hand.movable_joints)
        for i, gp in enumerate(trials):
            if not self.ev.evaluate(gp[None], mode="filter").results[0].success:
                return res, i + 1, False
        return res, len(trials), True

    def close(self) -> None:
        self.ev.close()


def synthesize_shard(name: str, params: Params, obj: ObjectModel, settings: SynthSettings) -> dict:
    """Solve, verify and return the arrays of one (hand, object) shard (not yet written), plus
    ``_timing`` and, when nothing converged, ``_diagnosis``."""
    t0, cpu0 = time.perf_counter(), time.process_time()
    hand = HandModel.from_params(params)
    nlp = GraspNLP(hand, obj, settings.nlp)
    seed = _shard_seed(settings.seed, name, obj.mesh_hash)
    starts = initial_poses(hand, obj, settings.grasps_per_object, np.random.default_rng(seed), settings.nlp.couplings)
    verify = _Verifier(name, params, obj, settings, hand, seed) if settings.filter else None
    rows: list[dict] = []
    kept = 0
    t_solve = t_sim = 0.0
    for k, st in enumerate(starts):
        t = time.perf_counter()
        r = nlp.solve(st["R0"], st["t0"], st["q0"], st["q_pref"])
        if r["success"] and hand.self_collision(r["grasp"][9:]):
            r["status"], r["success"] = "Self_Collision", False
        code = STATUS_CODES.get(r["status"], STATUS_CODES["other"])
        g = as_stored(r["grasp"], hand.lower, hand.upper)
        solved = code < len(SUCCESS_STATUSES) and r["violation"] <= 1e-3
        row = {"raw": g, "status": code, "viol": r["violation"], "iters": r["iterations"], "solved": solved,
               "contacts": len(r["contacts"]), "q1": ferrari_canny(r["contacts"], obj, settings.nlp.mu, settings.nlp.torque_length,
                                                                  normals=r["normals"]) if r["success"] else 0.0}
        row["min_distance"] = float(finger_object_distance(hand, obj, g[None])[0])
        if solved and settings.max_penetration_m is not None and row["min_distance"] < -settings.max_penetration_m:
            row["prefiltered"] = True  # starts too deep inside the body to be a grasp worth simulating
        t_solve += time.perf_counter() - t
        t = time.perf_counter()
        if solved and verify is not None and not row.get("prefiltered"):
            res, n_trials, robust = verify(k, g)
            row.update(post=res.post_grasp, sim=res.success, trials=n_trials, robust=robust, pen=res.initial_penetration,
                       sim_contacts=res.contacts, disp=res.displacement[-1] if np.isfinite(res.displacement[-1]) else np.inf)
        elif solved and verify is None:
            row.update(post=g, sim=True, robust=True)
        t_sim += time.perf_counter() - t
        rows.append(row)
        kept += bool(row.get("robust"))
        if settings.cap is not None and kept >= settings.cap:
            break
    if verify is not None:
        verify.close()
    arrays = _arrays(rows, hand, obj)
    # cpu_s: this process's CPU time; on a shared machine it is what the task would take on an idle core
    arrays["_timing"] = {"total_s": time.perf_counter() - t0, "cpu_s": time.process_time() - cpu0, "solve_s": t_solve, "sim_s": t_sim}
    if not arrays["solver_success"].any():
        arrays["_diagnosis"] = diagnose(hand, obj, [r["status"] for r in rows])
    return arrays


def _arrays(rows: list[dict], hand: HandModel, obj: ObjectModel) -> dict:
    raw = np.array([r["raw"] for r in rows]).reshape(-1, 31)
    post = np.array([r.get("post", np.full(31, np.nan)) for r in rows]).reshape(-1, 31)
    keep = np.array([bool(r.get("robust")) for r in rows], dtype=bool)
    col = lambda k, d, dt: np.array([r.get(k, d) for r in rows], dtype=dt)  # noqa: E731
    return {
        "grasps": raw[keep].astype(np.float32), "grasps_post": post[keep].astype(np.float32),
        "raw": raw.astype(np.float32), "post": post.astype(np.float32),
        "solver_success": col("solved", False, bool), "solver_status": col("status", 0, np.int16),
        "constraint_violation": col("viol", 0.0, np.float32), "iterations": col("iters", 0, np.int32),
        "q1": col("q1", 0.0, np.float32), "sim_success": col("sim", False, bool),
        "robust_trials": col("trials", 0, np.int8), "robust_success": keep,
        "sim_displacement": col("disp", np.nan, np.float32), "penetration": col("pen", np.nan, np.float32),
        "min_distance": col("min_distance", np.nan, np.float32), "prefiltered": col("prefiltered", False, bool),
        "contacts": col("contacts", 0, np.int16), "sim_contacts": col("sim_contacts", 0, np.int16),
    }


def shard_task(task: tuple) -> dict:
    """One (hand, object) shard: returns its npz bytes and manifest entry (the driver writes it)."""
    name, params, obj, key, settings = task
    # the hot loops are single-threaded (IPOPT/MUMPS as CasADi ships it, PyBullet); the variables
    # keep anything that initialises a thread pool inside the worker at one thread
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[var] = "1"
    arrays = synthesize_shard(name, params, obj, settings)
    timing, diagnosis = arrays.pop("_timing"), arrays.pop("_diagnosis", None)
    data = npz_bytes(arrays)
    info = {
        "file": f"{name}/{shard_name(obj.name, obj.mesh_hash)}", "object": obj.describe(),
        "n_candidates": int(len(arrays["raw"])), "n_solved": int(arrays["solver_success"].sum()),
        "n_sim_passed": int(arrays["sim_success"].sum()), "n_grasps": int(len(arrays["grasps"])),
        # without the filter a prefiltered grasp is kept unsimulated like any other: only a filtered run drops it
        "n_prefiltered": int(arrays["prefiltered"].sum()) if settings.filter else 0, "timing": timing,
        "sha256": hashlib.sha256(data).hexdigest()[:16],
    }
    if diagnosis:
        info["diagnosis"] = diagnosis
    return {"hand": name, "key": key, "bytes": data, "info": info}


def _check_objects(objects: list[ObjectModel], settings: SynthSettings) -> None:
    for o in objects:
        problem = size_problem(o, settings.object_extent_m)
        if problem:
            raise ObjectError(problem)


def _couplings_of(params) -> tuple:
    from ohra.hands import couplings_of

    return couplings_of(params) if isinstance(params, (BaseParams, ExtendedParams)) else ()


def synthesize(hands: list[tuple], objects: list[ObjectModel], out: str | Path, settings: SynthSettings,
               workers: int = 1, resume: bool = False, progress: bool = True, overwrite: bool = False,
               backend: str = "process", address: str | None = None, header: dict | None = None) -> dict:
    """Synthesise every (hand, object) pair into ``out`` and return the manifest.

    Args:
        hands: ``(name, params)`` or ``(name, params, couplings)``; a hand's couplings replace
            ``settings.nlp.couplings`` for its shards (the NLP's equality rows, projected starts, the
            filter's coupled controller) and are recorded in its manifest entry. Without them (and without
            ``settings.nlp.couplings``), params equal to a registered coupled hand's take its couplings
            (:func:`ohra.hands.couplings_of`).
        resume: keep pairs whose shards are complete (see :mod:`ohra.data.manifest`).
        overwrite: replace a dataset made with other settings (its shards are deleted).
        backend: ``"process"`` (a local pool of ``workers`` processes) or ``"ray"`` (``address``:
            a cluster, else a local one with ``workers`` CPUs).
        header: extra top-level manifest fields (recipes: ``recipe``, ``split``).

    Raises:
        OhraError: bad hands, objects outside the graspable size range, a manifest that is
            corrupt or was written with other settings, an ``out`` that holds other files and no manifest.
        FolderInUseError: another process is building into ``out``.
    """
    if not isinstance(settings, SynthSettings):
        raise OhraError(f"settings: expected SynthSettings, got {type(settings).__name__}")
    for i, h in enumerate(hands):
        if not isinstance(h, (tuple, list)) or len(h) not in (2, 3) or not isinstance(h[1], (BaseParams, ExtendedParams)):
            raise OhraError(f"hands[{i}]: expected (name, params) or (name, params, couplings), got {h!r}; e.g. "
                            f"({str(h)!r}, ohra.get_hand({str(h)!r}))" if isinstance(h, str) else
                            f"hands[{i}]: expected (name, params) or (name, params, couplings), got {type(h).__name__}")
    from ohra.objects.resolve import resolve_object

    objects = [resolve_object(o) for o in objects]  # ObjectModels, or specs as the CLI takes them ("builtin:box", a mesh)
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise OhraError(f"output path {out} exists and is not a directory")
    if int(workers) < 1:
        raise OhraError(f"--workers must be >= 1, got {workers}")
    check_backend(backend, address)
    hands = [(h[0], h[1], tuple(h[2]) if len(h) > 2 else (settings.nlp.couplings or _couplings_of(h[1]))) for h in hands]
    for name, params, _ in hands:
        check_hand_for_synthesis(name, params)
    _check_objects(objects, settings)
    keys = object_keys(objects)
    descs = [o.describe() for o in objects]  # settles each body once, before workers start
    with folder_lock(out, "dataset"):  # two builds of one folder would overwrite each other's manifest
        check_unrelated(out, [h[0] for h in hands])
        manifest = open_manifest(out, settings.to_dict(), settings.digest(), overwrite, {"ohra_version": __version__})
        manifest.update(header or {})
        entries, hand_settings = {}, {}
        for name, params, cs in hands:
            hand_settings[name] = replace(settings, nlp=replace(settings.nlp, couplings=cs))
            entries[name] = hand_entry(out, manifest, name, params.to_dict(), params_hash(params), overwrite)
            entries[name]["couplings"] = [c.to_dict() for c in cs]
            rekey_shards(entries[name]["shards"], objects, keys, descs)
        # object-major order: an interrupted build has every hand's shards for the objects it reached,
        # so a partial dataset stays balanced across hands
        tasks = [(name, params, obj, key, hand_settings[name])
                 for obj, key, desc in zip(objects, keys, descs) for name, params, _ in hands
                 if not (resume and shard_complete(out, entries[name]["shards"].get(key), desc))]
        writer = ManifestWriter(out / "manifest.json")
        _run(out, manifest, writer, tasks, len(hands) * len(objects), workers, backend, address, progress)
        _finish(manifest, writer)
        return manifest


def _run(out: Path, manifest: dict, writer: ManifestWriter, tasks: list, total: int, workers: int, backend: str, address: str | None, progress: bool) -> None:
    bar = _bar(total, progress)
    bar.update(total - len(tasks))
    t0, kept = time.perf_counter(), 0
    for res in run_tasks(shard_task, tasks, backend=backend, workers=workers, address=address):
        shards = manifest["hands"][res["hand"]]["shards"]
        old = shards.get(res["key"])
        atomic_write_bytes(out / res["info"]["file"], res["bytes"])
        if old and old.get("file") != res["info"]["file"]:
            (out / old["file"]).unlink(missing_ok=True)  # the object changed: its old shard is not listed any more
        # a recomputed pair of a packed hand leaves its old row in the pack, unlisted, until it is packed again
        shards[res["key"]] = res["info"]
        writer.write(manifest)
        kept += res["info"]["n_grasps"]
        bar.set_postfix(verified_s=f"{kept / (time.perf_counter() - t0):.2f}", kept=kept)
        bar.update(1)
    bar.close()


def _finish(manifest: dict, writer: ManifestWriter) -> None:
    core_s = 0.0
    for entry in manifest["hands"].values():
        sh = entry["shards"].values()
        entry["counts"] = {k: sum(s.get(f"n_{k2}", 0) for s in sh) for k, k2 in
                           (("candidates", "candidates"), ("solved", "solved"), ("prefiltered", "prefiltered"),
                            ("sim_passed", "sim_passed"), ("grasps", "grasps"))}
        core_s += sum(s["timing"]["total_s"] for s in sh)
    manifest["core_hours"] = core_s / 3600.0  # one core per shard task: the sum of shard wall times
    writer.write(manifest)


class _Quiet:
    def update(self, n):
        pass

    def set_postfix(self, **kw):
        pass

    def close(self):
        pass


def _bar(total: int, enabled: bool):
    if not enabled:
        return _Quiet()
    from tqdm import tqdm

    return tqdm(total=total, desc="pairs", unit="pair")
