"""The six-direction perturbation test in PyBullet (port of the OHRA / D(R,O) Isaac Gym filter).

Per grasp ``[t, rot6d, q22]`` (canonical palm pose in the object's mesh frame, canonical joints):
the hand is fixed at that pose, the object (convex pieces, mass = volume x density) is free at the
origin, gravity is off. Every driven joint is reset 10 % of the way toward its opening limit and
driven 10 % past the grasp toward its closing limit (:mod:`ohra.sim.controller`), 1 s. Then a
force of ``0.5 m`` N pulls the object along +x, +y, +z, -x, -y, -z, 1 s each, re-applied every
step. Success: the object's final displacement since the end of the squeeze is at most 2 cm
(filter mode: and it ends within 5 cm of the origin). Constants: :class:`ohra.sim.Protocol`.

Speed: one :class:`~ohra.sim.world.World` per (hand, object) and process, reset per grasp (see
there for why results do not depend on what ran before); absent/locked joints become fixed and
fixed links are merged; optional early exit; ``workers=K`` processes.

Early exit: when the object touches nothing and the free flight of its centre of mass under the
rest of the force schedule never comes within reach of the hand, nothing can touch it again and the
flight is exact; the grasp is stopped as a failure only if that flight ends more than
``early_exit_margin`` beyond the success threshold. So early exit never changes an outcome (the
benchmark and the tests compare with it off).
"""

from __future__ import annotations

import json
import multiprocessing as mp
import os
import warnings
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np
import pybullet as pb

from ohra.errors import GraspError, ObjectWarning, OhraError, user_stacklevel
from ohra.objects.model import DEFAULT_DENSITY, ObjectModel
from ohra.objects.resolve import resolve_object
from ohra.canonical.params import BaseParams, ExtendedParams, Params
from ohra.rotations import check_grasps, grasp_to_pose, pose_to_grasp
from ohra.sim.controller import squeeze_targets
from ohra.sim.hands import SimHand
from ohra.sim.protocol import COM_OFFSET_WARN, DIRECTION_NAMES, DIRECTIONS, Protocol
from ohra.sim.world import World

PHASES = ("squeeze",) + DIRECTION_NAMES
# rad: a joint this close to its limit is not "outside" it. Stored grasps are float32, whose
# spacing near pi is 2.4e-7 rad; a locked joint (lower == upper, e.g. Allegro's finger twist held at
# 0.0873) has no float32 value inside its limits at all, so a 1e-9 test flagged every stored grasp.
LIMIT_TOL = 1e-6


@dataclass
class GraspResult:
    """Outcome of one grasp (metres, radians)."""

    success: bool
    displacement: np.ndarray  # (7,): squeeze (from the start), then after each direction (from the end of the squeeze); NaN after an early exit
    # [m] how far the object's point (Protocol.object_point) lies at the end from where it started: the mesh-frame
    # origin from the world origin ("frame"), the centre of mass from its start ("com")
    final_distance_from_origin: float
    contacts: int  # hand links touching the object at the end of the squeeze
    initial_penetration: float  # deepest hand-object overlap at the input grasp (>= 0)
    post_grasp: np.ndarray  # (31,) canonical palm pose relative to the settled object + settled canonical joints
    clamped: bool  # joints were outside the limits and were clamped
    early_exit: bool
    steps: int

    def to_dict(self) -> dict:
        return {
            "success": bool(self.success),
            "displacement_m": {k: (None if not np.isfinite(v) else float(v)) for k, v in zip(PHASES, self.displacement)},
            "final_distance_from_origin_m": float(self.final_distance_from_origin),
            "contacts": int(self.contacts), "initial_penetration_m": float(self.initial_penetration),
            "clamped": bool(self.clamped), "early_exit": bool(self.early_exit), "steps": int(self.steps),
            "post_grasp": [float(x) for x in self.post_grasp],
        }


@dataclass
class EvalReport:
    """Results of a batch, in input order."""

    results: list[GraspResult]
    mode: str
    protocol: Protocol
    meta: dict = field(default_factory=dict)

    def __repr__(self) -> str:  # the dataclass default prints every grasp's arrays
        return (f"EvalReport(mode={self.mode!r}, {len(self.results)} grasps, success {100 * self.success_rate:.1f} %, "
                f"{self.clamped_count} clamped)")

    @property
    def success(self) -> np.ndarray:
        return np.array([r.success for r in self.results], dtype=bool)

    @property
    def success_rate(self) -> float:
        """Fraction of grasps that passed; NaN for a report of no grasps (0/0 is not a 0 % success rate,
        which averages over reports would silently count)."""
        return float(self.success.mean()) if self.results else float("nan")

    @property
    def post_grasps(self) -> np.ndarray:
        return np.array([r.post_grasp for r in self.results]).reshape(-1, 31)

    @property
    def clamped_count(self) -> int:
        return int(sum(r.clamped for r in self.results))

    @property
    def penetration(self) -> np.ndarray:
        return np.array([r.initial_penetration for r in self.results])

    @property
    def final_displacement(self) -> np.ndarray:
        """(N,) [m] each grasp's displacement after the last direction (since the end of the squeeze); NaN for a grasp
        whose test exited early (``GraspResult.early_exit``)."""
        return np.array([r.displacement[-1] for r in self.results])

    def to_dict(self) -> dict:
        return {
            **self.meta,
            "mode": self.mode, "protocol": asdict(self.protocol), "n": len(self.results),
            "successes": int(self.success.sum()),
            "success_rate": self.success_rate if self.results else None,  # JSON has no NaN: null for no grasps
            "clamped_joints_grasps": self.clamped_count,
            "early_exits": int(sum(r.early_exit for r in self.results)),
            "grasps": [r.to_dict() for r in self.results],
        }

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=1)


# -- one grasp ---------------------------------------------------------------------------------------
def run_grasp(world: World, grasp: np.ndarray, mode: str = "eval") -> GraspResult:
    """Run the protocol on one validated grasp in ``world`` (reset first, so order never matters)."""
    prot, c, hand = world.protocol, world.client, world.hand
    T_palm, q = grasp_to_pose(grasp)
    qc = np.clip(q, hand.canon_lower, hand.canon_upper)
    clamped = bool(np.any(np.abs(qc - q) > LIMIT_TOL))
    qs = hand.project_sim(np.clip(hand.to_sim(qc), hand.lower, hand.upper))  # a coupled hand takes only coupled poses
    T_root = T_palm @ hand.T_palm_root
    pb.setGravity(0, 0, 0, physicsClientId=c)
    world.reset_hand(T_root, qs)
    obj = world.new_object()
    pen = 0.0
    for cp in pb.getClosestPoints(world.body, obj, 0.0, physicsClientId=c):
        pen = max(pen, -float(cp[8]))
    toward = world.obj_inertial[:3, 3] if prot.object_point == "com" else None  # the object starts at the origin
    q_reset, q_target = squeeze_targets(qs, hand.lower, hand.upper, world.closes_positive(T_palm, qc, toward), prot.outer, prot.inner,
                                       couple=hand.project_sim if hand.coupled else None)
    world.set_joints(q_reset)
    world.drive_joints(q_target)

    point = _displacement_point(world)
    start = point()
    steps = 0
    for _ in range(prot.squeeze_steps):
        pb.stepSimulation(physicsClientId=c)
        steps += 1
    p0 = point()
    contacts = len({cp[3] for cp in pb.getContactPoints(world.body, obj, physicsClientId=c)})
    disp = np.full(7, np.nan)
    disp[0] = float(np.linalg.norm(p0 - start))
    force = prot.force_per_mass * world.mass
    if prot.gravity_in_evaluation:
        pb.setGravity(0, 0, -prot.gravity_in_evaluation, physicsClientId=c)
    n_dir, every = prot.direction_steps, prot.early_exit_every
    early = False
    for d, direction in enumerate(DIRECTIONS):
        f = (force * direction).tolist()
        for s in range(n_dir):
            com, _ = world.object_com()
            pb.applyExternalForce(obj, -1, f, com.tolist(), pb.WORLD_FRAME, physicsClientId=c)
            pb.stepSimulation(physicsClientId=c)
            steps += 1
            if prot.early_exit and (s + 1) % every == 0 and _failure_is_certain(world, T_root, p0, d, s + 1):
                early = True
                break
        disp[d + 1] = float(np.linalg.norm(point() - p0))
        if early:
            break
    pb.setGravity(0, 0, 0, physicsClientId=c)
    T_obj = world.object_frame()
    p_last = point()
    p_end = p_last - (world.obj_inertial[:3, 3] if prot.object_point == "com" else 0.0)  # from where it began
    final = float(np.linalg.norm(p_last - p0))
    success = (not early) and final <= prot.success_displacement
    if mode == "filter":
        success = success and float(np.linalg.norm(p_end)) <= prot.filter_max_distance
    q_end = hand.to_canonical(hand.project_sim(world.joint_values()))  # a coupled hand's settled pose, on its couplings
    post = pose_to_grasp(np.linalg.inv(T_obj) @ T_root @ np.linalg.inv(hand.T_palm_root), q_end)
    return GraspResult(bool(success), disp, float(np.linalg.norm(p_end)), contacts, pen, post, clamped, early, steps)


def _displacement_point(world: World):
    """() -> (3,) world position of the point whose displacement the protocol measures (its
    ``object_point``: the mesh frame's origin or the centre of mass)."""
    if world.protocol.object_point == "com":
        return lambda: world.object_com()[0]
    return lambda: world.object_frame()[:3, 3]


def _failure_is_certain(world: World, T_root: np.ndarray, p0: np.ndarray, d: int, s_done: int) -> bool:
    """Exact free-flight prediction (see module doc): True only if the object can never be caught."""
    prot, c = world.protocol, world.client
    if pb.getContactPoints(world.body, world.obj_body, physicsClientId=c):
        return False
    com, v = world.object_com()
    n_dir = prot.direction_steps
    acc = np.concatenate([np.repeat(DIRECTIONS[d:d + 1], n_dir - s_done, axis=0)]
                         + [np.repeat(DIRECTIONS[k:k + 1], n_dir, axis=0) for k in range(d + 1, 6)]) * prot.force_per_mass
    acc[:, 2] -= prot.gravity_in_evaluation
    # semi-implicit Euler on the substep grid, as Bullet integrates
    h = prot.dt / prot.substeps
    acc = np.repeat(acc, prot.substeps, axis=0)
    vel = v + np.cumsum(acc * h, axis=0)
    path = np.vstack([com, com + np.cumsum(vel * h, axis=0)])
    clearance = np.linalg.norm(path - T_root[:3, 3], axis=1).min() - world.reach - world.obj.radius
    if clearance <= 0.02:
        return False
    # the mesh origin stays within |COM offset| of the COM whatever the spin
    offset = float(np.linalg.norm(world.obj_inertial[:3, 3]))
    return float(np.linalg.norm(path[-1] - p0)) - 2.0 * offset > prot.success_displacement + prot.early_exit_margin


# -- workers -------------------------------------------------------------------------------------------
_WORKER: dict = {}


def _worker_init(hand: SimHand, obj: ObjectModel, protocol: Protocol) -> None:
    from ohra.data.backends import _ignore_sigint

    _ignore_sigint()  # Ctrl-C is the driver's to handle (one line), not each worker's traceback
    _WORKER["world"] = World(hand, obj, protocol)


def _worker_run(args: tuple[int, np.ndarray, str]) -> tuple[int, GraspResult]:
    i, g, mode = args
    return i, run_grasp(_WORKER["world"], g, mode)


def _chunk_run(task: tuple) -> list[tuple[int, GraspResult]]:
    """One backend task: a fresh world for (hand, object, protocol), then its chunk of grasps."""
    hand, obj, protocol, idx, grasps, mode = task
    world = World(hand, obj, protocol)
    try:
        return [(int(i), run_grasp(world, g, mode)) for i, g in zip(idx, grasps)]
    finally:
        world.close()


class GraspEvaluator:
    """Evaluate canonical grasps of one hand on one object with the six-direction protocol.

    Args:
        hand: canonical params, a hand name (``ohra.get_hand``), or a :class:`SimHand` (e.g. an
            original hand: :meth:`original`, :meth:`from_urdf`).
        obj: the object (an :class:`ObjectModel`, or ``builtin:NAME``, ``procedural:FAMILY:SEED``, a mesh or URDF
            path); its mesh frame is the frame of the grasps.
        protocol: constants (:class:`Protocol`; ``Protocol.strict()`` for the harder preset).

    ``evaluate(grasps, mode, workers)`` returns an :class:`EvalReport` in input order; results are
    identical for any order, batch split and worker count.
    """

    def __init__(self, hand: Params | SimHand | str, obj: ObjectModel | str, protocol: Protocol | None = None):
        if isinstance(hand, str):
            from ohra.hands import get_couplings, get_hand

            hand = SimHand.from_params(get_hand(hand), name=hand, couplings=get_couplings(hand))
        elif isinstance(hand, (BaseParams, ExtendedParams)):
            from ohra.hands import couplings_of

            hand = SimHand.from_params(hand, couplings=couplings_of(hand))  # a registered coupled hand's params: its couplings
        elif not isinstance(hand, SimHand):
            raise OhraError(f"hand must be params, a hand name or a SimHand, got {type(hand).__name__}")
        obj = resolve_object(obj)  # an ObjectModel, or a spec as the CLI takes it ("builtin:box", a mesh path)
        from ohra.objects.resolve import warn_if_ungraspable

        warn_if_ungraspable(obj)  # a millimetre mesh read as metres: an 80 m can, simulated without a word before
        self.hand = hand
        protocol = protocol or Protocol()
        if not isinstance(protocol, Protocol):
            raise GraspError(f"protocol: expected a Protocol (e.g. Protocol(friction=1.0) or Protocol.preset('strict')), "
                             f"got {type(protocol).__name__}")
        if obj.density != DEFAULT_DENSITY and obj.density != protocol.density:
            # the protocol fixes the test's density (the paper's 500 kg/m^3); an object's own density was dropped silently
            warnings.warn(f"object {obj.name!r} has density {obj.density:g} kg/m^3; the six-direction test simulates it at "
                          f"the protocol's {protocol.density:g} kg/m^3 ({1e3 * obj.volume * protocol.density:.4g} g): "
                          f"Protocol(density={obj.density:g}) simulates it at its own", ObjectWarning,
                          stacklevel=user_stacklevel())
        self.obj = obj
        self.protocol = protocol
        self._world: World | None = None
        offset = float(np.linalg.norm(obj.center_mass))
        if self.protocol.object_point == "frame" and offset > COM_OFFSET_WARN:
            warnings.warn(f"object {obj.name!r}: its mesh frame's origin lies {100 * offset:.1f} cm from its centre of mass; "
                          "the fingers close toward that origin and the test measures its displacement, so outcomes "
                          "depend on where the mesh's origin is: centre the mesh, or use Protocol(object_point='com') (ohra eval / ohra grasp eval: --object-point com; a recipe: protocol: {object_point: com})", ObjectWarning, stacklevel=user_stacklevel())

    @classmethod
    def original(cls, name: str, obj: ObjectModel, protocol: Protocol | None = None, form: str | None = None) -> "GraspEvaluator":
        """Evaluate canonical grasps on the *original* URDF of a registered hand (replay)."""
        return cls(SimHand.registered_original(name, form), obj, protocol)

    @classmethod
    def from_urdf(cls, urdf, action_map, obj: ObjectModel, protocol: Protocol | None = None, **kw) -> "GraspEvaluator":
        """Evaluate canonical grasps on any hand URDF driven through ``action_map`` (see :class:`SimHand`)."""
        return cls(SimHand.from_original(urdf, action_map, **kw), obj, protocol)

    @property
    def world(self) -> World:
        if self._world is None:
            self._world = World(self.hand, self.obj, self.protocol)
        return self._world

    def check(self, grasps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Validated (N,31) float grasps and the (N,) mask of those with joints outside the limits."""
        g = check_grasps(grasps)
        q = g[:, 9:]
        out = np.any((q < self.hand.canon_lower - LIMIT_TOL) | (q > self.hand.canon_upper + LIMIT_TOL), axis=1)
        return g, out

    def evaluate(self, grasps: np.ndarray, mode: str = "eval", workers: int = 1, progress: bool = False,
                 chunksize: int = 1, backend: str = "process", address: str | None = None,
                 resume: str | Path | None = None) -> EvalReport:
        """Run the protocol on (N,31) grasps; ``mode`` ``"eval"`` or ``"filter"``; ``workers`` processes
        (``backend="ray"``: Ray tasks of about N / (4 workers) grasps each, on a local cluster with
        ``workers`` CPUs or the cluster at ``address``; see :mod:`ohra.data.backends`).

        ``resume``: an ``.npz`` path rewritten (atomically) every 2 s while grasps finish and when the call ends
        or is interrupted (:mod:`ohra.sim.partial`); a call with the same grasps, hand, object, protocol and
        mode takes the outcomes stored there and simulates only the rest (``meta["resumed"]`` counts them), so
        an interrupted evaluation loses nothing it finished (a killed one at most its last 2 s). A file made
        under other inputs is replaced. The file is left in place; delete it once the report is kept."""
        if mode not in ("eval", "filter"):
            raise GraspError(f"mode must be 'eval' or 'filter', got {mode!r}")
        if isinstance(workers, bool) or not isinstance(workers, (int, np.integer)):
            raise GraspError(f"workers must be a whole number >= 1, got {workers!r}")
        if int(workers) < 1:
            raise GraspError(f"workers must be >= 1, got {workers}")
        g, out = self.check(grasps)
        if out.any():
            warnings.warn(f"{int(out.sum())} grasp(s) have joints outside the limits; they are clamped", stacklevel=user_stacklevel())
        results: list[GraspResult | None] = [None] * len(g)
        store = None
        if resume is not None:
            from ohra.sim.partial import PartialEvaluation, evaluation_key

            store = PartialEvaluation(resume, evaluation_key(self.hand, self.obj, self.protocol, mode, g))
            for i, r in store.done.items():  # the key holds the grasps' shape: every stored index is one of them
                results[i] = r
        todo = np.array([i for i, r in enumerate(results) if r is None], dtype=int)
        bar = _progress(len(g), progress)
        bar.update(len(g) - len(todo))
        try:
            if len(todo):
                sub = g[todo]
                it = self._iter(sub, mode, int(workers), int(chunksize)) if backend == "process" and not address else \
                    self._iter_backend(sub, mode, int(workers), backend, address)
                for j, r in it:
                    i = int(todo[j])
                    results[i] = r
                    if store is not None:
                        store.add(i, r)
                    bar.update(1)
        finally:
            bar.close()
            if store is not None:
                store.flush()  # an interruption (Ctrl-C, an error in a worker) keeps every finished grasp
        meta = {"hand": self.hand.name, "object": self.obj.name, "object_hash": self.obj.mesh_hash, "workers": int(workers)}
        if store is not None:
            meta["resumed"] = len(g) - len(todo)
        return EvalReport([r for r in results if r is not None], mode, self.protocol, meta)

    def _iter_backend(self, g: np.ndarray, mode: str, workers: int, backend: str, address: str | None) -> Iterable[tuple[int, GraspResult]]:
        from ohra.data.backends import run_tasks

        n_chunks = max(1, min(len(g), 4 * workers))
        tasks = [(self.hand, self.obj, self.protocol, idx, g[idx], mode) for idx in np.array_split(np.arange(len(g)), n_chunks) if len(idx)]
        for chunk in run_tasks(_chunk_run, tasks, backend=backend, workers=workers, address=address):
            yield from chunk

    def _iter(self, g: np.ndarray, mode: str, workers: int, chunksize: int) -> Iterable[tuple[int, GraspResult]]:
        if workers == 1 or len(g) < 2:
            world = self.world
            for i in range(len(g)):
                yield i, run_grasp(world, g[i], mode)
            return
        # fork: the hand and object reach the workers without pickling; PyBullet is single-threaded
        # and the thread variables cover any pool first initialised inside a worker
        ctx = mp.get_context("fork")
        saved = {v: os.environ.get(v) for v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")}
        os.environ.update({v: "1" for v in saved})
        try:
            with ctx.Pool(min(workers, len(g)), initializer=_worker_init, initargs=(self.hand, self.obj, self.protocol)) as pool:
                yield from pool.imap_unordered(_worker_run, [(i, g[i], mode) for i in range(len(g))], chunksize=chunksize)
        finally:
            for v, old in saved.items():
                if old is None:
                    os.environ.pop(v, None)
                else:
                    os.environ[v] = old

    def close(self) -> None:
        if self._world is not None:
            self._world.close()
            self._world = None

    def __enter__(self) -> "GraspEvaluator":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __del__(self) -> None:  # pragma: no cover - best effort
        try:
            self.close()
        except Exception:
            pass


class _NoBar:
    def update(self, n: int) -> None:
        pass

    def close(self) -> None:
        pass


def _progress(total: int, enabled: bool):
    if not enabled:
        return _NoBar()
    from tqdm import tqdm

    return tqdm(total=total, desc="evaluating", unit="grasp")


def evaluate_grasps(hand: Params | SimHand | str, obj: ObjectModel, grasps: np.ndarray, mode: str = "eval",
                    workers: int = 1, protocol: Protocol | None = None) -> EvalReport:
    """One-shot convenience: ``GraspEvaluator(hand, obj, protocol).evaluate(grasps, mode, workers)``."""
    with GraspEvaluator(hand, obj, protocol) as ev:
        return ev.evaluate(grasps, mode=mode, workers=workers)


__all__: Sequence[str] = ("GraspEvaluator", "GraspResult", "EvalReport", "Protocol", "DIRECTIONS", "run_grasp",
                          "evaluate_grasps", "PHASES")
