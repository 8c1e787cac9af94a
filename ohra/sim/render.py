"""PNG pictures of grasps with PyBullet's CPU renderer (TinyRenderer: no display, no GPU).

A contact sheet tiles one image per grasp; a green or red frame marks success or failure when
outcomes are given. The hand is drawn from its URDF's visual shapes, the object from its mesh.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np
import pybullet as pb

from ohra.sim.bullet import captured_c_output
from ohra.objects.model import ObjectModel
from ohra.rotations import grasp_to_pose, matrix_to_quat
from ohra.sim.hands import SimHand


def pose_joints(hand: SimHand, body: int, by_name: dict[str, int], qs: np.ndarray, client: int) -> None:
    """Set ``hand``'s driven joints to ``qs`` (sim order, rad) and its URDF mimic joints from their drivers, as
    the simulation poses them (:meth:`ohra.sim.world.World.set_joints`); ``by_name``: joint name -> PyBullet index."""
    for k, n in enumerate(hand.joints):
        pb.resetJointState(body, by_name[n], float(qs[k]), physicsClientId=client)
    for name, (driver, mul, off) in hand.mimic.items():
        if name in by_name and driver in hand.joints:
            pb.resetJointState(body, by_name[name], mul * float(qs[hand.joints.index(driver)]) + off, physicsClientId=client)


def render_grasps(hand: SimHand, obj: ObjectModel, grasps: np.ndarray, size: int = 256,
                  distance: float | None = None, yaw: float = 45.0, pitch: float = -30.0) -> np.ndarray:
    """(N, size, size, 3) uint8 RGB images of canonical grasps (object at the origin)."""
    c = pb.connect(pb.DIRECT)
    try:
        fd, path = tempfile.mkstemp(suffix=".urdf")
        with os.fdopen(fd, "w") as fh:
            fh.write(hand.urdf)
        try:
            with captured_c_output():
                body = pb.loadURDF(path, useFixedBase=True, physicsClientId=c)
        finally:
            Path(path).unlink(missing_ok=True)
        by_name = {pb.getJointInfo(body, j, physicsClientId=c)[1].decode(): j for j in range(pb.getNumJoints(body, physicsClientId=c))}
        V = np.asarray(obj.mesh.vertices)
        F = np.asarray(obj.mesh.faces)
        vis = pb.createVisualShape(pb.GEOM_MESH, vertices=V.tolist(), indices=F.ravel().tolist(),
                                   rgbaColor=[0.85, 0.63, 0.4, 1.0], physicsClientId=c)
        pb.createMultiBody(0, -1, vis, [0, 0, 0], [0, 0, 0, 1], physicsClientId=c)
        dist = distance if distance is not None else 3.0 * max(obj.radius, 0.05) + 0.25
        view = pb.computeViewMatrixFromYawPitchRoll(obj.center_mass.tolist(), dist, yaw, pitch, 0.0, 2, physicsClientId=c)
        proj = pb.computeProjectionMatrixFOV(45.0, 1.0, 0.01, 5.0, physicsClientId=c)
        out = np.zeros((len(grasps), size, size, 3), dtype=np.uint8)
        for i, g in enumerate(np.asarray(grasps, dtype=float).reshape(-1, 31)):
            T, q = grasp_to_pose(g)
            Tr = T @ hand.T_palm_root
            pb.resetBasePositionAndOrientation(body, Tr[:3, 3].tolist(), matrix_to_quat(Tr[:3, :3]).tolist(), physicsClientId=c)
            # the pose the evaluator starts from: a coupled hand's coupled joints set from their drivers
            qs = hand.project_sim(np.clip(hand.to_sim(np.clip(q, hand.canon_lower, hand.canon_upper)), hand.lower, hand.upper))
            pose_joints(hand, body, by_name, qs, c)
            img = pb.getCameraImage(size, size, view, proj, renderer=pb.ER_TINY_RENDERER, physicsClientId=c)
            out[i] = np.reshape(img[2], (size, size, 4))[..., :3]
        return out
    finally:
        pb.disconnect(c)


def contact_sheet(images: np.ndarray, success: np.ndarray | None = None, columns: int = 4, border: int = 4) -> np.ndarray:
    """Tile (N,H,W,3) images into one RGB array; green/red frames for success/failure."""
    n, h, w, _ = images.shape
    cols = max(1, min(columns, n))
    rows = max(1, -(-n // cols))
    H, W = h + 2 * border, w + 2 * border
    sheet = np.full((rows * H, cols * W, 3), 255, dtype=np.uint8)
    for i in range(n):
        r, k = divmod(i, cols)
        tile = np.full((H, W, 3), 200, dtype=np.uint8)
        if success is not None:
            tile[:] = (40, 170, 60) if bool(success[i]) else (200, 50, 40)
        tile[border:border + h, border:border + w] = images[i]
        sheet[r * H:(r + 1) * H, k * W:(k + 1) * W] = tile
    return sheet


def write_png(image: np.ndarray, path: str | Path) -> Path:
    """Write an RGB array as PNG via a temporary file and a rename (no partial file)."""
    from matplotlib.image import imsave  # no pyplot: the caller's backend (e.g. notebook inline) is left alone

    from ohra.io import atomic_path

    path = Path(path)
    with atomic_path(path, suffix=".png") as tmp:
        imsave(tmp, image)
    return path
