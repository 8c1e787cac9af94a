"""The six-direction perturbation test in PyBullet (port of the OHRA / D(R,O) Isaac Gym filter).

Per grasp: the canonical hand is fixed at the grasp pose (palm frame in the object frame, which is
the world frame), the object (convex pieces, mass from volume x density) sits at the origin.
Every present joint is reset 10 % of the way toward its opening limit and driven 10 % past the
grasp toward its closing limit ("squeeze"), 1 s. Then a force of ``0.5 m`` N pulls the object along
+x, +y, +z, -x, -y, -z, 1 s each, re-applied every step. Success: the object's final displacement
since the end of the squeeze is at most 2 cm (filter mode: and it ends within 5 cm of the origin).

Determinism: one world per (hand, object) is built once per process and restored from a saved
state before every grasp, so a grasp's outcome does not depend on the order, the batch or the
number of worker processes (tests check this bit for bit).

Early exit (optional, on by default): when the object touches nothing and its free-flight path
under the remaining force schedule stays out of the hand's reach, the rest of the run is decided;
the grasp is stopped and marked failed only if that path ends more than ``early_exit_margin``
beyond the success threshold (so early exit never changes an outcome; the benchmark checks it).
"""

from __future__ import annotations

import math
import multiprocessing as mp
import os
import tempfile
import warnings
import xml.etree.ElementTree as ET
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Sequence, Union

import numpy as np
import pybullet as pb

from ..errors import GraspError
from ..kinematics import HandModel
from ..objects import ObjectModel
from ..params import FINGERS, JOINT_NAMES, BaseParams, ExtendedParams
from ..rotations import check_grasps, grasp_to_pose, matrix_to_quat, pose_to_grasp, quat_to_matrix
from ..urdfgen import render

Params = Union[BaseParams, ExtendedParams]
DIRECTIONS = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [-1, 0, 0], [0, -1, 0], [0, 0, -1]], dtype=float)


@dataclass(frozen=True)
class Protocol:
    """Constants of the perturbation protocol (reference values as defaults)."""

    dt: float = 0.01  # s, simulation step
    substeps: int = 2
    squeeze_time: float = 1.0  # s
    direction_time: float = 1.0  # s per direction
    force_per_mass: float = 0.5  # N/kg (0.5 m/s^2)
    friction: float = 3.0  # effective hand-object friction (PyBullet multiplies: sqrt on each body)
    density: float = 500.0  # kg/m^3
    outer: float = 0.1  # fraction of the range opened at reset
    inner: float = 0.1  # fraction of the range closed past the grasp as target
    motor_force: float = 1.0  # N m, drive limit (URDF effort)
    position_gain: float = 0.3
    velocity_gain: float = 1.0
    success_displacement: float = 0.02  # m
    filter_max_distance: float = 0.05  # m from the origin (filter mode)
    gravity_in_evaluation: float = 0.0  # m/s^2 along -z during the perturbation phase
    early_exit: bool = True
    early_exit_margin: float = 0.05  # m beyond the threshold before a free flight counts as decided

    @classmethod
    def strict(cls) -> "Protocol":
        """Harder preset: friction 1.0 and gravity on during the perturbation phase."""
        return cls(friction=1.0, gravity_in_evaluation=9.81)


@dataclass
class GraspResult:
    """Outcome of one grasp."""

    success: bool
    displacement: np.ndarray  # (7,) m: after the squeeze (from the start) and after each direction (from p0)
    final_distance_from_origin: float
    contacts: int  # hand links touching the object at the end of the squeeze
    initial_penetration: float  # m, deepest hand-object overlap at the input grasp
    post_grasp: np.ndarray  # (31,) palm pose relative to the settled object + settled joints
    clamped: bool  # joints were outside limits and were clamped
    early_exit: bool
    steps: int


@dataclass
class EvalReport:
    """Results of a batch, in input order."""

    results: list[GraspResult]
    mode: str
    protocol: Protocol

    @property
    def success(self) -> np.ndarray:
        return np.array([r.success for r in self.results], dtype=bool)

    @property
    def success_rate(self) -> float:
        return float(self.success.mean()) if self.results else 0.0

    @property
    def post_grasps(self) -> np.ndarray:
        return np.array([r.post_grasp for r in self.results]).reshape(-1, 31)

    @property
    def clamped_count(self) -> int:
        return int(sum(r.clamped for r in self.results))

    def to_dict(self) -> dict:
        return {
            "mode": self.mode,
            "protocol": asdict(self.protocol),
            "n": len(self.results),
            "success_rate": self.success_rate,
            "clamped_joints_grasps": self.clamped_count,
            "grasps": [
                {
                    "success": r.success, "displacement_m": [float(x) for x in r.displacement],
                    "final_distance_from_origin_m": r.final_distance_from_origin, "contacts": r.contacts,
                    "initial_penetration_m": r.initial_penetration, "clamped": r.clamped,
                    "early_exit": r.early_exit, "steps": r.steps,
                }
                for r in self.results
            ],
        }


class _World:
    """One PyBullet world with the hand and the object, restorable to its initial state."""

    def __init__(self, params: Params, obj: ObjectModel, protocol: Protocol):
        self.protocol = protocol
        self.hand = HandModel.from_params(params)
        self.obj = obj
        self.client = pb.connect(pb.DIRECT)
        fd, path = tempfile.mkstemp(suffix=".urdf")
        with os.fdopen(fd, "w") as fh:
            fh.write(self.hand.urdf)
        self._urdf_path = path
        self.build()

    def build(self) -> None:
        """(Re)create the world from scratch. PyBullet's saveState/restoreState keeps contact caches
        that make outcomes depend on earlier grasps, so every grasp starts from a fresh world."""
        c, protocol = self.client, self.protocol
        pb.resetSimulation(physicsClientId=c)
        pb.setGravity(0, 0, 0, physicsClientId=c)
        pb.setTimeStep(protocol.dt, physicsClientId=c)
        pb.setPhysicsEngineParameter(numSubSteps=protocol.substeps, deterministicOverlappingPairs=1, physicsClientId=c)
        self.body = pb.loadURDF(self._urdf_path, useFixedBase=True, flags=pb.URDF_USE_SELF_COLLISION | pb.URDF_IGNORE_VISUAL_SHAPES, physicsClientId=c)
        self._setup_hand()
        self._setup_object()

    def _setup_hand(self) -> None:
        c, b = self.client, self.body
        mu = math.sqrt(self.protocol.friction)
        self.joint_index: dict[str, int] = {}
        link_finger: dict[int, int] = {}
        child_of = {j.get("name"): j.find("child").get("link") for j in ET.fromstring(self.hand.urdf).iter("joint")}
        self.child_link = [child_of[n] for n in JOINT_NAMES]
        for j in range(pb.getNumJoints(b, physicsClientId=c)):
            info = pb.getJointInfo(b, j, physicsClientId=c)
            name, link = info[1].decode(), info[12].decode()
            self.joint_index[name] = j
            prefix = link.split("_")[0]
            link_finger[j] = FINGERS.index(prefix) if prefix in FINGERS else -1  # palm: -1
            pb.changeDynamics(b, j, lateralFriction=mu, spinningFriction=0.0, rollingFriction=0.0,
                              linearDamping=0.0, angularDamping=0.0, jointDamping=0.0, physicsClientId=c)
        links = sorted(link_finger)
        for i in links:
            for k in links:
                if k <= i:
                    continue
                fi, fk = link_finger[i], link_finger[k]
                if fi == fk or fi < 0 or fk < 0:  # palm-finger and same-finger pairs never collide
                    pb.setCollisionFilterPair(b, b, i, k, 0, physicsClientId=c)
        self.link_finger = link_finger
        self.jidx = np.array([self.joint_index[n] for n in JOINT_NAMES])
        present = self.hand.present_joints
        for k, n in enumerate(JOINT_NAMES):
            if not present[k]:  # inactive joints: locked at 0
                pb.setJointMotorControl2(b, self.jidx[k], pb.POSITION_CONTROL, targetPosition=0.0, force=100.0, physicsClientId=c)
        # reach of the hand from the palm origin (bounds every point a finger can touch)
        p = self.hand.params
        reach = 2.0 * p.palm_radius + 0.05
        caps = self.hand.capsule_specs
        if caps:
            base = np.linalg.norm(self.hand.frame_poses(np.zeros(22), [s[0] for s in caps])[:, :3, 3], axis=1).max()
            reach = max(reach, float(base) + sum(sorted((s[3] for s in caps), reverse=True)[:3]) + max(s[2] for s in caps))
        self.reach = reach

    def _setup_object(self) -> None:
        c, o, prot = self.client, self.obj, self.protocol
        pieces = o.convex_pieces()  # cached on the object
        shapes = []
        for piece in pieces:
            shapes.append(pb.createCollisionShape(pb.GEOM_MESH, vertices=np.asarray(piece.vertices).tolist(), physicsClientId=c))
        mass = o.volume * prot.density
        com = o.center_mass
        I = o.inertia / o.density * prot.density
        w, V = np.linalg.eigh(0.5 * (I + I.T))
        if np.linalg.det(V) < 0:
            V[:, 0] *= -1
        q_inertial = matrix_to_quat(V)
        if len(shapes) == 1:
            self.obj_body = pb.createMultiBody(mass, shapes[0], -1, [0, 0, 0], [0, 0, 0, 1], baseInertialFramePosition=com.tolist(),
                                               baseInertialFrameOrientation=q_inertial.tolist(), physicsClientId=c)
        else:
            # compound: base carries the first piece, the others hang on fixed links; link masses split by volume
            vols = np.array([p.volume for p in pieces])
            shares = vols / vols.sum()
            self.obj_body = pb.createMultiBody(
                mass * shares[0], shapes[0], -1, [0, 0, 0], [0, 0, 0, 1],
                baseInertialFramePosition=pieces[0].center_mass.tolist(),
                linkMasses=(mass * shares[1:]).tolist(), linkCollisionShapeIndices=shapes[1:],
                linkVisualShapeIndices=[-1] * (len(shapes) - 1), linkPositions=[[0, 0, 0]] * (len(shapes) - 1),
                linkOrientations=[[0, 0, 0, 1]] * (len(shapes) - 1),
                linkInertialFramePositions=[p.center_mass.tolist() for p in pieces[1:]],
                linkInertialFrameOrientations=[[0, 0, 0, 1]] * (len(shapes) - 1),
                linkParentIndices=[0] * (len(shapes) - 1), linkJointTypes=[pb.JOINT_FIXED] * (len(shapes) - 1),
                linkJointAxis=[[0, 0, 1]] * (len(shapes) - 1), physicsClientId=c,
            )
        mu = math.sqrt(prot.friction)
        for link in range(-1, pb.getNumJoints(self.obj_body, physicsClientId=c)):
            pb.changeDynamics(self.obj_body, link, lateralFriction=mu, spinningFriction=0.0, rollingFriction=0.0,
                              linearDamping=0.0, angularDamping=0.0, physicsClientId=c)
        self.mass = mass
        self.multi_piece = len(shapes) > 1

    # -- per grasp ---------------------------------------------------------------------------------------
    def _object_origin(self) -> tuple[np.ndarray, np.ndarray]:
        """Position and rotation of the object's mesh frame (PyBullet reports the base inertial frame)."""
        c = self.client
        pos, orn = pb.getBasePositionAndOrientation(self.obj_body, physicsClientId=c)
        R = quat_to_matrix(orn)
        dyn = pb.getDynamicsInfo(self.obj_body, -1, physicsClientId=c)
        local_pos, local_orn = np.array(dyn[3]), dyn[4]
        R_local = quat_to_matrix(local_orn)
        R_frame = R @ R_local.T
        return np.asarray(pos) - R_frame @ local_pos, R_frame

    def _com_velocity(self) -> tuple[np.ndarray, np.ndarray]:
        c = self.client
        pos, _ = pb.getBasePositionAndOrientation(self.obj_body, physicsClientId=c)
        v, _ = pb.getBaseVelocity(self.obj_body, physicsClientId=c)
        return np.asarray(pos), np.asarray(v)

    def _set_joints(self, q: np.ndarray) -> None:
        for k in range(22):
            pb.resetJointState(self.body, int(self.jidx[k]), float(q[k]), 0.0, physicsClientId=self.client)

    def squeeze_targets(self, T: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(q_outer, q_inner): per joint, open/close by the protocol fractions (reference controller)."""
        hm = self.hand
        poses = T @ hm.frame_poses(q, self.child_link)
        axes = np.array([hm.tree.joint_axis[hm.tree.joint_names.index(n)] for n in JOINT_NAMES])
        a_w = np.einsum("kij,kj->ki", poses[:, :3, :3], axes)
        l_w = poses[:, :3, 2]
        n = np.cross(a_w, l_w)
        p = poses[:, :3, 3]
        o = -p / np.maximum(np.linalg.norm(p, axis=1, keepdims=True), 1e-12)
        closing_up = (n * o).sum(axis=1) >= 0.0
        lo, up = hm.lower, hm.upper
        prot = self.protocol
        outer = np.where(closing_up, q + prot.outer * (lo - q), q + prot.outer * (up - q))
        inner = np.where(closing_up, q + prot.inner * (up - q), q + prot.inner * (lo - q))
        present = hm.present_joints
        return np.where(present, outer, 0.0), np.where(present, inner, 0.0)

    def run(self, grasp: np.ndarray, mode: str) -> GraspResult:
        prot, c, hm = self.protocol, self.client, self.hand
        self.build()
        T, q = grasp_to_pose(grasp)
        qc = np.clip(q, hm.lower, hm.upper)
        clamped = bool(np.any(np.abs(qc - q) > 1e-9))
        pb.resetBasePositionAndOrientation(self.body, T[:3, 3].tolist(), matrix_to_quat(T[:3, :3]).tolist(), physicsClientId=c)
        self._set_joints(qc)
        pen = 0.0
        for cp in pb.getClosestPoints(self.body, self.obj_body, 0.0, physicsClientId=c):
            pen = max(pen, -cp[8])
        q_outer, q_inner = self.squeeze_targets(T, qc)
        self._set_joints(q_outer)
        present = hm.present_joints
        for k in range(22):
            if present[k]:
                pb.setJointMotorControl2(self.body, int(self.jidx[k]), pb.POSITION_CONTROL, targetPosition=float(q_inner[k]),
                                         force=prot.motor_force, positionGain=prot.position_gain,
                                         velocityGain=prot.velocity_gain, physicsClientId=c)
        n_sq = int(round(prot.squeeze_time / prot.dt))
        n_dir = int(round(prot.direction_time / prot.dt))
        start, _ = self._object_origin()
        steps = 0
        for _ in range(n_sq):
            pb.stepSimulation(physicsClientId=c)
            steps += 1
        p0, _ = self._object_origin()
        contacts = len({cp[3] for cp in pb.getContactPoints(self.body, self.obj_body, physicsClientId=c)})
        disp = np.full(7, np.nan)
        disp[0] = float(np.linalg.norm(p0 - start))
        F = prot.force_per_mass * self.mass
        if prot.gravity_in_evaluation:
            pb.setGravity(0, 0, -prot.gravity_in_evaluation, physicsClientId=c)
        early = False
        for d, direction in enumerate(DIRECTIONS):
            for s in range(n_dir):
                com, _ = self._com_velocity()
                pb.applyExternalForce(self.obj_body, -1, (F * direction).tolist(), com.tolist(), pb.WORLD_FRAME, physicsClientId=c)
                pb.stepSimulation(physicsClientId=c)
                steps += 1
                if prot.early_exit and s % 10 == 9 and self._decided_failure(T, p0, d, s + 1, n_dir):
                    early = True
                    break
            p, _ = self._object_origin()
            disp[d + 1] = float(np.linalg.norm(p - p0))
            if early:
                break
        if prot.gravity_in_evaluation:
            pb.setGravity(0, 0, 0, physicsClientId=c)
        p_end, R_end = self._object_origin()
        final_disp = float(np.linalg.norm(p_end - p0))
        success = (not early) and final_disp <= prot.success_displacement
        if mode == "filter":
            success = success and float(np.linalg.norm(p_end)) <= prot.filter_max_distance
        q_end = np.array([pb.getJointState(self.body, int(j), physicsClientId=c)[0] for j in self.jidx])
        q_end = np.where(present, q_end, 0.0)
        T_obj = np.eye(4)
        T_obj[:3, :3], T_obj[:3, 3] = R_end, p_end
        post = pose_to_grasp(np.linalg.inv(T_obj) @ T, q_end)
        return GraspResult(bool(success), disp, float(np.linalg.norm(p_end)), contacts, float(pen), post, clamped, early, steps)

    def _decided_failure(self, T: np.ndarray, p0: np.ndarray, d: int, s_done: int, n_dir: int) -> bool:
        """Free flight of the COM under the remaining schedule: out of reach and far -> failure is certain."""
        c = self.client
        if pb.getContactPoints(self.body, self.obj_body, physicsClientId=c):
            return False
        if self.protocol.gravity_in_evaluation:
            return False
        com, v = self._com_velocity()
        a = self.protocol.force_per_mass
        dt = self.protocol.dt
        acc = [DIRECTIONS[d]] * (n_dir - s_done) + [DIRECTIONS[k] for k in range(d + 1, 6) for _ in range(n_dir)]
        acc = a * np.array(acc).reshape(-1, 3)
        vel = v + np.cumsum(acc * dt, axis=0)
        path = com + np.cumsum(vel * dt, axis=0)
        path = np.vstack([com, path])
        palm = T[:3, 3]
        clearance = np.linalg.norm(path - palm, axis=1).min() - self.reach - self.obj.radius
        if clearance <= 0.02:
            return False
        # the mesh origin sits at a fixed distance from the COM whatever the object's spin
        offset = float(np.linalg.norm(com - self._object_origin()[0]))
        far = float(np.linalg.norm(path[-1] - p0)) - 2.0 * offset
        return far > self.protocol.success_displacement + self.protocol.early_exit_margin

    def close(self) -> None:
        if self.client is not None and pb.isConnected(self.client):
            pb.disconnect(self.client)
        self.client = None
        Path(self._urdf_path).unlink(missing_ok=True)


_WORKER: dict = {}


def _worker_init(params: Params, obj: ObjectModel, protocol: Protocol) -> None:
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[var] = "1"
    _WORKER["world"] = _World(params, obj, protocol)


def _worker_run(args: tuple[int, np.ndarray, str]) -> tuple[int, GraspResult]:
    i, g, mode = args
    return i, _WORKER["world"].run(g, mode)


class GraspEvaluator:
    """Evaluate canonical grasps of one hand on one object with the six-direction protocol.

    Args:
        hand: canonical params of the hand.
        obj: the object (its mesh frame is the world frame of the grasps).
        protocol: protocol constants (:class:`Protocol`; ``Protocol.strict()`` for the harder preset).
    """

    def __init__(self, hand: Params, obj: ObjectModel, protocol: Protocol | None = None):
        if not isinstance(hand, (BaseParams, ExtendedParams)):
            raise TypeError("hand must be BaseParams or ExtendedParams")
        self.params = hand
        self.obj = obj
        self.protocol = protocol or Protocol()
        self._world: _World | None = None

    @property
    def world(self) -> _World:
        if self._world is None:
            self._world = _World(self.params, self.obj, self.protocol)
        return self._world

    def evaluate(self, grasps: np.ndarray, mode: str = "eval", workers: int = 1, progress: bool = False) -> EvalReport:
        """Run the protocol on (N,31) grasps; ``mode`` ``"eval"`` or ``"filter"``; ``workers`` processes."""
        if mode not in ("eval", "filter"):
            raise GraspError(f"mode must be 'eval' or 'filter', got {mode!r}")
        if int(workers) < 1:
            raise GraspError(f"workers must be >= 1, got {workers}")
        g = check_grasps(grasps)
        hm = self.world.hand if workers == 1 else HandModel.from_params(self.params)
        q = g[:, 9:]
        out_of_limits = np.any((q < hm.lower - 1e-9) | (q > hm.upper + 1e-9), axis=1)
        if out_of_limits.any():
            warnings.warn(f"{int(out_of_limits.sum())} grasp(s) have joints outside the limits; they are clamped", stacklevel=2)
        bar = _progress(len(g), progress)
        results: list[GraspResult | None] = [None] * len(g)
        if workers == 1 or len(g) < 2:
            for i in range(len(g)):
                results[i] = self.world.run(g[i], mode)
                bar.update(1)
        else:
            ctx = mp.get_context("fork")
            with ctx.Pool(int(workers), initializer=_worker_init, initargs=(self.params, self.obj, self.protocol)) as pool:
                for i, r in pool.imap_unordered(_worker_run, [(i, g[i], mode) for i in range(len(g))], chunksize=1):
                    results[i] = r
                    bar.update(1)
        bar.close()
        return EvalReport([r for r in results if r is not None], mode, self.protocol)

    def close(self) -> None:
        if self._world is not None:
            self._world.close()
            self._world = None

    def __enter__(self) -> "GraspEvaluator":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


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
