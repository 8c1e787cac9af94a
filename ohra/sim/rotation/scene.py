"""The PyBullet world of the rotation task: a palm-up hand (fixed base), gravity, one free object.

Frames: the world's +z is up. The canonical palm frame sits at the world origin, turned palm-up:
palm +x (the palm normal) -> world +z, palm +z (finger-forward) -> world +x, palm +y (thumb side of
a right hand) -> world -y. An original URDF's root is placed by the same palm frame
(``SimHand.T_palm_root``), so canonical and original hands hold the object at the same place.

One control step is ``substeps`` calls of ``stepSimulation`` with PyBullet's time step set to
``sim_dt``, the motor targets held. Not PyBullet's own ``numSubSteps``: it computes a motor's
impulse cap from the *outer* step, so every sub-step may push ``numSubSteps`` times
``motor_force``, and it reports torques divided by that factor (measured: with 6 sub-steps a
0.005 N m cap held a LEAP finger that needs 0.025 N m, reporting 0.0042 N m). A fresh object body is made on every reset and every hand
link's collision filter is re-applied, which drops PyBullet's cached contact manifolds, so a reset
state evolves the same whatever ran before it (see ``ohra.sim.world``).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass

import numpy as np
import pybullet as pb

from ohra.errors import OhraError
from ohra.sim.bullet import convex_pieces_shape, load_hand
from ohra.sim.hands import SimHand
from ohra.sim.rotation.config import RotationConfig
from ohra.sim.rotation.objects import ObjectShape
from ohra.sim.world import FINGER_BITS, OBJECT_BIT, PALM_BIT, _mask_of

class SceneError(OhraError, RuntimeError):
    """The hand cannot hold the task's scene (e.g. it has no palm collision shape to rest the object on)."""


# rotation of the palm frame in the world: columns are the palm x, y, z axes in world coordinates
R_WORLD_PALM = np.array([[0.0, 0.0, 1.0], [0.0, -1.0, 0.0], [1.0, 0.0, 0.0]])
T_WORLD_PALM = np.eye(4)
T_WORLD_PALM[:3, :3] = R_WORLD_PALM
_PRIM = {"sphere": pb.GEOM_SPHERE, "box": pb.GEOM_BOX, "cylinder": pb.GEOM_CYLINDER, "capsule": pb.GEOM_CAPSULE}


@dataclass
class Snapshot:
    """The state the environment reads after a control step (world frame, SI units).

    ``q``, ``dq``, ``tau``: (n,) driven joint positions [rad], velocities [rad/s], motor torques [N m],
    in ``SimHand.joints`` order. ``obj_pos`` (3,) [m] and ``obj_quat`` (4,) xyzw: the object frame;
    ``obj_com`` (3,) [m]: the object's centre of mass (what termination, drift and the observation measure:
    a mesh's frame origin may lie centimetres off the object, and it swings round as the object turns);
    ``obj_linvel`` [m/s] (of the centre of mass) and ``obj_angvel`` [rad/s]: (3,) each.
    """

    q: np.ndarray
    dq: np.ndarray
    tau: np.ndarray
    obj_pos: np.ndarray
    obj_quat: np.ndarray
    obj_linvel: np.ndarray
    obj_angvel: np.ndarray
    obj_com: np.ndarray


def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array([aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz])


def yaw_quat(yaw: float) -> np.ndarray:
    """xyzw quaternion of a rotation by ``yaw`` rad about world +z."""
    return np.array([0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)])


class RotationScene:
    """PyBullet DIRECT world holding the palm-up hand and the object (see module doc)."""

    def __init__(self, hand: SimHand, obj: ObjectShape, cfg: RotationConfig, palm_radius: float,
                 visual: bool = False):
        self.hand, self.obj, self.cfg, self.visual = hand, obj, cfg, visual
        qi = np.asarray(obj.inertia_quat, dtype=float)
        self._turned_inertia = not np.allclose(np.abs(qi), [0.0, 0.0, 0.0, 1.0], atol=1e-12)
        self._inertia_conj = np.array([-qi[0], -qi[1], -qi[2], qi[3]])
        self.palm_radius = float(palm_radius)  # m, of the hand's canonical params (places the object)
        self.client = c = pb.connect(pb.DIRECT)
        pb.setGravity(0.0, 0.0, -cfg.gravity, physicsClientId=c)
        pb.setPhysicsEngineParameter(fixedTimeStep=cfg.sim_dt, numSubSteps=1,
                                     numSolverIterations=int(cfg.solver_iterations), deterministicOverlappingPairs=1,
                                     physicsClientId=c)
        self._load_hand()
        self._make_object_shape()
        self.obj_body: int | None = None
        self._substeps = cfg.substeps

    # -- hand -----------------------------------------------------------------------------------
    def _load_hand(self) -> None:
        c, h, cfg = self.client, self.hand, self.cfg
        flags = pb.URDF_USE_INERTIA_FROM_FILE | pb.URDF_MERGE_FIXED_LINKS
        if cfg.self_collision:
            flags |= pb.URDF_USE_SELF_COLLISION
        if not self.visual:
            flags |= pb.URDF_IGNORE_VISUAL_SHAPES
        self.T_world_root = T_WORLD_PALM @ h.T_palm_root
        loaded = load_hand(h, fill_inertials(h.urdf), flags, cfg.friction, c, joint_damping=cfg.joint_damping)
        self.body = b = loaded.body
        self.links, self.mimic, self.link_finger = loaded.links, loaded.mimic, loaded.link_finger
        self.jidx = loaded.jidx
        # loadURDF places the base by its inertial frame's origin only when no pose is given; set the link frame
        d = pb.getDynamicsInfo(b, -1, physicsClientId=c)
        Ti = np.eye(4)
        Ti[:3, :3] = np.reshape(pb.getMatrixFromQuaternion(d[4]), (3, 3))
        Ti[:3, 3] = d[3]
        T = self.T_world_root @ Ti
        pb.resetBasePositionAndOrientation(b, T[:3, 3].tolist(), _matrix_to_quat(T[:3, :3]), physicsClientId=c)
        n = len(self.jidx)
        self._forces = [float(cfg.motor_force)] * n
        self._kp = [float(cfg.position_gain)] * n
        self._kd = [float(cfg.velocity_gain)] * n
        self.palm_top = self._palm_height()

    def set_hand(self, q: np.ndarray) -> None:
        """Joint positions ``q`` (sim order) at rest, motors holding them, fresh hand contact caches."""
        c, b = self.client, self.body
        for k, j in enumerate(self.jidx):
            pb.resetJointState(b, j, float(q[k]), 0.0, physicsClientId=c)
        for j, m, mul, off in self.mimic:
            pb.resetJointState(b, j, mul * float(q[m]) + off, 0.0, physicsClientId=c)
        for j, _ in self.links:  # re-adding every link collider drops its cached contact manifolds
            group, mask = _mask_of(self.link_finger[j])
            pb.setCollisionFilterGroupMask(b, j, group, mask, physicsClientId=c)
        self.drive(q)

    def drive(self, target: np.ndarray) -> None:
        """Position-motor targets (sim order, rad) held through the next control step.

        PyBullet's position motor is a velocity constraint solved implicitly with the contacts (a
        stiff PD servo that cannot go unstable), pushing with at most ``motor_force``; a joint
        blocked by the object therefore presses with the whole cap. An explicit PD torque
        (HORA's kp 3 N m/rad, kd 0.1 N m s/rad) diverges at this step on ~30 g links (measured:
        joint speeds hit PyBullet's 100 rad/s clamp within one control step, even at kp 0.5).
        """
        c, b = self.client, self.body
        pb.setJointMotorControlArray(b, self.jidx, pb.POSITION_CONTROL, targetPositions=[float(x) for x in target],
                                     forces=self._forces, positionGains=self._kp, velocityGains=self._kd,
                                     physicsClientId=c)
        for j, m, mul, off in self.mimic:
            pb.setJointMotorControl2(b, j, pb.POSITION_CONTROL, targetPosition=mul * float(target[m]) + off,
                                     force=self._forces[0], positionGain=self._kp[0], velocityGain=self._kd[0],
                                     physicsClientId=c)

    def _palm_height(self) -> float:
        """World z [m] of the palm surface under the palm centre, by a ray cast down onto the hand.

        Cast right after loading, before :meth:`set_hand` gives the links collision filters that a
        ray (group 1) does not pass. The joints are at 0 clipped into their limits (fingers stretched
        along the palm, none over its centre).
        """
        c, b = self.client, self.body
        q0 = np.clip(0.0, self.hand.lower, self.hand.upper)
        for k, j in enumerate(self.jidx):
            pb.resetJointState(b, j, float(q0[k]), 0.0, physicsClientId=c)
        p = self.palm_centre_world()
        pb.performCollisionDetection(physicsClientId=c)  # the ray uses the broadphase bounds: bring them up to date
        hit = pb.rayTest([p[0], p[1], 1.0], [p[0], p[1], -1.0], physicsClientId=c)[0]
        if hit[0] != b:
            hint = ("" if self.hand.canonical else "; on an original URDF whose palm collision mesh is missing, simulate "
                    "it with the canonical collision shapes: collisions=\"canonical\" (--set 'collisions=\"canonical\"')")
            raise SceneError(f"{self.hand.name}: the ray down the palm centre hits no collision shape of the hand (no "
                             f"palm to rest the object on){hint}")
        return float(hit[3][2])

    def palm_centre_world(self) -> np.ndarray:
        """(3,) world position of the palm disc's centre, palm-frame ``(0, 0, palm_radius)``."""
        return R_WORLD_PALM @ np.array([0.0, 0.0, self.palm_radius])

    # -- object ---------------------------------------------------------------------------------
    def _make_object_shape(self) -> None:
        c, prims = self.client, self.obj.prims
        if not prims:
            self._make_mesh_shape()
            return
        kw = dict(radii=[p["size"][0] if p["type"] != "box" else 0.0 for p in prims],
                  halfExtents=[list(p["size"]) if p["type"] == "box" else [0.0, 0.0, 0.0] for p in prims],
                  lengths=[p["size"][1] if p["type"] in ("cylinder", "capsule") else 0.0 for p in prims],
                  physicsClientId=c)
        kinds = [_PRIM[p["type"]] for p in prims]
        pos = [(np.asarray(p["pos"]) - self.obj.com).tolist() for p in prims]  # link frame = centre of mass
        self.obj_shape = pb.createCollisionShapeArray(kinds, collisionFramePositions=pos, **kw)
        self.obj_visual = -1
        if self.visual:
            self.obj_visual = pb.createVisualShapeArray(kinds, visualFramePositions=pos,
                                                        rgbaColors=[[0.85, 0.63, 0.4, 1.0]] * len(prims), **kw)

    def _make_mesh_shape(self) -> None:
        """Collision shape of an object without primitives: its convex pieces, link frame at the centre of mass."""
        c, o = self.client, self.obj
        pieces = [p.copy() for p in o.pieces]
        for p in pieces:
            p.apply_translation(-o.com)
        self.obj_shape = convex_pieces_shape(pieces, c)
        self.obj_visual = -1
        if self.visual:
            m = o.mesh
            self.obj_visual = pb.createVisualShape(pb.GEOM_MESH, vertices=(np.asarray(m.vertices) - o.com).tolist(),
                                                   indices=np.asarray(m.faces).reshape(-1).tolist(),
                                                   rgbaColor=[0.85, 0.63, 0.4, 1.0], physicsClientId=c)

    def new_object(self, pos: np.ndarray, quat: np.ndarray, fixed: bool = False) -> None:
        """A fresh object body with its frame at ``pos`` (world, m) and ``quat`` (xyzw), at rest."""
        c, o = self.client, self.obj
        if self.obj_body is not None:
            pb.removeBody(self.obj_body, physicsClientId=c)
        R = np.reshape(pb.getMatrixFromQuaternion([float(x) for x in quat]), (3, 3))
        com = np.asarray(pos, dtype=float) + R @ o.com
        # the inertial frame turned onto the principal axes; PyBullet then reports that frame's pose (read())
        b = pb.createMultiBody(0.0 if fixed else o.mass, self.obj_shape, self.obj_visual, com.tolist(),
                               [float(x) for x in quat], baseInertialFramePosition=[0.0, 0.0, 0.0],
                               baseInertialFrameOrientation=[float(x) for x in o.inertia_quat], physicsClientId=c)
        mu = math.sqrt(self.cfg.friction)
        # collisionMargin 0 for convex meshes: PyBullet would inflate them by 1 mm (primitives include theirs)
        pb.changeDynamics(b, -1, lateralFriction=mu, spinningFriction=0.0, rollingFriction=0.0, restitution=0.0,
                          linearDamping=0.0, angularDamping=0.0, physicsClientId=c,
                          **({} if o.prims else {"collisionMargin": 0.0}))
        if not fixed:
            pb.changeDynamics(b, -1, localInertiaDiagonal=o.inertia.tolist(), physicsClientId=c)
        pb.setCollisionFilterGroupMask(b, -1, OBJECT_BIT, PALM_BIT | FINGER_BITS, physicsClientId=c)
        self.obj_body = b

    # -- stepping and reading -------------------------------------------------------------------
    def step(self) -> None:
        """One control step (``substeps`` physics sub-steps; see the module doc)."""
        for _ in range(self._substeps):
            pb.stepSimulation(physicsClientId=self.client)

    def read(self) -> Snapshot:
        c = self.client
        js = pb.getJointStates(self.body, self.jidx, physicsClientId=c)
        q, dq, tau = np.array([(s[0], s[1], s[3]) for s in js]).T
        p, quat = pb.getBasePositionAndOrientation(self.obj_body, physicsClientId=c)
        v, w = pb.getBaseVelocity(self.obj_body, physicsClientId=c)
        quat = np.asarray(quat)
        if self._turned_inertia:  # PyBullet reports the inertial frame: back to the object frame
            quat = _quat_mul(quat, self._inertia_conj)
        com = pos = np.asarray(p)  # the body's base frame is its centre of mass (new_object)
        if self.obj.com.any():
            R = np.reshape(pb.getMatrixFromQuaternion(quat.tolist()), (3, 3))
            pos = pos - R @ self.obj.com
        return Snapshot(q, dq, tau, pos, quat, np.asarray(v), np.asarray(w), com)

    def com_world(self, pos: np.ndarray, quat: np.ndarray) -> np.ndarray:
        """(3,) world position [m] of the centre of mass of the object whose frame is at ``pos``, ``quat`` (xyzw)."""
        R = np.reshape(pb.getMatrixFromQuaternion([float(x) for x in quat]), (3, 3))
        return np.asarray(pos, dtype=float) + R @ np.asarray(self.obj.com, dtype=float)

    def hand_contacts(self) -> int:
        """Number of distinct hand links touching the object now."""
        pts = pb.getContactPoints(self.body, self.obj_body, physicsClientId=self.client)
        return len({p[3] for p in pts})

    def close(self) -> None:
        if self.client is not None and pb.isConnected(self.client):
            pb.disconnect(self.client)
        self.client = None


def fill_inertials(urdf: str) -> str:
    """URDF text where every link without ``<inertial>`` gets the canonical template's dummy inertial.

    PyBullet gives such a link 1 kg and a 1 kg m^2 inertia (and merging fixed links adds that to the
    parent): an original LEAP fingertip became a 1 kg, 1 kg m^2 body whose motor could barely turn it.
    Frame-only links are meant to be massless; the canonical URDFs give them
    ``DUMMY_MASS``/``DUMMY_INERTIA`` (1 g, 1e-8 kg m^2), and so does this.
    """
    from ohra.canonical.urdfgen import DUMMY_INERTIA, DUMMY_MASS

    root = ET.fromstring(urdf)
    changed = False
    for link in root.iter("link"):
        if link.find("inertial") is None:
            inertial = ET.SubElement(link, "inertial")
            ET.SubElement(inertial, "origin", xyz="0 0 0", rpy="0 0 0")
            ET.SubElement(inertial, "mass", value=repr(DUMMY_MASS))
            ET.SubElement(inertial, "inertia", ixx=repr(DUMMY_INERTIA), ixy="0", ixz="0", iyy=repr(DUMMY_INERTIA),
                          iyz="0", izz=repr(DUMMY_INERTIA))
            changed = True
    return ET.tostring(root, encoding="unicode") if changed else urdf


def _matrix_to_quat(R: np.ndarray) -> list[float]:
    from ohra.rotations import matrix_to_quat

    return [float(x) for x in matrix_to_quat(R)]
