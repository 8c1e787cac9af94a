"""Kinematics and collision geometry of a canonical hand.

(Over 400 lines because the numpy batch FK must walk exactly the tree the Pinocchio model is built
from; they are kept side by side so a change to one is seen in the other.)

:class:`HandModel` wraps a Pinocchio model of a canonical URDF (the reference implementation for
single configurations and Jacobians), a vectorised numpy forward kinematics over the same
kinematic tree for batches of configurations, and Coal capsule geometry for collision queries.

Why two forward-kinematics paths here (the package has two more: CasADi expressions for the grasp
NLP in ``ohra.synth.fk`` and ``canonical_keypoints`` from parameter arrays for the parse fit):
Pinocchio is the reference and the fastest for one configuration; on batches its per-call Python
overhead dominates, and the numpy path evaluates 4096 configurations about 5x faster (also about 6x
faster than evaluating the CasADi expressions numerically; ``benchmarks/results/fk_paths.md``).
Batches are what the synthesiser's finger-pair reach, the dataset distance checks and the samplers
use. ``tests/test_fk_paths.py`` holds every path to Pinocchio to 1e-9 m.

All poses are 4x4 homogeneous matrices in the canonical palm frame (the URDF root; +x palm normal,
+y thumb side of a right hand, +z finger-forward), in metres. Configurations are always the 22-D
canonical joint vector (``ohra.canonical.params.JOINT_NAMES`` order) in radians; absent joints must be 0.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Iterable, Sequence

import coal
import numpy as np
import pinocchio as pin

from ohra.errors import OhraError, is_finite_real, require_seed
from ohra.canonical.params import FINGERS, JOINT_NAMES, BaseParams, ExtendedParams, Params, load_params, require_params
from ohra.canonical.urdfgen import palm_geometry, render
from ohra.transforms import axis_angle_to_matrix

SEGMENTS = ("proximal", "middle", "distal")


@dataclass(frozen=True)
class Capsules:
    """Finger capsules at one configuration (K capsules) or a batch (leading N axis on p0/p1).

    ``p0``/``p1`` are the centres of the two end spheres (the capsule's core segment) in the palm
    frame [m]; ``radius`` [m]; ``link`` the link name and ``finger`` the finger index (0 thumb .. 4 little).
    """

    p0: np.ndarray
    p1: np.ndarray
    radius: np.ndarray
    link: tuple[str, ...]
    finger: np.ndarray


@dataclass(frozen=True)
class _Tree:
    """The kinematic tree in a form numpy (and CasADi) can evaluate.

    ``joint_parent[j]`` is the index of the parent joint (-1 for the root), ``joint_placement[j]`` the
    fixed 4x4 transform from the parent joint frame to joint j at q=0, ``joint_axis[j]`` its unit
    axis in its own frame and ``joint_q[j]`` its index in the canonical 22-vector. Frames (links, tips)
    hang off a joint with a fixed placement.
    """

    joint_names: tuple[str, ...]
    joint_parent: np.ndarray
    joint_placement: np.ndarray
    joint_axis: np.ndarray
    joint_q: np.ndarray
    frame_names: tuple[str, ...]
    frame_joint: np.ndarray
    frame_placement: np.ndarray


def _joint_axis(jm: pin.JointModel) -> np.ndarray:
    short = jm.shortname()
    if short in ("JointModelRX", "JointModelRY", "JointModelRZ"):
        return np.eye(3)["XYZ".index(short[-1])]
    if short == "JointModelRevoluteUnaligned":
        return np.asarray(jm.extract().axis, dtype=float)
    raise OhraError(f"unsupported joint type {short} in canonical hand model")


class HandModel:
    """Kinematics (Pinocchio + batched numpy) and capsule collision geometry of a canonical hand."""

    def __repr__(self) -> str:
        fingers = [f for f in ("thumb", "index", "middle", "ring", "little")
                   if any(n.startswith(f + "_") and m for n, m in zip(JOINT_NAMES, self.movable_joints))]
        return f"HandModel(dof={int(self.movable_joints.sum())}, fingers={fingers}, form={type(self.params).__name__ if self.params is not None else None})"

    def __init__(self, urdf: str, params: Params | None = None):
        self.urdf = urdf
        self.params = params
        try:
            self.model: pin.Model = pin.buildModelFromXML(urdf)
        except Exception as exc:  # pinocchio raises plain ValueError/RuntimeError
            raise OhraError(f"Pinocchio cannot load the canonical URDF: {exc}") from None
        self.data: pin.Data = self.model.createData()
        missing = [n for n in JOINT_NAMES if not self.model.existJointName(n)]
        if missing or self.model.nq != 22:
            raise OhraError(f"not a canonical hand URDF: nq={self.model.nq}, missing joints {missing}")
        # canonical index -> pinocchio q index
        self._pin_q = np.array([self.model.joints[self.model.getJointId(n)].idx_q for n in JOINT_NAMES])
        self._perm = np.argsort(self._pin_q)  # pinocchio q index -> canonical index
        self.lower = np.array(self.model.lowerPositionLimit)[self._pin_q]
        self.upper = np.array(self.model.upperPositionLimit)[self._pin_q]
        self.present_joints = (self.lower != 0.0) | (self.upper != 0.0)
        self.movable_joints = self.upper > self.lower
        self.frame_names: tuple[str, ...] = tuple(
            f.name for f in self.model.frames if f.type == pin.FrameType.BODY
        )
        self._frame_id = {n: self.model.getFrameId(n, pin.FrameType.BODY) for n in self.frame_names}
        self.tip_names: tuple[str, ...] = tuple(f"{f}_tip" for f in FINGERS if f"{f}_tip" in self._frame_id)
        self.present_fingers = np.array([f"{f}_tip" in self._frame_id for f in FINGERS])
        self.tree = self._build_tree()
        # index of the basis axis (0, 1, 2) of each joint when it is +-x, +-y or +-z, else -1
        self._aligned = [
            int(np.argmax(np.abs(a))) if np.isclose(np.abs(a).max(), 1.0, rtol=0, atol=1e-12) else -1
            for a in self.tree.joint_axis
        ]

    # -- construction --------------------------------------------------------------------------
    @classmethod
    def from_params(cls, params: Params) -> "HandModel":
        """Model of the canonical hand rendered from ``params`` (:func:`~ohra.canonical.urdfgen.render`).

        Args:
            params: base or extended params; kept for the capsule and palm geometry.

        Raises:
            ParamsError: ``params`` is not :class:`BaseParams` or :class:`ExtendedParams`.
        """
        require_params(params)
        return cls(render(params), params)

    @classmethod
    def from_urdf(cls, path: str | Path, params: Params | None = None) -> "HandModel":
        """Model from a canonical URDF file.

        Args:
            path: a URDF written by :func:`~ohra.canonical.urdfgen.write` (22 canonical joints).
            params: the params it was rendered from; without them the kinematics work but capsule,
                palm and collision queries raise :class:`OhraError`.

        Raises:
            OhraError: the file is missing, Pinocchio cannot load it, or it lacks canonical joints.
        """
        p = Path(path)
        if not p.is_file():
            raise OhraError(f"canonical URDF not found: {p}")
        return cls(p.read_text(), params)

    @classmethod
    def from_json(cls, path: str | Path) -> "HandModel":
        return cls.from_params(load_params(path))

    def _build_tree(self) -> _Tree:
        m = self.model
        names, parents, placements, axes, qidx = [], [], [], [], []
        jid_to_tree = {0: -1}
        for jid in range(1, m.njoints):
            jid_to_tree[jid] = len(names)
            names.append(m.names[jid])
            parents.append(jid_to_tree[m.parents[jid]])
            placements.append(m.jointPlacements[jid].homogeneous)
            axes.append(_joint_axis(m.joints[jid]))
            qidx.append(JOINT_NAMES.index(m.names[jid]))
        f_names, f_joint, f_place = [], [], []
        for n in self.frame_names:
            fr = m.frames[self._frame_id[n]]
            f_names.append(n)
            f_joint.append(jid_to_tree[fr.parentJoint])
            f_place.append(fr.placement.homogeneous)
        return _Tree(
            tuple(names), np.array(parents), np.array(placements), np.array(axes), np.array(qidx),
            tuple(f_names), np.array(f_joint), np.array(f_place),
        )

    # -- configurations ------------------------------------------------------------------------
    @property
    def nq(self) -> int:
        return 22

    def check_q(self, q: np.ndarray) -> np.ndarray:
        """Validate a (22,) or (N,22) configuration; returns it as a float array."""
        try:
            q = np.asarray(q, dtype=float)
        except (TypeError, ValueError):
            raise OhraError(f"expected a canonical configuration of 22 joint angles [rad], got {type(q).__name__} of "
                            "non-numbers") from None
        if q.shape[-1:] != (22,) or q.ndim > 2:
            raise OhraError(f"expected a canonical configuration of shape (22,) or (N, 22), got {q.shape}")
        if not np.all(np.isfinite(q)):
            raise OhraError("configuration contains NaN or inf")
        return q

    def _check_one_q(self, q: np.ndarray, method: str) -> np.ndarray:
        """:meth:`check_q` for methods that take one configuration: a batch is an error naming both shapes."""
        q = self.check_q(q)
        if q.ndim != 1:
            hint = "use frame_poses for batches" if method == "frame_pose" else "call it once per configuration"
            raise OhraError(f"{method} takes one configuration of shape (22,), got {q.shape}; {hint}")
        return q

    def clamp(self, q: np.ndarray) -> np.ndarray:
        """Clip to the joint limits (absent joints to 0)."""
        return np.clip(self.check_q(q), self.lower, self.upper)

    def neutral(self) -> np.ndarray:
        """Zero clamped into the limits (the reference's initial q)."""
        return np.clip(np.zeros(22), self.lower, self.upper)

    def random_configurations(self, n: int, seed: int = 0) -> np.ndarray:
        """Configurations drawn uniformly within the joint limits (absent joints 0).

        Args:
            n: number of configurations.
            seed: seed of ``numpy.random.default_rng``; same seed, same configurations.

        Returns:
            (n, 22) joint angles [rad], canonical joint order.

        Raises:
            OhraError: ``n`` is not a whole number >= 0; ``seed`` not a whole number >= 0.
        """
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 0:
            raise OhraError(f"random_configurations: n must be a whole number >= 0, got {n!r}")
        rng = np.random.default_rng(require_seed(seed, OhraError, "random_configurations: seed"))
        return self.lower + rng.random((int(n), 22)) * (self.upper - self.lower)

    def _to_pin(self, q: np.ndarray) -> np.ndarray:
        out = np.empty(22)
        out[self._pin_q] = q
        return out

    # -- forward kinematics --------------------------------------------------------------------
    def frame_pose(self, q: np.ndarray, frame: str) -> np.ndarray:
        """Pose of a link or tip frame at one configuration (Pinocchio).

        Args:
            q: (22,) joint angles [rad].
            frame: a name in :attr:`frame_names` (e.g. ``"index_tip"``).

        Returns:
            (4, 4) ``T_palm_frame``: the frame's pose in the palm frame, translation [m].

        Raises:
            OhraError: ``q`` is not (22,) or not finite; unknown ``frame``.
        """
        q = self._check_one_q(q, "frame_pose")
        fid = self._fid(frame)
        pin.forwardKinematics(self.model, self.data, self._to_pin(q))
        return pin.updateFramePlacement(self.model, self.data, fid).homogeneous.copy()

    def frame_poses(self, q: np.ndarray, frames: Sequence[str] | None = None) -> np.ndarray:
        """Poses of ``frames`` in the palm frame; vectorised over the batch, evaluating only the
        joints the requested frames hang from.

        Args:
            q: (22,) or (N, 22) joint angles [rad].
            frames: F names from :attr:`frame_names`; None: all of them, in that order.

        Returns:
            (F, 4, 4) or (N, F, 4, 4) ``T_palm_frame``, translation [m].

        Raises:
            OhraError: ``q`` has the wrong shape or is not finite; an unknown frame.
        """
        q = self.check_q(q)
        single = q.ndim == 1
        if isinstance(frames, str):  # one name, not its letters ("unknown frame 'i'")
            raise OhraError(f"frames: expected a list of frame names, got the string {frames!r}; "
                            f"frame_poses(q, [{frames!r}]) or frame_pose(q, {frames!r})")
        frames = self.frame_names if frames is None else tuple(frames)
        if single:  # one configuration: Pinocchio's C++ FK beats numpy's per-call overhead
            pin.framesForwardKinematics(self.model, self.data, self._to_pin(q))
            oMf = self.data.oMf
            return np.array([oMf[self._fid(f)].homogeneous for f in frames])
        qb = q
        idx = np.array([self.tree.frame_names.index(self._check_frame(f)) for f in frames], dtype=int)
        parent = self.tree.frame_joint[idx]
        R, t = self._joint_poses(qb, self._ancestors(tuple(int(p) for p in parent)))
        Tf = self.tree.frame_placement[idx]
        n = qb.shape[0]
        out = np.zeros((n, len(idx), 4, 4))
        out[..., 3, 3] = 1.0
        for k, pj in enumerate(parent):
            if pj < 0:
                out[:, k] = Tf[k]
                continue
            out[:, k, :3, :3] = R[pj] @ Tf[k, :3, :3]
            out[:, k, :3, 3] = R[pj] @ Tf[k, :3, 3] + t[pj]
        return out

    def _ancestors(self, joints: tuple[int, ...]) -> tuple[int, ...]:
        """The given joints and all their ancestors, in tree (topological) order."""
        need: set[int] = set()
        for j in joints:
            while j >= 0 and j not in need:
                need.add(j)
                j = int(self.tree.joint_parent[j])
        return tuple(sorted(need))

    def _joint_poses(self, qb: np.ndarray, joints: tuple[int, ...]) -> tuple[dict[int, np.ndarray], dict[int, np.ndarray]]:
        """Rotations (N,3,3) and positions (N,3) of joint frames after their own rotation."""
        t = self.tree
        n = qb.shape[0]
        Rs: dict[int, np.ndarray] = {}
        ts: dict[int, np.ndarray] = {}
        for j in joints:  # parents come first: joint indices follow the tree order
            P = t.joint_placement[j]
            pj = int(t.joint_parent[j])
            if pj < 0:
                base_R = np.broadcast_to(P[:3, :3], (n, 3, 3))
                ts[j] = np.broadcast_to(P[:3, 3], (n, 3)).copy()
            else:
                base_R = Rs[pj] @ P[:3, :3]
                ts[j] = Rs[pj] @ P[:3, 3] + ts[pj]
            a = t.joint_axis[j]
            ang = qb[:, t.joint_q[j]]
            c, s = np.cos(ang)[:, None], np.sin(ang)[:, None]
            k = self._aligned[j]
            if k >= 0:
                # rotation about a basis axis: mix the two other columns of the base rotation
                sign = a[k]
                u, v = (k + 1) % 3, (k + 2) % 3
                R = np.empty((n, 3, 3))
                R[:, :, k] = base_R[:, :, k]
                R[:, :, u] = c * base_R[:, :, u] + sign * s * base_R[:, :, v]
                R[:, :, v] = -sign * s * base_R[:, :, u] + c * base_R[:, :, v]
            else:
                R = base_R @ axis_angle_to_matrix(a, ang)
            Rs[j] = R
        return Rs, ts

    def fingertips(self, q: np.ndarray) -> np.ndarray:
        """Fingertip positions (tip frame origins) in the palm frame.

        Args:
            q: (22,) or (N, 22) joint angles [rad].

        Returns:
            (5, 3) or (N, 5, 3) positions [m], thumb .. little; NaN rows for absent fingers.

        Raises:
            OhraError: ``q`` has the wrong shape or is not finite.
        """
        q = self.check_q(q)
        lead = q.shape[:-1]
        out = np.full(lead + (5, 3), np.nan)
        if self.tip_names:
            P = self.frame_poses(q, self.tip_names)[..., :3, 3]
            out[..., self.present_fingers, :] = P
        return out

    def jacobian(self, q: np.ndarray, frame: str) -> np.ndarray:
        """Frame Jacobian at one configuration (Pinocchio ``LOCAL_WORLD_ALIGNED``).

        Args:
            q: (22,) joint angles [rad].
            frame: a name in :attr:`frame_names`.

        Returns:
            (6, 22) ``[linear; angular]`` velocity of ``frame`` per joint velocity, columns in canonical
            joint order: the linear rows [m/rad] are the velocity of the frame origin, and both are
            expressed in palm-frame axes.

        Raises:
            OhraError: ``q`` is not (22,) or not finite; unknown ``frame``.
        """
        q = self._check_one_q(q, "jacobian")
        fid = self._fid(frame)
        qp = self._to_pin(q)
        J = pin.computeFrameJacobian(self.model, self.data, qp, fid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
        return np.asarray(J)[:, self._pin_q]

    @staticmethod
    def _check_pose(T: np.ndarray | None, what: str) -> np.ndarray:
        """A (4, 4) finite pose (None: identity); an :class:`OhraError` naming ``what`` otherwise (a NaN pose gave a
        made-up 3 cm penetration)."""
        if T is None:
            return np.eye(4)
        try:
            T = np.asarray(T, dtype=float)
        except (TypeError, ValueError):
            raise OhraError(f"{what}: expected a (4, 4) homogeneous transform, got {type(T).__name__}") from None
        if T.shape != (4, 4):
            raise OhraError(f"{what}: expected a (4, 4) homogeneous transform, got shape {T.shape}")
        if not np.all(np.isfinite(T)):
            raise OhraError(f"{what} contains NaN or inf")
        return T

    @staticmethod
    def _check_margin(margin: float) -> float:
        if not is_finite_real(margin):
            raise OhraError(f"margin must be a finite distance [m], got {margin!r}")
        return float(margin)

    def _check_frame(self, frame: str) -> str:
        if frame not in self._frame_id:
            raise OhraError(f"unknown frame {frame!r}; known: {', '.join(self.frame_names)}")
        return frame

    def _fid(self, frame: str) -> int:
        return self._frame_id[self._check_frame(frame)]

    # -- capsule geometry ----------------------------------------------------------------------
    @cached_property
    def capsule_specs(self) -> tuple[tuple[str, int, float, float], ...]:
        """(link, finger index, radius, length) of every finger segment that carries geometry."""
        if self.params is None:
            raise OhraError("capsule geometry needs the hand parameters (build with HandModel.from_params)")
        p = self.params
        links = p.link_presence()
        out = []
        for fi, f in enumerate(FINGERS):
            for s, seg in enumerate(SEGMENTS):
                if not links[f][s]:
                    continue
                if isinstance(p, BaseParams):
                    r, L = p.finger_radius, p.finger_lengths[0 if fi == 0 else 1, s]
                else:
                    r, L = p.finger_radii[fi], p.finger_lengths[fi, s]
                out.append((f"{f}_{seg}", fi, float(r), float(L)))
        return tuple(out)

    @property
    def palm(self) -> dict[str, float]:
        """Palm cylinder: radius and depth [m]; axis +x, centre (0, 0, radius) in the palm frame."""
        if self.params is None:
            raise OhraError("palm geometry needs the hand parameters")
        R, depth = palm_geometry(self.params)
        return {"radius": R, "depth": depth}

    def capsules(self, q: np.ndarray) -> Capsules:
        """Finger capsules at ``q`` (one per segment that carries geometry, K in all).

        Args:
            q: (22,) or (N, 22) joint angles [rad].

        Returns:
            :class:`Capsules`: ``p0``/``p1`` (K, 3) or (N, K, 3) end-sphere centres in the palm frame
            [m], ``radius`` (K,) [m], ``link`` and ``finger`` per capsule.

        Raises:
            OhraError: the model has no params; ``q`` has the wrong shape or is not finite.
        """
        specs = self.capsule_specs
        links = [s[0] for s in specs]
        T = self.frame_poses(q, links) if links else np.zeros(np.shape(q)[:-1] + (0, 4, 4))
        r = np.array([s[2] for s in specs])
        L = np.array([s[3] for s in specs])
        a = np.stack([np.zeros_like(r), np.zeros_like(r), r], axis=-1)
        b = np.stack([np.zeros_like(r), np.zeros_like(r), L - r], axis=-1)
        p0 = np.einsum("...kij,kj->...ki", T[..., :3, :3], a) + T[..., :3, 3]
        p1 = np.einsum("...kij,kj->...ki", T[..., :3, :3], b) + T[..., :3, 3]
        return Capsules(p0, p1, r, tuple(links), np.array([s[1] for s in specs], dtype=int))

    # -- Coal collision ------------------------------------------------------------------------
    def collision_objects(self, q: np.ndarray, T_world_palm: np.ndarray | None = None) -> list[tuple[str, int, coal.CollisionObject]]:
        """Coal objects (name, finger index or -1 for the palm, object) of the hand at one (22,) configuration."""
        q = self._check_one_q(q, "collision_objects")
        T0 = self._check_pose(T_world_palm, "T_world_palm")
        out: list[tuple[str, int, coal.CollisionObject]] = []
        R, depth = palm_geometry(self.params) if self.params is not None else (0.0, 0.0)
        Tp = np.eye(4)
        Tp[:3, :3] = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])  # cylinder z -> palm x
        Tp[:3, 3] = (0.0, 0.0, R)
        out.append(("palm", -1, coal.CollisionObject(coal.Cylinder(R, depth), _se3(T0 @ Tp))))
        specs = self.capsule_specs
        if specs:
            T = self.frame_poses(q, [s[0] for s in specs])
            for (link, fi, r, L), Tl in zip(specs, T):
                Tc = Tl.copy()
                Tc[:3, 3] = Tl[:3, 3] + Tl[:3, 2] * (L / 2.0)
                geom = coal.Capsule(r, max(L - 2.0 * r, 0.0))
                out.append((link, fi, coal.CollisionObject(geom, _se3(T0 @ Tc))))
        return out

    def self_collision_pairs(self, q: np.ndarray, margin: float = 0.0) -> list[tuple[str, str]]:
        """Pairs of finger segments on different fingers closer than ``margin`` (palm-finger and
        same-finger pairs are excluded, as in the evaluation protocol).

        Args:
            q: (22,) joint angles [rad].
            margin: distance [m] below which a pair counts; 0: only penetrating pairs.

        Returns:
            ``(link, link)`` name pairs, e.g. ``("index_distal", "middle_distal")``.

        Raises:
            OhraError: the model has no params; ``q`` is not (22,) or not finite.
        """
        q = self._check_one_q(q, "self_collision_pairs")
        margin = self._check_margin(margin)
        objs = [o for o in self.collision_objects(q) if o[1] >= 0]
        hits = []
        for i in range(len(objs)):
            for j in range(i + 1, len(objs)):
                if objs[i][1] == objs[j][1]:
                    continue
                d = _distance(objs[i][2], objs[j][2])
                if d < margin:
                    hits.append((objs[i][0], objs[j][0]))
        return hits

    def self_collision(self, q: np.ndarray, margin: float = 0.0) -> bool:
        """Whether segments of two different fingers intersect (:meth:`self_collision_pairs`).

        Args:
            q: (22,) joint angles [rad].
            margin: distance [m] below which a pair counts; 0: only penetration.

        Raises:
            OhraError: the model has no params; ``q`` is not (22,) or not finite.
        """
        return bool(self.self_collision_pairs(self._check_one_q(q, "self_collision"), margin))

    def object_distances(
        self, q: np.ndarray, geometry: coal.CollisionGeometry, T_palm_object: np.ndarray | None = None
    ) -> dict[str, float]:
        """Distance [m] from every hand shape (palm and capsules) to an object.

        For a convex object (``coal.Convex`` or a primitive) the value is signed: negative means
        penetration and its magnitude is the penetration depth (GJK/EPA). For a triangle mesh
        (``coal.BVHModel``) Coal's distance is unsigned: a colliding shape reports ``-depth`` taken
        from the deepest contact of a collision query, which is exact for shallow contacts but
        underestimates deep ones (the mesh has no inside); use an SDF (``ohra.objects.model``) when
        deep signed values matter.

        Args:
            q: (22,) joint angles [rad].
            geometry: the object's Coal geometry in its own frame [m].
            T_palm_object: (4, 4) pose of the object frame in the palm frame [m]; None: identity.

        Returns:
            ``{"palm": d, "<link>": d, ...}``: one signed distance [m] per hand shape.

        Raises:
            OhraError: the model has no params; ``q`` is not (22,) or not finite; ``T_palm_object`` is not a finite
                (4, 4) transform.
        """
        q = self._check_one_q(q, "object_distances")
        To = self._check_pose(T_palm_object, "T_palm_object")
        obj = coal.CollisionObject(geometry, _se3(To))
        is_mesh = isinstance(geometry, coal.BVHModelBase)
        out: dict[str, float] = {}
        for name, _, co in self.collision_objects(q):
            d = _distance(co, obj)
            if is_mesh and d <= 0.0:
                d = -_penetration(co, obj)
            out[name] = d
        return out

    def min_distance(self, q: np.ndarray, geometry: coal.CollisionGeometry, T_palm_object: np.ndarray | None = None) -> float:
        """Smallest value of :meth:`object_distances` (same arguments).

        Returns:
            Distance [m] of the closest hand shape; negative: minus the deepest penetration.

        Raises:
            OhraError: the model has no params; ``q`` is not (22,) or not finite.
        """
        return min(self.object_distances(self._check_one_q(q, "min_distance"), geometry, T_palm_object).values())

    def penetration_depth(self, q: np.ndarray, geometry: coal.CollisionGeometry, T_palm_object: np.ndarray | None = None) -> float:
        """Largest penetration depth of any hand shape into the object (arguments as
        :meth:`object_distances`).

        Returns:
            Depth [m], >= 0; 0 when no shape penetrates.

        Raises:
            OhraError: the model has no params; ``q`` is not (22,) or not finite.
        """
        return max(0.0, -self.min_distance(self._check_one_q(q, "penetration_depth"), geometry, T_palm_object))


def _se3(T: np.ndarray) -> coal.Transform3s:
    return coal.Transform3s(np.ascontiguousarray(T[:3, :3]), np.ascontiguousarray(T[:3, 3]))


def _distance(a: coal.CollisionObject, b: coal.CollisionObject) -> float:
    req = coal.DistanceRequest()
    req.enable_signed_distance = True
    res = coal.DistanceResult()
    return float(coal.distance(a, b, req, res))


def _penetration(a: coal.CollisionObject, b: coal.CollisionObject) -> float:
    req = coal.CollisionRequest()
    req.num_max_contacts = 64
    req.enable_contact = True
    res = coal.CollisionResult()
    coal.collide(a, b, req, res)
    if not res.isCollision():
        return 0.0
    return max(abs(float(res.getContact(i).penetration_depth)) for i in range(res.numContacts()))


def load_hand_model(hand: str | Params) -> HandModel:
    """HandModel of a registered hand name, a params JSON path or params."""
    if isinstance(hand, (BaseParams, ExtendedParams)):
        return HandModel.from_params(hand)
    from ohra.hands import get_hand

    return HandModel.from_params(get_hand(hand))
