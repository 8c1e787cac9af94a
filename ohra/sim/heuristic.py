"""Plausible (not optimised) grasps by closing the hand around an object: benchmark and demo input.

For a seeded random approach direction ``d`` (from the object's centre outward) and roll about it,
the palm is placed facing the object (palm normal ``+x`` along ``-d``) with its front face
``standoff`` metres from the object's support point along ``d``, the object's centre level with the
knuckles (+-2 cm). Then, per finger, among ``samples`` configurations drawn uniformly within the
joint limits, the one whose distal segment is closest to touching the object (capsule-axis points'
signed distance minus radius within 3 mm, nowhere deeper than 2 mm) is kept; a finger with no such
sample stays straight. No physics and no force closure: some of these grasps hold in the
six-direction test, many do not, which is what a throughput benchmark of the evaluator needs. The
synthesiser (``ohra.synth``) makes real grasps.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from ohra.canonical.kinematics import HandModel
from ohra.objects.model import ObjectModel
from ohra.rotations import pose_to_grasp

_AXIS_SAMPLES = np.linspace(0.0, 1.0, 5)  # points along each capsule's core segment


def _frame_facing(d: np.ndarray, roll: float) -> np.ndarray:
    """Rotation whose +x is ``-d`` and whose +z is rolled by ``roll`` about that axis."""
    x = -d / np.linalg.norm(d)
    helper = np.array([0.0, 0.0, 1.0]) if abs(x[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    z0 = helper - (helper @ x) * x
    z0 /= np.linalg.norm(z0)
    y0 = np.cross(z0, x)
    z = np.cos(roll) * z0 + np.sin(roll) * y0
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=1)


def closing_direction(hm: HandModel, T: np.ndarray, q: np.ndarray, target: np.ndarray) -> np.ndarray:
    """+1 where a positive joint rotation moves the child link toward ``target`` (object frame), else -1.

    The link direction is the child frame's +z (canonical links extend along +z), as in the squeeze
    controller of the evaluation protocol.
    """
    from ohra.canonical.params import JOINT_NAMES

    child = [hm.tree.frame_names[int(np.flatnonzero(hm.tree.frame_joint == hm.tree.joint_names.index(n))[0])]
             for n in JOINT_NAMES]
    poses = T @ hm.frame_poses(q, child)
    axes = np.array([hm.tree.joint_axis[hm.tree.joint_names.index(n)] for n in JOINT_NAMES])
    a_w = np.einsum("kij,kj->ki", poses[:, :3, :3], axes)
    motion = np.cross(a_w, poses[:, :3, 2])
    to_target = target - poses[:, :3, 3]
    return np.where((motion * to_target).sum(axis=1) >= 0.0, 1.0, -1.0)


def heuristic_grasps(hm: HandModel, obj: ObjectModel, n: int, seed: int = 0, standoff: tuple[float, float] = (0.0, 0.01),
                     samples: int = 256, couplings: Sequence | None = None) -> np.ndarray:
    """``n`` seeded grasps ``(n, 31)`` of ``hm`` around ``obj`` from random directions (see module doc).

    ``couplings``: the hand's joint couplings; every candidate configuration keeps them (coupled joints set from
    their drivers, as simulation drives them), so a finger chosen for touching still touches once simulated.
    None: those of the registered hand whose params ``hm`` was built from (:func:`ohra.hands.couplings_of`), if any.
    """
    from ohra.canonical.couplings import project
    from ohra.canonical.params import FINGER_SLICES, FINGERS

    if couplings is None:
        from ohra.hands import couplings_of

        couplings = couplings_of(hm.params) if hm.params is not None else ()
    couplings = tuple(couplings)

    rng = np.random.default_rng(seed)
    caps = hm.capsule_specs
    links = [c[0] for c in caps]
    finger = np.array([c[1] for c in caps])
    radius = np.array([c[2] for c in caps])
    length = np.array([c[3] for c in caps])
    q0 = np.clip(np.zeros(22), hm.lower, hm.upper)
    base_z = hm.frame_poses(q0, links)[:, 2, 3]
    z_mid = float(np.median(base_z[finger != 0])) if np.any(finger != 0) else float(base_z.mean())
    half_depth = hm.palm["depth"] / 2
    centre = np.asarray(obj.center_mass, dtype=float)
    verts = np.asarray(obj.mesh.vertices)
    out = np.zeros((n, 31))
    for i in range(n):
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        R = _frame_facing(d, rng.uniform(-np.pi, np.pi))
        support = float(((verts - centre) @ d).max())
        c_hand = np.array([half_depth + support + rng.uniform(*standoff), 0.0, z_mid + rng.uniform(-0.02, 0.02)])
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = centre - R @ c_hand
        # candidate configurations: each finger's joints uniform within their limits
        Q = np.repeat(q0[None], samples + 1, axis=0)
        Q[1:] = rng.uniform(hm.lower, hm.upper, size=(samples, 22))
        if couplings:  # each candidate as simulation would hold it
            Q = np.clip(project(couplings, Q), hm.lower, hm.upper)
        P = T @ hm.frame_poses(Q, links)  # (S+1, K, 4, 4)
        a = P[..., :3, 2]
        pts = P[..., None, :3, 3] + (radius[None, :, None, None] + _AXIS_SAMPLES[None, None, :, None]
                                     * (length - 2 * radius)[None, :, None, None]) * a[..., None, :]
        sd = obj.signed_distance(pts.reshape(-1, 3)).reshape(samples + 1, len(links), -1).min(axis=2) - radius
        q = q0.copy()
        for f, fname in enumerate(FINGERS):
            mine = finger == f
            if not mine.any():
                continue
            dmin = sd[:, mine].min(axis=1)
            # touching (within 3 mm, at most 2 mm deep) with the tip segment: the closest such sample wins
            tip_d = sd[:, np.flatnonzero(mine)[-1]]
            ok = (dmin >= -0.002) & (tip_d <= 0.003)
            if ok.any():
                k = int(np.flatnonzero(ok)[np.argmin(np.abs(tip_d[ok]))])
                q[FINGER_SLICES[fname]] = Q[k, FINGER_SLICES[fname]]
        if couplings:  # a slot coupled to another finger's joint follows the row that finger chose
            q = np.clip(project(couplings, q), hm.lower, hm.upper)
        out[i] = pose_to_grasp(T, q)
    return out


def _finger_of(j: int) -> int:
    from ohra.canonical.params import FINGER_SLICES, FINGERS

    for k, f in enumerate(FINGERS):
        if FINGER_SLICES[f].start <= j < FINGER_SLICES[f].stop:
            return k
    return -1
