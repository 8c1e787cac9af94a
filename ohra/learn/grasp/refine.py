"""Test-time refinement of sampled grasps: open the fingers just enough to clear the object (and, with
``touch``, close the hovering ones until they touch it).

The grasp model's wrist translations and joints are a few millimetres off, and the error shows up
as fingers sunk into the object: the shipped model's grasps on unseen objects start with a median
9 mm of finger penetration (Allegro, Shadow; 6 mm Barrett), and grasps with less penetration pass
the six-direction test more often (README, *Grasp model*). In simulation a sunk finger is pushed out
with a large impulse and knocks the object away. This module moves only the joints (the palm pose
stays) along the steepest descent of the penetration energy

    E(q) = sum over capsule samples of max(0, -clearance - d(p(q)))^2

(``d``: the object body's exact signed distance minus the capsule radius, ``p``: points along each
finger capsule's core) until no sample is deeper than ``clearance`` or the iterations run out. Steps
have a fixed length in joint space (``step_rad``, normalised gradient, finite differences over the
movable joints), halved for a grasp whenever it would not lower that grasp's energy; joints stay
within the hand's limits, absent joints stay zero. Grasps that clear already are returned unchanged.
Pure numpy (no torch): it runs on any canonical hand, LEAP variants included.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ohra.errors import GraspError, require_finite, require_whole


@dataclass(frozen=True, repr=False)
class RefineSettings:
    """``clearance_m``: the penetration depth left alone [m]; ``iterations``: gradient steps at most;
    ``step_rad``: the joint-space length of a step [rad]; ``samples_per_capsule``: points along each
    capsule core; ``fd_rad``: finite-difference step of the gradient [rad]; ``touch``: also close every
    finger whose nearest point hovers more than ``clearance_m`` off the surface until it touches (the
    energy gains ``sum over fingers of max(0, d_finger - clearance)^2``; in the training data every
    finger of a grasp lies within 2 mm of the surface, while a third of the shipped model's fingers
    hover 1-15 mm off it)."""

    clearance_m: float = 0.001
    iterations: int = 30
    step_rad: float = 0.03
    samples_per_capsule: int = 5
    fd_rad: float = 1e-3
    touch: bool = False

    def __repr__(self) -> str:
        # without ``touch`` when off: the caches of evaluations made before the option hold this text in their keys
        shown = [f"{k}={getattr(self, k)!r}" for k in ("clearance_m", "iterations", "step_rad", "samples_per_capsule", "fd_rad")]
        return f"RefineSettings({', '.join(shown + (['touch=True'] if self.touch else []))})"

    def __post_init__(self) -> None:
        require_finite(self.clearance_m, GraspError, "RefineSettings: clearance_m")
        for name in ("step_rad", "fd_rad"):
            require_finite(getattr(self, name), GraspError, f"RefineSettings: {name}", positive=True)
        require_whole(self.iterations, GraspError, "RefineSettings: iterations", 0)
        require_whole(self.samples_per_capsule, GraspError, "RefineSettings: samples_per_capsule", 2)
        if not isinstance(self.touch, (bool, np.bool_)):  # "no" would switch it on
            raise GraspError(f"RefineSettings: touch must be True or False, got {self.touch!r}")


def as_refine_settings(refine: "bool | RefineSettings | None") -> RefineSettings | None:
    """The settings a ``refine=`` argument asks for: None when off (False/None), the defaults for True.

    Raises:
        GraspError: anything else (a number, a string: ``refine=0`` or ``"no"`` must not switch it on).
    """
    if isinstance(refine, RefineSettings):
        return refine
    if refine is None or (isinstance(refine, (bool, np.bool_)) and not refine):
        return None
    if isinstance(refine, (bool, np.bool_)):
        return RefineSettings()
    raise GraspError(f"refine must be True, False, None or a RefineSettings, got {refine!r}")


@dataclass
class RefineResult:
    """Refined ``grasps`` (N, 31; the input's float type), the smallest finger-object signed distance before and after
    [m] (N,), and the gradient steps taken per grasp (N,)."""

    grasps: np.ndarray
    min_distance_before: np.ndarray
    min_distance_after: np.ndarray
    steps: np.ndarray


def _capsule_distances(hand, obj, T: np.ndarray, q: np.ndarray, s: RefineSettings,
                       only: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Signed distances (N, S, K) [m] of S samples along each of the K capsule cores to ``obj``, minus the
    capsule radius, for palm poses T (N,4,4) and joints q (N,22); and each capsule's finger index (K,).
    ``only``: capsule indices to measure (N, S, len(only)); the others are not computed."""
    caps = hand.capsules(q)
    p0, p1, radius = (caps.p0, caps.p1, caps.radius) if only is None else (caps.p0[:, only], caps.p1[:, only], caps.radius[only])
    u = np.linspace(0.0, 1.0, s.samples_per_capsule)[:, None, None]
    pts = p0[:, None] + u * (p1 - p0)[:, None]  # (N, S, K, 3) palm frame
    world = np.einsum("nij,nskj->nski", T[:, :3, :3], pts) + T[:, None, None, :3, 3]
    return obj.signed_distance(world.reshape(-1, 3)).reshape(world.shape[:3]) - radius, caps.finger


def _moved_by(hand) -> dict[int, np.ndarray]:
    """For each canonical joint index, the capsules (indices into ``hand.capsules``) whose pose depends on it."""
    tree = hand.tree
    specs = hand.capsule_specs
    out: dict[int, list[int]] = {}
    for k, spec in enumerate(specs):
        j = int(tree.frame_joint[tree.frame_names.index(spec[0])])
        while j >= 0:
            out.setdefault(int(tree.joint_q[j]), []).append(k)
            j = int(tree.joint_parent[j])
    return {j: np.array(sorted(set(ks)), dtype=int) for j, ks in out.items()}


def _per_finger(per_capsule: np.ndarray, finger: np.ndarray) -> np.ndarray:
    """(N, K) per-capsule values -> (N, F) the smallest per finger (thumb-to-little order)."""
    if not finger.size:  # a hand without fingers (leap_0000)
        return np.zeros((len(per_capsule), 0))
    return np.stack([per_capsule[:, finger == f].min(axis=1) for f in np.unique(finger)], axis=1)


def _nearest(d: np.ndarray) -> np.ndarray:
    """(N,) the smallest of capsule-sample distances d (N, S, K); +inf for a hand without finger capsules."""
    return d.min(axis=(1, 2)) if d.shape[1] and d.shape[2] else np.full(len(d), np.inf)


def _energy(d: np.ndarray, finger: np.ndarray, s: RefineSettings) -> np.ndarray:
    """(N,) penetration energy of capsule-sample distances d (N, S, K) (see the module docstring)."""
    energy = (np.maximum(-s.clearance_m - d, 0.0) ** 2).sum(axis=(1, 2))
    if s.touch:
        for nearest in _per_finger(d.min(axis=1), finger).T:  # added finger by finger (the evaluated runs' order)
            energy = energy + np.maximum(nearest - s.clearance_m, 0.0) ** 2
    return energy


def _penetration(hand, obj, T: np.ndarray, q: np.ndarray, s: RefineSettings) -> tuple[np.ndarray, np.ndarray]:
    """(energy (N,), smallest signed distance (N,)) of grasps with palm poses T (N,4,4) and joints q (N,22)."""
    d, finger = _capsule_distances(hand, obj, T, q, s)
    return _energy(d, finger, s), _nearest(d)


def finger_clearance(hand, obj, grasps: np.ndarray, settings: RefineSettings | None = None) -> np.ndarray:
    """The smallest signed distance [m] between the finger capsules of ``hand`` (a
    :class:`~ohra.canonical.kinematics.HandModel` or params) and ``obj`` for grasps (N, 31) in the dataset
    convention: negative when a finger is sunk into the object. Capsule cores are sampled with
    ``settings.samples_per_capsule`` points."""
    from ohra.canonical.kinematics import HandModel
    from ohra.rotations import grasp_to_pose

    hm = hand if isinstance(hand, HandModel) else HandModel.from_params(hand)
    T, q = grasp_to_pose(np.asarray(grasps, dtype=float))
    return _penetration(hm, obj, T, q, settings or RefineSettings())[1]


def finger_distances(hand, obj, grasps: np.ndarray, settings: RefineSettings | None = None) -> np.ndarray:
    """(N, F) each present finger's nearest capsule-core sample to ``obj``, minus the capsule radius [m]
    (negative: sunk), for grasps (N, 31); fingers in thumb-to-little order. What ``touch`` brings within
    the clearance of the surface."""
    from ohra.canonical.kinematics import HandModel
    from ohra.rotations import grasp_to_pose

    hm = hand if isinstance(hand, HandModel) else HandModel.from_params(hand)
    T, q = grasp_to_pose(np.asarray(grasps, dtype=float))
    d, finger = _capsule_distances(hm, obj, T, q, settings or RefineSettings())
    return _per_finger(d.min(axis=1), finger)


def refine_grasps(hand, obj, grasps: np.ndarray, settings: RefineSettings | None = None) -> RefineResult:
    """Clear the fingers of ``hand`` (a :class:`~ohra.canonical.kinematics.HandModel` or params) out of
    ``obj`` (an :class:`~ohra.objects.model.ObjectModel`) for grasps (N, 31) in the dataset convention
    (palm frame in the object frame). See the module docstring; deterministic."""
    from ohra.canonical.kinematics import HandModel
    from ohra.rotations import grasp_to_pose

    s = settings or RefineSettings()
    hm = hand if isinstance(hand, HandModel) else HandModel.from_params(hand)
    g = np.asarray(grasps)
    if g.ndim != 2 or g.shape[1] != 31:
        raise GraspError(f"refine_grasps: grasps must be (N, 31), got {g.shape}")
    if len(g) == 0:
        z = np.zeros(0)
        return RefineResult(g.astype(np.result_type(g.dtype, np.float32)), z, z, np.zeros(0, dtype=int))
    T, q = grasp_to_pose(g.astype(float))
    q = q.copy()
    movable = np.flatnonzero(hm.upper > hm.lower)
    moved = _moved_by(hm)
    D, finger = _capsule_distances(hm, obj, T, q, s)  # kept in step with q: (N, S, K)
    E, d0 = _energy(D, finger, s), _nearest(D)
    step = np.full(len(g), float(s.step_rad))
    steps = np.zeros(len(g), dtype=int)
    for _ in range(int(s.iterations)):
        act = np.flatnonzero((E > 0) & (step > 1e-4))
        if not act.size:
            break
        T_act, q_act, D_act, E_act = T[act], q[act], D[act], E[act]
        grad = np.zeros((len(act), q.shape[1]))
        for j in movable:
            ks = moved.get(int(j))
            if ks is None:  # no capsule hangs from this joint: the energy does not depend on it
                continue
            qj = q_act.copy()
            qj[:, j] += s.fd_rad
            # only the capsules joint j moves are measured again; the others' distances are those at q, as they
            # would be measured again (a sample's distance depends on its own position only)
            dj = D_act.copy()
            dj[:, :, ks] = _capsule_distances(hm, obj, T_act, qj, s, only=ks)[0]
            grad[:, j] = (_energy(dj, finger, s) - E_act) / s.fd_rad
        norm = np.linalg.norm(grad, axis=1, keepdims=True)
        trial = np.clip(q_act - step[act, None] * grad / np.maximum(norm, 1e-12), hm.lower, hm.upper)
        D_new, _ = _capsule_distances(hm, obj, T_act, trial, s)
        E_new = _energy(D_new, finger, s)
        better = E_new < E_act
        q[act[better]], E[act[better]], D[act[better]] = trial[better], E_new[better], D_new[better]
        steps[act[better]] += 1
        step[act[~better]] *= 0.5
    d1 = _nearest(D)
    out = g.astype(np.result_type(g.dtype, np.float32))  # a copy; float64 stays float64
    changed = steps > 0
    out[changed, 9:] = q[changed]
    return RefineResult(out, d0, d1, steps)


__all__ = ["RefineSettings", "RefineResult", "as_refine_settings", "refine_grasps", "finger_clearance", "finger_distances"]
