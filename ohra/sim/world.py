"""One PyBullet world holding a hand and an object, reused for many grasps.

Reuse without cross-talk: the hand is loaded once; before every grasp its joints, velocities and
motors are reset, its links' collision filters are re-applied (PyBullet removes and re-adds a
collision object when its filter changes, which drops every cached contact manifold and its
warm-start impulses), and the object is a fresh body built from collision shapes made once. A
grasp therefore starts from the same state whatever ran before it (tests compare outcomes bit for
bit across orders, batches and worker counts). ``saveState``/``restoreState`` is not used: it
keeps the contact caches, so outcomes would depend on the previous grasp.

Collision filtering (reference shape filters): every hand link gets the group bit of its finger
(palm and other non-finger links: a palm bit); a finger link collides with the object and with the
other fingers, never with its own finger or the palm; the palm collides with the object only.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import numpy as np
import pybullet as pb

from ohra.sim.bullet import convex_pieces_shape, load_hand
from ohra.sim.controller import closes_positive
from ohra.objects.model import ObjectModel
from ohra.rotations import matrix_to_quat, quat_to_matrix
from ohra.sim.hands import SimHand
from ohra.sim.protocol import Protocol

PALM_BIT = 1 << 5
OBJECT_BIT = 1 << 6
FINGER_BITS = 0b11111


def _mask_of(finger: int) -> tuple[int, int]:
    if finger < 0:
        return PALM_BIT, OBJECT_BIT
    bit = 1 << finger
    return bit, OBJECT_BIT | (FINGER_BITS & ~bit)


class World:
    """PyBullet DIRECT world: the hand (fixed base) and the object (free, at the origin)."""

    def __init__(self, hand: SimHand, obj: ObjectModel, protocol: Protocol):
        self.hand, self.obj, self.protocol = hand, obj, protocol
        self._twin: World | None = None  # the canonical twin's world (squeeze directions of an original hand)
        self.client = pb.connect(pb.DIRECT)
        c = self.client
        pb.setGravity(0, 0, 0, physicsClientId=c)
        pb.setTimeStep(protocol.dt, physicsClientId=c)
        pb.setPhysicsEngineParameter(numSubSteps=int(protocol.substeps), numSolverIterations=int(protocol.solver_iterations),
                                     solverResidualThreshold=float(protocol.solver_residual_threshold),
                                     deterministicOverlappingPairs=1, physicsClientId=c)
        self._load_hand()
        self._make_object_shape()
        self.obj_body: int | None = None

    # -- hand ------------------------------------------------------------------------------------
    def _load_hand(self) -> None:
        c, h, prot = self.client, self.hand, self.protocol
        flags = pb.URDF_USE_SELF_COLLISION | pb.URDF_IGNORE_VISUAL_SHAPES | pb.URDF_USE_INERTIA_FROM_FILE
        if prot.merge_fixed_links:
            flags |= pb.URDF_MERGE_FIXED_LINKS
        loaded = load_hand(h, h.urdf, flags, prot.friction, c, joint_damping=prot.urdf_joint_damping)
        self.body = b = loaded.body
        self.links: list[tuple[int, str]] = loaded.links
        self.root_link = self.links[0][1]
        self.jidx = np.array(loaded.jidx, dtype=int)
        self.mimic, self.link_finger = loaded.mimic, loaded.link_finger
        # axes of the driven joints in their child link frames (PyBullet: joint frame == child link frame)
        self.axes = np.array([pb.getJointInfo(b, int(j), physicsClientId=c)[13] for j in self.jidx], dtype=float)
        self.base_inertial = self._local_inertial(b, -1)
        self.reach = self._reach()

    def _local_inertial(self, body: int, link: int) -> np.ndarray:
        """(4,4) inertial frame in the link frame (PyBullet places a base by its inertial frame)."""
        d = pb.getDynamicsInfo(body, link, physicsClientId=self.client)
        T = np.eye(4)
        T[:3, :3] = quat_to_matrix(d[4])
        T[:3, 3] = d[3]
        return T

    def _reach(self) -> float:
        """Upper bound on the distance of any hand point from the root origin, over all joint values.

        Chain bound: a link frame is at most (parent bound + |joint offset|) from the root; its
        geometry adds at most the farthest corner of its bounding box from its frame origin.
        """
        root = ET.fromstring(self.hand.urdf)
        parent = {j.find("child").get("link"): j for j in root.iter("joint")}
        bound: dict[str, float] = {}

        def frame_bound(link: str) -> float:
            if link not in bound:
                j = parent.get(link)
                if j is None:
                    bound[link] = 0.0
                else:
                    o = j.find("origin")
                    xyz = np.array([float(x) for x in (o.get("xyz", "0 0 0") if o is not None else "0 0 0").split()])
                    extra = 0.0
                    if j.get("type") == "prismatic":
                        lim = j.find("limit")
                        extra = max(abs(float(lim.get("lower", 0))), abs(float(lim.get("upper", 0)))) if lim is not None else 0.0
                    bound[link] = frame_bound(j.find("parent").get("link")) + float(np.linalg.norm(xyz)) + extra
            return bound[link]

        c, b = self.client, self.body
        pb.resetBasePositionAndOrientation(b, self.base_inertial[:3, 3].tolist(), matrix_to_quat(self.base_inertial[:3, :3]).tolist(), physicsClientId=c)
        reach = 0.0
        for j, name in self.links:
            lo, hi = (np.array(v) for v in pb.getAABB(b, j, physicsClientId=c))
            if j < 0:
                origin = np.zeros(3)
            else:
                origin = np.array(pb.getLinkState(b, j, computeForwardKinematics=1, physicsClientId=c)[4])
            corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
            extent = float(np.linalg.norm(corners - origin, axis=1).max())
            # merged links hang their geometry on the surviving link: their chain is inside the extent
            reach = max(reach, frame_bound(name) + extent)
        return reach

    def set_hand_pose(self, T_world_root: np.ndarray) -> None:
        T = T_world_root @ self.base_inertial
        pb.resetBasePositionAndOrientation(self.body, T[:3, 3].tolist(), matrix_to_quat(T[:3, :3]).tolist(), physicsClientId=self.client)

    def reset_hand(self, T_world_root: np.ndarray, q: np.ndarray) -> None:
        """Pose, joint values (zero velocity) and fresh contact caches for the hand."""
        c, b = self.client, self.body
        self.set_hand_pose(T_world_root)
        self.set_joints(q)
        for j, _ in self.links:  # re-adding every link collider drops its cached contact manifolds
            group, mask = _mask_of(self.link_finger[j])
            pb.setCollisionFilterGroupMask(b, j, group, mask, physicsClientId=c)

    def set_joints(self, q: np.ndarray) -> None:
        c, b = self.client, self.body
        for k, j in enumerate(self.jidx):
            pb.resetJointState(b, int(j), float(q[k]), 0.0, physicsClientId=c)
        for j, m, mul, off in self.mimic:
            pb.resetJointState(b, j, mul * float(q[m]) + off, 0.0, physicsClientId=c)

    def drive_joints(self, target: np.ndarray) -> None:
        c, b, p = self.client, self.body, self.protocol
        # PyBullet caps a motor's impulse at force x (full step dt) in *every* substep, so with
        # numSubSteps = n the torque limit is effectively n x force (measured: a 0.5 N m motor
        # accelerates a test link twice as fast at 2 substeps): divide to keep the stated limit
        force = p.motor_force / int(p.substeps)
        for k, j in enumerate(self.jidx):
            pb.setJointMotorControl2(b, int(j), pb.POSITION_CONTROL, targetPosition=float(target[k]), targetVelocity=0.0,
                                     force=force, positionGain=p.position_gain, velocityGain=p.velocity_gain,
                                     physicsClientId=c)
        for j, m, mul, off in self.mimic:
            pb.setJointMotorControl2(b, j, pb.POSITION_CONTROL, targetPosition=mul * float(target[m]) + off, targetVelocity=0.0,
                                     force=force, positionGain=p.position_gain, velocityGain=p.velocity_gain,
                                     physicsClientId=c)

    def joint_values(self) -> np.ndarray:
        return np.array([s[0] for s in pb.getJointStates(self.body, self.jidx.tolist(), physicsClientId=self.client)])

    def joint_frames(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """World (axis, link direction, origin) of every driven joint's child link frame.

        The link direction is the frame's +z (the reference's assumption, true of canonical links),
        except where +z lies along the joint axis (``|axis . z| > 0.9``, e.g. Inspire's links, which
        extend along -y and turn about z): there +z says nothing about which way the link swings, so
        the direction from the joint to the link's centre of mass is used instead.
        """
        states = pb.getLinkStates(self.body, self.jidx.tolist(), computeForwardKinematics=1, physicsClientId=self.client)
        pos = np.array([s[4] for s in states])
        com = np.array([s[0] for s in states])
        R = quat_to_matrix(np.array([s[5] for s in states]))
        axis, z = np.einsum("kij,kj->ki", R, self.axes), R[:, :, 2].copy()
        to_com = com - pos
        along = np.abs((axis * z).sum(axis=1)) > 0.9
        along &= np.linalg.norm(to_com, axis=1) > 1e-6
        z[along] = to_com[along] / np.linalg.norm(to_com[along], axis=1, keepdims=True)
        return axis, z, pos

    # -- object ----------------------------------------------------------------------------------
    def _make_object_shape(self) -> None:
        c, o, prot = self.client, self.obj, self.protocol
        pieces = o.convex_pieces()
        if o.primitives:
            kinds = {"sphere": pb.GEOM_SPHERE, "box": pb.GEOM_BOX, "cylinder": pb.GEOM_CYLINDER, "capsule": pb.GEOM_CAPSULE}
            prims = o.primitives
            self.obj_shape = pb.createCollisionShapeArray(
                [kinds[p["type"]] for p in prims],
                radii=[p["size"][0] if p["type"] != "box" else 0.0 for p in prims],
                halfExtents=[list(p["size"]) if p["type"] == "box" else [0.0, 0.0, 0.0] for p in prims],
                lengths=[p["size"][1] if p["type"] in ("cylinder", "capsule") else 0.0 for p in prims],
                collisionFramePositions=[list(p["pos"]) for p in prims],
                collisionFrameOrientations=[[0, 0, 0, 1]] * len(prims), physicsClientId=c)
        else:
            self.obj_shape = convex_pieces_shape(pieces, c)
        self.mass = o.volume * prot.density
        I = np.asarray(o.inertia, dtype=float) / o.density * prot.density  # about the COM, mesh axes
        w, V = np.linalg.eigh(0.5 * (I + I.T))
        if np.linalg.det(V) < 0:
            V[:, 0] *= -1
        self.obj_inertia_diag = np.maximum(w, 1e-12)
        self.obj_inertial = np.eye(4)
        self.obj_inertial[:3, :3] = V
        self.obj_inertial[:3, 3] = o.center_mass

    def new_object(self) -> int:
        """Remove the previous object body and create a fresh one at the origin (mesh frame = world)."""
        c = self.client
        if self.obj_body is not None:
            pb.removeBody(self.obj_body, physicsClientId=c)
        Ti = self.obj_inertial
        b = pb.createMultiBody(self.mass, self.obj_shape, -1, [0, 0, 0], [0, 0, 0, 1], 
                               baseInertialFramePosition=Ti[:3, 3].tolist(),
                               baseInertialFrameOrientation=matrix_to_quat(Ti[:3, :3]).tolist(), physicsClientId=c)
        mu = math.sqrt(self.protocol.friction)
        # collisionMargin 0: PyBullet inflates convex meshes by a 1 mm margin, which would make the
        # simulated object larger than the body the solver grasped (primitives include their margin)
        pb.changeDynamics(b, -1, lateralFriction=mu, spinningFriction=0.0, rollingFriction=0.0, restitution=0.0,
                          linearDamping=0.0, angularDamping=0.0, localInertiaDiagonal=self.obj_inertia_diag.tolist(),
                          collisionMargin=0.0, physicsClientId=c)
        pb.setCollisionFilterGroupMask(b, -1, OBJECT_BIT, PALM_BIT | FINGER_BITS, physicsClientId=c)
        self.obj_body = b
        return b

    def object_frame(self) -> np.ndarray:
        """(4,4) world pose of the object's mesh frame (PyBullet reports the inertial frame)."""
        pos, orn = pb.getBasePositionAndOrientation(self.obj_body, physicsClientId=self.client)
        T = np.eye(4)
        T[:3, :3] = quat_to_matrix(orn)
        T[:3, 3] = pos
        return T @ np.linalg.inv(self.obj_inertial)

    def object_com(self) -> tuple[np.ndarray, np.ndarray]:
        c = self.client
        pos, _ = pb.getBasePositionAndOrientation(self.obj_body, physicsClientId=c)
        v, _ = pb.getBaseVelocity(self.obj_body, physicsClientId=c)
        return np.asarray(pos), np.asarray(v)

    def closes_positive(self, T_world_palm: np.ndarray, q_canonical: np.ndarray, toward: np.ndarray | None) -> np.ndarray:
        """(J,) bool per driven joint: a positive rotation closes it onto ``toward`` (world; None: the origin), by the
        reference rule (:func:`~ohra.sim.controller.closes_positive`) on the hand's own joint frames as they stand,
        or, for a hand with a canonical twin (``SimHand.squeeze_reference``), on the twin posed at the same grasp
        (``q_canonical``, (22,)) and mapped through the action map's signs."""
        ref = self.hand.squeeze_reference
        if ref is None:
            return closes_positive(*self.joint_frames(), toward)
        if self._twin is None:  # one more DIRECT client per world, made on first use
            self._twin = World(ref, self.obj, self.protocol)
        qr = ref.project_sim(np.clip(ref.to_sim(np.clip(q_canonical, ref.canon_lower, ref.canon_upper)), ref.lower, ref.upper))
        self._twin.set_hand_pose(T_world_palm @ ref.T_palm_root)
        self._twin.set_joints(qr)
        idx, flip = self.hand.squeeze_map()
        return closes_positive(*self._twin.joint_frames(), toward)[idx] ^ flip

    def close(self) -> None:
        if self._twin is not None:
            self._twin.close()
            self._twin = None
        if self.client is not None and pb.isConnected(self.client):
            pb.disconnect(self.client)
        self.client = None
