"""Initial grasps of the rotation task: a seeded generator of stable starting states, cached to a file.

Procedure (HORA's grasp cache, made hand-agnostic):

1. *Nominal object pose*: the object rests on the palm centre (its lowest point 1 mm above the
   palm surface found by a ray cast), at yaw 0; its centre of mass above the palm centre.
2. *Holding pose*: with the object pinned there, every driven joint sweeps from 0 (clipped into
   its limits) towards its closing limit: the one whose rotation swings the joint's subtree
   (the links it moves) towards the object. Each finger stops when it touches the object (or
   70 % of the way); the settled joint values are the holding pose. An original URDF takes the
   canonical hand's holding pose through its action map (``grasp_hold="canonical"``, the default),
   so canonical and original start from the same hand pose; ``"own"`` closes its own fingers.
3. *Samples*: the holding pose plus uniform per-joint noise of +-``grasp_noise`` rad (reference
   ranges: LEAP 0.25, Shadow 0.1), clipped into the limits; the object at the nominal pose turned by a
   uniform random yaw about its centre of mass (which stays over the palm centre); the motors hold the noisy pose for ``settle_time`` s under gravity. A
   sample is kept when the object's centre of mass is still within half the termination margins (height,
   distance), has not moved over the last ``STILL_TIME`` s (a creeping object would start every episode with a
   free drift) and is touched by at least ``min_contacts`` distinct hand links. The kept state after
   the settle (joints, motor targets, object pose) is a starting state.

The result depends only on the hand's URDF, the object, the physics settings and the seed; it is
stored under ``ohra.paths.cache_dir()/rotation/`` keyed by a hash of all of them (atomic write); an unfinished
generation is saved beside it every ``PARTIAL_EVERY`` kept states and continued by the next use.
"""

from __future__ import annotations

import hashlib
import json
import math
import re
import sys
import time
import warnings
import zipfile
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pybullet as pb

from ohra.errors import OhraError, user_stacklevel
from ohra.io import write_npz
from ohra.paths import cache_dir
from ohra.sim.rotation.rewards import delta_yaw
from ohra.sim.rotation.scene import R_WORLD_PALM, RotationScene, _quat_mul, yaw_quat
from ohra.sim.rotation.task import Task

VERSION = 5  # bump when the procedure changes: old cache files are then ignored
CLEARANCE = 0.001  # m between the object's lowest point and the palm at the nominal pose
CLOSE_TIME = 2.0  # s of closing onto the pinned object for the holding pose
CLOSE_SPEED = 1.5  # rad/s of target sweep while closing
CLOSE_FRACTION = 0.7  # of the way from 0 to the closing limit, at most
STILL_TIME = 0.5  # s: the last part of the settle over which a kept object must have stopped
STILL_MOVE = (0.002, 0.02)  # (m, rad): the most it may move and turn about +z in that time
MAX_ATTEMPTS_PER_GRASP = 20


class GraspGenerationError(OhraError, RuntimeError):
    """No starting state survived the settle."""


@dataclass
class GraspSet:
    """Starting states (world frame, simulator joint order).

    Attributes:
        q: (N, n) driven joint positions [rad].
        target: (N, n) the motor targets holding them (the perturbed pose: a finger blocked by the
            object keeps pressing; starting from ``target`` continues the settled state exactly).
        obj_pos: (N, 3) object frame positions [m]; obj_quat: (N, 4) xyzw.
        hold: (n,) the holding pose the samples perturb.
        attempts: samples tried to keep N.
        key: hash of everything the states depend on.
    """

    q: np.ndarray
    target: np.ndarray
    obj_pos: np.ndarray
    obj_quat: np.ndarray
    hold: np.ndarray
    attempts: int
    key: str

    def __len__(self) -> int:
        return len(self.q)

    def save(self, path: Path) -> Path:
        return write_npz(path, {"q": self.q, "target": self.target, "obj_pos": self.obj_pos, "obj_quat": self.obj_quat,
                                "hold": self.hold, "attempts": self.attempts, "key": self.key})

    @classmethod
    def load(cls, path: Path) -> "GraspSet":
        with np.load(path) as d:
            return cls(d["q"], d["target"], d["obj_pos"], d["obj_quat"], d["hold"], int(d["attempts"]), str(d["key"]))


def nominal_pose(scene: RotationScene) -> tuple[np.ndarray, np.ndarray]:
    """(pos (3,), quat (4,) xyzw): the object frame's pose (world) with the object resting on the palm centre
    at yaw 0: its centre of mass above the palm centre and its lowest point ``CLEARANCE`` above the palm
    (``half_height`` is measured below the centre of mass). A mesh whose frame origin lies away from the
    object (a file in scene coordinates) is placed by its centre of mass, not by that origin."""
    p = scene.palm_centre_world()
    quat = scene.obj.rest_quat.copy()
    com = np.array([p[0], p[1], scene.palm_top + scene.obj.half_height + CLEARANCE])
    R = np.reshape(pb.getMatrixFromQuaternion([float(x) for x in quat]), (3, 3))
    return com - R @ np.asarray(scene.obj.com, dtype=float), quat


def closing_directions(scene: RotationScene, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """How each driven joint closes onto a point ``target`` (world), from the hand's current pose.

    Returns (sign (n,) +1/-1: the rotation that swings the joint's subtree (the links it moves,
    mass-weighted) towards ``target``; spread (n,) bool: a finger joint (not the thumb) whose axis
    lies within 45 deg of the palm normal, i.e. one that spreads the finger sideways instead of
    curling it).
    """
    c, b = scene.client, scene.body
    n_links = pb.getNumJoints(b, physicsClientId=c)
    parent = [pb.getJointInfo(b, j, physicsClientId=c)[16] for j in range(n_links)]
    states = pb.getLinkStates(b, list(range(n_links)), computeForwardKinematics=1, physicsClientId=c)
    com = np.array([s[0] for s in states])
    mass = np.array([max(pb.getDynamicsInfo(b, j, physicsClientId=c)[0], 1e-9) for j in range(n_links)])
    normal = R_WORLD_PALM[:, 0]  # palm +x in the world
    sign, spread = np.ones(len(scene.jidx)), np.zeros(len(scene.jidx), dtype=bool)
    for k, j in enumerate(scene.jidx):
        sub = [i for i in range(n_links) if _descends(i, j, parent)]
        c_sub = (com[sub] * mass[sub, None]).sum(0) / mass[sub].sum()
        R = np.reshape(pb.getMatrixFromQuaternion(states[j][5]), (3, 3))  # joint frame == child link frame
        axis = R @ np.asarray(pb.getJointInfo(b, j, physicsClientId=c)[13], dtype=float)
        axis /= max(np.linalg.norm(axis), 1e-12)
        motion = np.cross(axis, c_sub - np.asarray(states[j][4]))
        sign[k] = 1.0 if motion @ (target - c_sub) >= 0.0 else -1.0
        spread[k] = scene.hand.joint_finger[k] != 0 and abs(axis @ normal) > np.sqrt(0.5)
    return sign, spread


def _descends(i: int, j: int, parent: list[int]) -> bool:
    while i >= 0:
        if i == j:
            return True
        i = parent[i]
    return False


def holding_pose(scene: RotationScene) -> np.ndarray:
    """(n,) the joint values of the fingers closed onto the pinned object (see module doc).

    The targets of every finger sweep from 0 towards its closing limits at ``CLOSE_SPEED`` and
    stop, finger by finger, when one of its links touches the object (the finger then rests on
    the object instead of crushing into it) or at ``CLOSE_FRACTION`` of the way (a finger that
    misses does not curl into a fist against its neighbours). Sideways-spreading finger joints stay
    at 0: closing them presses neighbouring fingers into each other.
    """
    hand, cfg, c = scene.hand, scene.cfg, scene.client
    pos, quat = nominal_pose(scene)
    q0 = np.clip(0.0, hand.lower, hand.upper)
    scene.set_hand(q0)
    scene.new_object(pos, quat, fixed=True)
    R = np.reshape(pb.getMatrixFromQuaternion([float(x) for x in quat]), (3, 3))
    sign, spread = closing_directions(scene, pos + R @ np.asarray(scene.obj.com, dtype=float))  # onto the object
    goal = np.where(spread, q0, q0 + CLOSE_FRACTION * (np.where(sign > 0, hand.upper, hand.lower) - q0))
    target, step = q0.copy(), CLOSE_SPEED / cfg.control_hz
    moving = np.ones(5, dtype=bool)  # per finger
    finger_of_link = scene.link_finger
    for _ in range(int(round(CLOSE_TIME * cfg.control_hz))):
        for p in pb.getContactPoints(scene.body, scene.obj_body, physicsClientId=c):
            f = finger_of_link.get(p[3], -1)
            if f >= 0:
                moving[f] = False
        m = moving[hand.joint_finger]
        target = np.where(m, target + np.clip(goal - target, -step, step), target)
        scene.drive(np.where(m, target, scene.read().q))
        scene.step()
    return scene.read().q


def canonical_holding_pose(task: Task) -> np.ndarray:
    """(22,) canonical joint values of the holding pose of ``task``'s canonical hand (same params,
    object and physics; the template's finger masses) closed onto the pinned object."""
    from ohra.sim.rotation.task import resolve

    ctask = resolve(task.cfg.with_overrides(urdf="canonical", space=None, inertials="capsule", collisions="own"))
    scene = RotationScene(ctask.hand, ctask.obj, ctask.cfg, ctask.palm_radius)
    try:
        return ctask.hand.to_canonical(holding_pose(scene))
    finally:
        scene.close()


def _hold(task: Task, scene: RotationScene) -> np.ndarray:
    """The holding pose the samples perturb, in the simulator's joint order (see module doc)."""
    hand = task.hand
    if hand.canonical or task.cfg.grasp_hold == "own":
        return holding_pose(scene)
    return np.clip(hand.to_sim(canonical_holding_pose(task)), hand.lower, hand.upper)


def cache_key(task: Task) -> str:
    """Hash of everything the starting states depend on."""
    cfg = task.cfg
    fields = {k: getattr(cfg, k) for k in ("friction", "sim_dt", "control_hz", "solver_iterations", "self_collision",
                                           "gravity", "motor_force", "position_gain", "velocity_gain", "grasp_count",
                                           "grasp_seed", "settle_time", "min_contacts", "fall_height", "max_distance",
                                           "joint_damping")}
    if not task.hand.canonical and cfg.grasp_hold != "own":  # keys of states made before the setting stay valid
        fields["grasp_hold"] = cfg.grasp_hold
    fields.update(noise=cfg.resolved_grasp_noise, object=task.obj.name, mass=task.obj.mass,
                  prims=[dict(p) for p in task.obj.prims], version=VERSION, palm_radius=task.palm_radius,
                  **({"body": task.obj.digest} if task.obj.digest else {}),  # a mesh object (keys of primitives unchanged)
                  # placed by its centre of mass (keys of objects whose frame is their centre of mass unchanged)
                  # and turned about it ("com-yaw"; before, the yaw turned it about its frame origin)
                  **({"placed": "com-yaw"} if np.any(np.asarray(task.obj.com) != 0.0) else {}),
                  pybullet=pb.getAPIVersion())
    h = hashlib.sha256(task.hand.urdf.encode())
    h.update(json.dumps(fields, sort_keys=True, default=float).encode())
    return h.hexdigest()[:16]


def cache_path(task: Task) -> Path:
    """The cache file of ``task``'s starting states: named for the hand, URDF and object (a file's stem when
    either is given as a path), keyed by :func:`cache_key`."""
    hand, obj = (_label(str(s)) for s in (task.cfg.hand, task.cfg.object))
    return cache_dir() / "rotation" / f"{hand}_{task.cfg.urdf}_{obj}_{cache_key(task)}.npz"


def _label(spec: str) -> str:
    if "/" in spec or "\\" in spec or spec.endswith((".json", ".yaml", ".yml", ".obj", ".stl", ".ply", ".urdf")):
        spec = Path(spec).stem
    return re.sub(r"[^A-Za-z0-9_.-]+", "-", spec)


REJECTIONS = ("non-finite state", "object fell", "object left the hand", "object still moving", "object still turning",
              "too few hand contacts")


def _rejection(scene: RotationScene, start: np.ndarray, before) -> str | None:
    """Why a settled sample is not kept (one of :data:`REJECTIONS`), None when it is: its centre of mass in place
    (half the termination margins; ``start`` is where it began, world [m]), still since ``before`` (the state
    ``STILL_TIME`` s earlier), and touched by ``min_contacts`` hand links."""
    cfg, s = scene.cfg, scene.read()
    if not (np.all(np.isfinite(s.obj_com)) and np.all(np.isfinite(s.q))):
        return REJECTIONS[0]
    if s.obj_com[2] < start[2] - cfg.fall_height / 2:
        return REJECTIONS[1]
    if np.linalg.norm(s.obj_com - start) > cfg.max_distance / 2:
        return REJECTIONS[2]
    if np.linalg.norm(s.obj_com - before.obj_com) > STILL_MOVE[0]:
        return REJECTIONS[3]
    if abs(delta_yaw(before.obj_quat, s.obj_quat)) > STILL_MOVE[1]:
        return REJECTIONS[4]
    return None if scene.hand_contacts() >= cfg.min_contacts else REJECTIONS[5]


def _keep(scene: RotationScene, start: np.ndarray, before, rejected: Counter | None = None) -> bool:
    """Whether to keep a settled sample (:func:`_rejection`); ``rejected`` counts the reasons of the others."""
    why = _rejection(scene, start, before)
    if why is not None and rejected is not None:
        rejected[why] += 1
    return why is None


PARTIAL_EVERY = 25  # kept states between two saves of an unfinished generation
FORECAST_AFTER = 50  # attempts of this run before the one forecast of how long and how many (a hand that keeps
# few perturbed grasps on its original URDF can take over an hour with no word but a bar on a terminal)
FORECAST_SECONDS = 600.0  # a generation forecast to take longer than this is said


def forecast(kept: int, attempts: int, seconds: float, run_attempts: int, count: int, max_attempts: int) -> str | None:
    """A sentence forecasting where a generation ends (kept states, minutes), or None when it ends within
    :data:`FORECAST_SECONDS` with every state. ``attempts`` / ``kept`` count the whole generation (a continued one's
    included), ``seconds`` the ``run_attempts`` made by this process."""
    if run_attempts <= 0 or attempts <= 0:
        return None
    per_attempt = seconds / run_attempts
    left = max_attempts - attempts
    need = math.inf if kept == 0 else (count - kept) * attempts / kept
    more = min(need, left)
    ends = count if need <= left else kept + int(left * kept / attempts)
    eta = more * per_attempt
    if ends >= count and eta <= FORECAST_SECONDS:
        return None
    rate = f"{kept} of {attempts} perturbed grasps kept so far ({100 * kept / attempts:.0f} %, {per_attempt:.2f} s each)"
    if ends >= count:
        return f"{rate}: the {count} starting states take about {eta / 60:.0f} more minutes (cached for later uses)"
    if kept == 0:  # generate() raises GraspGenerationError when none is kept at all
        return (f"{rate}: if none holds, the generation fails after its limit of {max_attempts} attempts, in about "
                f"{eta / 60:.0f} more minutes")
    return (f"{rate}: at that rate the generation stops at its limit of {max_attempts} attempts with about {ends} of "
            f"{count} starting states, in about {eta / 60:.0f} more minutes (cached for later uses); fewer states "
            "(grasp_count) end it sooner")


def generate(task: Task, progress: bool | None = False, partial: Path | None = None) -> GraspSet:
    """Generate ``task.cfg.grasp_count`` starting states (see module doc); seeded by ``grasp_seed``.

    ``partial``: a file where the unfinished set is saved every ``PARTIAL_EVERY`` kept states (with the random
    generator's state) and from which an interrupted generation continues; the result equals an uninterrupted
    one (each attempt starts from a reset scene: ``RotationScene``).
    """
    cfg, hand = task.cfg, task.hand
    scene = RotationScene(hand, task.obj, cfg, task.palm_radius)
    try:
        hold = _hold(task, scene)
        pos, rest = nominal_pose(scene)
        com = scene.com_world(pos, rest)  # each sample turns the object about its centre of mass
        rng = np.random.default_rng(cfg.grasp_seed)
        r = cfg.resolved_grasp_noise
        steps = int(round(cfg.settle_time * cfg.control_hz))
        check = steps - int(round(STILL_TIME * cfg.control_hz))
        Q, T, P, O = [], [], [], []
        attempts = 0
        key = cache_key(task)
        rejected: Counter = Counter()  # the rejections' reasons, for the messages below (an interrupted run's included)
        if partial is not None:
            attempts = _resume_partial(partial, key, hold, rng, (Q, T, P, O), rejected)
        bar = _bar(cfg.grasp_count, f"grasps {hand.name}", progress)
        bar.update(len(Q))
        t0, first = time.perf_counter(), attempts
        while len(Q) < cfg.grasp_count and attempts < MAX_ATTEMPTS_PER_GRASP * cfg.grasp_count:
            if attempts - first == FORECAST_AFTER:
                note = forecast(len(Q), attempts, time.perf_counter() - t0, attempts - first, cfg.grasp_count,
                                MAX_ATTEMPTS_PER_GRASP * cfg.grasp_count)
                if note:
                    warnings.warn(f"{hand.name} with {task.obj.name}, starting states (first use): {note}",
                                  stacklevel=user_stacklevel())
            attempts += 1
            q = np.clip(hold + rng.uniform(-r, r, size=hold.shape), hand.lower, hand.upper)
            quat = _quat_mul(yaw_quat(float(rng.uniform(-math.pi, math.pi))), rest)
            scene.set_hand(q)
            scene.new_object(com - (scene.com_world(np.zeros(3), quat)), quat)
            before = None
            for k in range(steps):
                scene.step()
                if k + 1 == check:
                    before = scene.read()
            if _keep(scene, com, before, rejected):
                s = scene.read()
                Q.append(s.q)
                T.append(q)
                P.append(s.obj_pos)
                O.append(s.obj_quat)
                bar.update(1)
                if partial is not None and len(Q) % PARTIAL_EVERY == 0 and len(Q) < cfg.grasp_count:
                    _save_partial(partial, key, hold, rng, attempts, (Q, T, P, O), rejected)
        bar.close()
    finally:
        scene.close()
    if not Q:
        why = ", ".join(f"{k} ({n})" for k, n in rejected.most_common())
        raise GraspGenerationError(f"{hand.name} with {task.obj.name}: none of {attempts} perturbed grasps survived "
                                   f"{cfg.settle_time} s (noise +-{r} rad)" + (f": {why}" if why else "")
                                   + (" (a hand that cannot hold the object palm up, or a holding pose that does not "
                                      "close on it)" if rejected.get(REJECTIONS[1], 0) > attempts / 2 else ""))
    if len(Q) < cfg.grasp_count:
        why = ", ".join(f"{k} ({n})" for k, n in rejected.most_common())
        warnings.warn(f"{hand.name}: only {len(Q)} of {cfg.grasp_count} starting states after {attempts} attempts"
                      + (f"; the others: {why}" if why else ""), stacklevel=user_stacklevel())
    return GraspSet(np.array(Q), np.array(T), np.array(P), np.array(O), hold, attempts, key)


def _save_partial(path: Path, key: str, hold: np.ndarray, rng: np.random.Generator, attempts: int, lists,
                  rejected: Counter) -> None:
    Q, T, P, O = (np.array(x) for x in lists)
    write_npz(path, {"q": Q, "target": T, "obj_pos": P, "obj_quat": O, "hold": hold, "attempts": attempts,
                     "key": key, "rng": json.dumps(rng.bit_generator.state), "rejected": json.dumps(dict(rejected))})


def _resume_partial(path: Path, key: str, hold: np.ndarray, rng: np.random.Generator, lists, rejected: Counter) -> int:
    """Fill ``lists``, ``rng`` and ``rejected`` from an unfinished generation of the same key; returns its attempts
    (0: none). A file from before the counts were saved continues with none counted."""
    if not path.is_file():
        return 0
    try:
        with np.load(path, allow_pickle=False) as d:
            if str(d["key"]) != key or not np.array_equal(d["hold"], hold):
                return 0
            arrays = [np.asarray(d[k]) for k in ("q", "target", "obj_pos", "obj_quat")]
            attempts, state = int(d["attempts"]), json.loads(str(d["rng"]))
            counts = json.loads(str(d["rejected"])) if "rejected" in d.files else {}
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
        return 0  # unreadable: start again
    rng.bit_generator.state = state
    rejected.update({str(k): int(n) for k, n in counts.items()})
    for lst, a in zip(lists, arrays):
        lst.extend(list(a))
    return attempts


def load_or_generate(task: Task, progress: bool | None = None) -> GraspSet:
    """The cached starting states of ``task``, generated and cached on first use (tens of minutes for a hand
    whose perturbed grasps seldom hold: the original Allegro with the cube keeps ~1 in 7). ``progress``: a
    bar while generating; ``None`` shows one when stderr is a terminal."""
    path = cache_path(task)
    if path.is_file():
        try:
            gs = GraspSet.load(path)
            if gs.key == cache_key(task):
                return gs
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
            pass  # unreadable (truncated, empty) or foreign file: regenerate
    partial = path.with_name(f".{path.stem}.partial.npz")  # an interrupted generation continues from here
    gs = generate(task, progress, partial=partial)
    gs.save(path)
    partial.unlink(missing_ok=True)
    return gs


class _NoBar:
    def update(self, n: int) -> None:
        pass

    def close(self) -> None:
        pass


def _bar(total: int, desc: str, show: bool | None):
    if show is None:
        show = sys.stderr.isatty()
    if not show:
        return _NoBar()
    from tqdm import tqdm

    return tqdm(total=total, desc=f"{desc} (first use; cached)", leave=False)
