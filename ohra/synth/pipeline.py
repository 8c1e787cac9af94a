"""Grasp dataset synthesis: NLP multistarts per (hand, object), PyBullet filter, atomic shards.

Dataset layout (``ohra.data.dataset``): ``OUT/<hand>/<object>-<meshhash>.npz`` shards plus
``OUT/manifest.json``. A shard holds, over all solver candidates: ``raw`` (N,31) solutions,
``post`` (N,31) post-simulation grasps, ``sim_success`` (N,), solver status codes, constraint
violation, iterations, Ferrari-Canny ``q1``, solver ``contacts``, ``min_distance`` (finger capsules to
the mesh, negative = penetration), and from the simulator the initial ``penetration``, links in
contact after the squeeze (``sim_contacts``) and the final displacement; and ``grasps`` (M,31) float32 = the
post-simulation grasps that passed the filter (what the reference datasets store).
"""

from __future__ import annotations

import hashlib
import json
import multiprocessing as mp
import os
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Union

import numpy as np

from ohra import __version__
from ohra.data.dataset import atomic_write_json, atomic_write_npz, shard_name
from ohra.errors import OhraError
from ohra.canonical.kinematics import HandModel
from ohra.objects.model import ObjectModel
from ohra.canonical.params import BaseParams, ExtendedParams
from ohra.rotations import grasp_to_pose
from ohra.sim import GraspEvaluator, Protocol
from ohra.sim.hands import SimHand
from ohra.synth.init import initial_poses
from ohra.synth.nlp import GraspNLP, NLPSettings, SUCCESS_STATUSES
from ohra.synth.quality import ferrari_canny

Params = Union[BaseParams, ExtendedParams]
# solver_status codes in the shards; "Self_Collision" marks a converged solution whose fingers
# intersect in the exact (Coal) capsule check, which the NLP's sphere samples can miss
STATUS_CODES = {s: i for i, s in enumerate(SUCCESS_STATUSES + ("Maximum_Iterations_Exceeded", "Infeasible_Problem_Detected",
                                                                 "Restoration_Failed", "Error_In_Step_Computation", "other",
                                                                 "Self_Collision"))}


@dataclass(frozen=True)
class SynthSettings:
    grasps_per_object: int = 8  # solver restarts per object
    seed: int = 0
    filter: bool = True
    nlp: NLPSettings = field(default_factory=NLPSettings)
    protocol: Protocol = field(default_factory=Protocol)

    def digest(self) -> str:
        d = json.dumps(asdict(self), sort_keys=True, default=str)
        return hashlib.sha256(d.encode()).hexdigest()[:12]


def params_hash(params: Params) -> str:
    return hashlib.sha256(params.to_json().encode()).hexdigest()[:16]


def _shard_seed(seed: int, hand: str, obj_hash: str) -> int:
    return int.from_bytes(hashlib.sha256(f"{seed}:{hand}:{obj_hash}".encode()).digest()[:4], "little")


def finger_object_distance(hand: HandModel, obj: ObjectModel, grasps: np.ndarray, per_capsule: int = 9) -> np.ndarray:
    """(N,) smallest signed distance [m] from any finger capsule to the object surface at each grasp
    (negative: penetration), measured against the mesh's dense surface samples, not the solver's grid."""
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
    if params.num_fingers < 2:
        raise OhraError(f"hand {name!r} has {params.num_fingers} finger(s); grasp synthesis needs at least two")


def synthesize_shard(name: str, params: Params, obj: ObjectModel, settings: SynthSettings) -> dict:
    """Solve, filter and return the arrays of one (hand, object) shard (not yet written)."""
    t0 = time.perf_counter()
    hand = HandModel.from_params(params)
    nlp = GraspNLP(hand, obj, settings.nlp)
    rng = np.random.default_rng(_shard_seed(settings.seed, name, obj.mesh_hash))
    starts = initial_poses(hand, obj, settings.grasps_per_object, rng, settings.nlp.couplings)
    raw, status, viol, q1, iters, n_contacts = [], [], [], [], [], []
    t_solve = time.perf_counter()
    for st in starts:
        r = nlp.solve(st["R0"], st["t0"], st["q0"], st["q_pref"])
        if r["success"] and hand.self_collision(r["grasp"][9:]):
            r["status"], r["success"] = "Self_Collision", False
        status.append(STATUS_CODES.get(r["status"], STATUS_CODES["other"]))
        viol.append(r["violation"])
        iters.append(r["iterations"])
        raw.append(r["grasp"])
        q1.append(ferrari_canny(r["contacts"], obj, settings.nlp.mu, settings.nlp.torque_length, normals=r["normals"]) if r["success"] else 0.0)
        n_contacts.append(len(r["contacts"]))
    solve_time = time.perf_counter() - t_solve
    raw_a = np.array(raw).reshape(-1, 31)
    min_dist = finger_object_distance(hand, obj, raw_a)
    solved = np.array([s < len(SUCCESS_STATUSES) for s in status]) & (np.array(viol) <= 1e-3)
    post = np.full_like(raw_a, np.nan)
    sim_ok = np.zeros(len(raw_a), dtype=bool)
    sim_contacts = np.zeros(len(raw_a), dtype=np.int16)
    disp = np.full(len(raw_a), np.nan)
    pen = np.full(len(raw_a), np.nan)
    t_sim = time.perf_counter()
    if settings.filter and solved.any():
        ev = GraspEvaluator(SimHand.from_params(params, name, couplings=settings.nlp.couplings), obj, settings.protocol)
        rep = ev.evaluate(raw_a[solved], mode="filter")
        ev.close()
        idx = np.flatnonzero(solved)
        for k, res in zip(idx, rep.results):
            post[k] = res.post_grasp
            sim_ok[k] = res.success
            disp[k] = res.displacement[-1] if np.isfinite(res.displacement[-1]) else np.inf
            pen[k] = res.initial_penetration
            sim_contacts[k] = res.contacts
    elif not settings.filter:
        post[solved] = raw_a[solved]
        sim_ok[:] = solved
    sim_time = time.perf_counter() - t_sim
    return {
        "grasps": post[sim_ok].astype(np.float32),
        "raw": raw_a.astype(np.float32),
        "post": post.astype(np.float32),
        "solver_success": solved,
        "solver_status": np.array(status, dtype=np.int16),
        "constraint_violation": np.array(viol, dtype=np.float32),
        "iterations": np.array(iters, dtype=np.int32),
        "q1": np.array(q1, dtype=np.float32),
        "sim_success": sim_ok,
        "sim_displacement": disp.astype(np.float32),
        "penetration": pen.astype(np.float32),
        "min_distance": min_dist.astype(np.float32),
        "contacts": np.array(n_contacts, dtype=np.int16),
        "sim_contacts": sim_contacts,
        "_timing": {"total_s": time.perf_counter() - t0, "solve_s": solve_time, "sim_s": sim_time},
    }


def _job(args: tuple) -> tuple[str, dict]:
    name, params, obj, settings, out = args
    # the hot loops are single-threaded (IPOPT/MUMPS as CasADi ships it, PyBullet); the variables
    # keep anything that initialises a thread pool inside the worker at one thread. numpy's BLAS is
    # already initialised before the fork and only sees small arrays here (2 workers scale ~1.9x).
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[var] = "1"
    arrays = synthesize_shard(name, params, obj, settings)
    timing = arrays.pop("_timing")
    path = Path(out) / name / shard_name(obj.name, obj.mesh_hash)
    atomic_write_npz(path, arrays)
    return obj.name, {
        "file": str(path.relative_to(out)), "object": obj.describe(), "n_candidates": int(len(arrays["raw"])),
        "n_solved": int(arrays["solver_success"].sum()), "n_grasps": int(len(arrays["grasps"])),
        "timing": timing, "sha256": hashlib.sha256(path.read_bytes()).hexdigest()[:16],
    }


def synthesize(hands: list[tuple], objects: list[ObjectModel], out: str | Path, settings: SynthSettings,
               workers: int = 1, resume: bool = False, progress: bool = True) -> dict:
    """Synthesise a dataset for every (hand, object) pair into ``out``; returns the manifest.

    ``hands`` holds ``(name, params)`` or ``(name, params, couplings)``; a hand's couplings replace
    ``settings.nlp.couplings`` for its shards (the NLP's equality rows, projected starts, the
    filter's coupled controller) and are recorded in its manifest entry.
    """
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise OhraError(f"output path {out} exists and is not a directory")
    if int(workers) < 1:
        raise OhraError(f"--workers must be >= 1, got {workers}")
    hands = [(h[0], h[1], tuple(h[2]) if len(h) > 2 else settings.nlp.couplings) for h in hands]
    for name, params, _ in hands:
        check_hand_for_synthesis(name, params)
    out.mkdir(parents=True, exist_ok=True)
    man_path = out / "manifest.json"
    manifest = {"format": "ohra-grasps/1", "ohra_version": __version__, "settings": json.loads(json.dumps(asdict(settings), default=str)),
                "settings_digest": settings.digest(), "hands": {}}
    if resume and man_path.is_file():
        old = json.loads(man_path.read_text())
        if old.get("settings_digest") == settings.digest():
            manifest["hands"] = old.get("hands", {})
    elif man_path.is_file() and not resume:
        manifest["hands"] = {}
    for name, params, cs in hands:
        hand_settings = replace(settings, nlp=replace(settings.nlp, couplings=cs))
        entry = manifest["hands"].setdefault(name, {"params": params.to_dict(), "params_hash": params_hash(params), "shards": {}})
        entry["couplings"] = [c.to_dict() for c in cs]
        if entry.get("params_hash") != params_hash(params):
            entry.update({"params": params.to_dict(), "params_hash": params_hash(params), "shards": {}})
        todo = []
        for obj in objects:
            sh = entry["shards"].get(obj.name)
            if resume and sh and sh["object"]["mesh_hash"] == obj.mesh_hash and (out / sh["file"]).is_file():
                continue
            todo.append((name, params, obj, hand_settings, str(out)))
        bar = _bar(len(objects), name, progress)
        bar.update(len(objects) - len(todo))
        t0 = time.perf_counter()
        solves = kept = cands = 0
        results = _run(todo, workers)
        for obj_name, info in results:
            entry["shards"][obj_name] = info
            atomic_write_json(man_path, manifest)
            solves += info["n_candidates"]
            kept += info["n_grasps"]
            cands += info["n_solved"]
            dt = time.perf_counter() - t0
            bar.set_postfix(solves_s=f"{solves / dt:.2f}", accepted_s=f"{kept / dt:.2f}", pass_rate=f"{kept / max(cands, 1):.0%}")
            bar.update(1)
        bar.close()
        entry["counts"] = {
            "candidates": sum(s["n_candidates"] for s in entry["shards"].values()),
            "solved": sum(s["n_solved"] for s in entry["shards"].values()),
            "grasps": sum(s["n_grasps"] for s in entry["shards"].values()),
        }
    atomic_write_json(man_path, manifest)
    return manifest


def _run(todo: list[tuple], workers: int):
    if workers == 1 or len(todo) <= 1:
        for job in todo:
            yield _job(job)
        return
    ctx = mp.get_context("fork")
    with ctx.Pool(min(workers, len(todo))) as pool:
        yield from pool.imap(_job, todo)


class _Quiet:
    def update(self, n):
        pass

    def set_postfix(self, **kw):
        pass

    def close(self):
        pass


def _bar(total: int, name: str, enabled: bool):
    if not enabled:
        return _Quiet()
    from tqdm import tqdm

    return tqdm(total=total, desc=name, unit="object")
