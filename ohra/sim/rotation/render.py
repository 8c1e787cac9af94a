"""Pictures of rotation episodes: PyBullet's CPU renderer (TinyRenderer), strips and GIFs.

A scene built with ``visual=True`` keeps the URDF's visual shapes (and gives the object one). The
camera looks at the palm centre from above and the side (world +z is up in the picture).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pybullet as pb

from ohra.io import atomic_path
from ohra.sim.rotation.scene import RotationScene


def render(scene: RotationScene, size: int = 240, distance: float | None = None, yaw: float = 90.0,
           pitch: float = -50.0) -> np.ndarray:
    """(size, size, 3) uint8 RGB image of ``scene`` now (no display, no GPU). A scene built without visuals (an env
    without ``render_mode``) draws its collision shapes, which PyBullet's renderer shows for primitives but not for a
    mesh object's convex pieces: such an object is drawn by a stand-in with no collision shape, posed as the object."""
    c = scene.client
    stand_in = _mesh_stand_in(scene)
    target = scene.palm_centre_world() + np.array([0.0, 0.0, scene.palm_top + scene.obj.half_height])
    dist = distance if distance is not None else 3.0 * scene.palm_radius + 0.08
    view = pb.computeViewMatrixFromYawPitchRoll(target.tolist(), dist, yaw, pitch, 0.0, 2, physicsClientId=c)
    proj = pb.computeProjectionMatrixFOV(45.0, 1.0, 0.01, 5.0, physicsClientId=c)
    try:
        img = pb.getCameraImage(size, size, view, proj, renderer=pb.ER_TINY_RENDERER, physicsClientId=c)
    finally:
        if stand_in is not None:
            pb.removeBody(stand_in, physicsClientId=c)
    return np.reshape(np.asarray(img[2], dtype=np.uint8), (size, size, 4))[..., :3]


def _mesh_stand_in(scene: RotationScene) -> int | None:
    """A body with the object's mesh as its only shape (no collision: the physics never sees it) at the object's pose,
    when the scene drew none; None otherwise. The visual shape is made once per scene."""
    if scene.visual or scene.obj.prims or scene.obj_body is None:
        return None
    c = scene.client
    shape = getattr(scene, "_stand_in_visual", None)
    if shape is None:
        m, com = scene.obj.mesh, np.asarray(scene.obj.com, dtype=float)
        shape = pb.createVisualShape(pb.GEOM_MESH, vertices=(np.asarray(m.vertices) - com).tolist(),
                                     indices=np.asarray(m.faces).reshape(-1).tolist(), rgbaColor=[0.85, 0.63, 0.4, 1.0],
                                     physicsClientId=c)
        scene._stand_in_visual = shape
    pos, quat = pb.getBasePositionAndOrientation(scene.obj_body, physicsClientId=c)
    return pb.createMultiBody(0.0, -1, shape, pos, quat, physicsClientId=c)


def strip(frames: list[np.ndarray] | np.ndarray, border: int = 2) -> np.ndarray:
    """Frames (N, H, W, 3) side by side with white gaps: one (H, N*(W+border)-border, 3) image."""
    frames = np.asarray(frames)
    n, h, w, _ = frames.shape
    out = np.full((h, n * (w + border) - border, 3), 255, dtype=np.uint8)
    for i in range(n):
        out[:, i * (w + border):i * (w + border) + w] = frames[i]
    return out


def write_gif(frames: list[np.ndarray] | np.ndarray, path: str | Path, fps: float = 20.0) -> Path:
    """Write an animated GIF (Pillow) atomically."""
    from PIL import Image

    images = [Image.fromarray(np.asarray(f, dtype=np.uint8)) for f in frames]
    with atomic_path(path, suffix=".gif") as tmp:
        images[0].save(tmp, save_all=True, append_images=images[1:], duration=int(round(1000 / fps)), loop=0)
    return Path(path)
