"""Objects of the rotation task: the sized shapes, every built-in, procedural objects and mesh files, with the
mass properties of the body ohra simulates; PyBullet's inertial frame turned onto the principal axes."""

from __future__ import annotations

import numpy as np
import pytest

from ohra.errors import ObjectError
from ohra.objects import ObjectModel
from ohra.objects.builtin import BUILTINS
from ohra.rotations import quat_to_matrix
from ohra.sim.rotation.config import RotationConfig
from ohra.sim.rotation.grasps import cache_path
from ohra.sim.rotation.objects import make_object
from ohra.sim.rotation.scene import RotationScene
from ohra.sim.rotation.task import resolve


@pytest.mark.parametrize("name", sorted(BUILTINS))
def test_every_builtin_is_a_rotation_object_with_the_inertia_of_its_body(name):
    """Principal moments along turned axes give back the object's inertia tensor in its own frame (the box's
    moments come sorted, not in axis order, and the L-block's axes are not the mesh axes)."""
    shape = make_object(f"builtin:{name}", None, 500.0)
    model = ObjectModel.builtin(name, 500.0)
    R = quat_to_matrix(shape.inertia_quat)
    np.testing.assert_allclose(R @ np.diag(shape.inertia) @ R.T, model.inertia, atol=1e-12)
    assert shape.mass == pytest.approx(model.mass)
    np.testing.assert_allclose(shape.com, model.center_mass)
    assert bool(shape.prims) != bool(shape.pieces)  # primitives, or convex pieces (the ellipsoid)


def _scene(obj: str, **kw) -> RotationScene:
    cfg = RotationConfig(object=obj, gravity=0.0, **kw)
    t = resolve(cfg)
    return RotationScene(t.hand, t.obj, cfg, t.palm_radius)


@pytest.mark.parametrize("obj", ["builtin:l_block", "builtin:box", "builtin:ellipsoid", "cube"])
def test_the_object_pose_reads_back_as_placed_whatever_its_principal_axes(obj):
    """PyBullet reports the inertial frame: read() must turn it back into the object frame."""
    scene = _scene(obj)
    try:
        quat = np.array([0.2, -0.4, 0.3, 0.8])
        quat /= np.linalg.norm(quat)
        pos = np.array([0.01, -0.02, 0.3])
        scene.new_object(pos, quat)
        s = scene.read()
        np.testing.assert_allclose(s.obj_pos, pos, atol=1e-9)
        assert abs(abs(float(s.obj_quat @ quat)) - 1.0) < 1e-9
    finally:
        scene.close()


def test_a_spinning_l_block_keeps_its_angular_momentum():
    """Free of gravity and contacts, the world angular momentum R I R^T w of the object (its inertia in the
    object frame, turned by the pose read back) stays constant while w itself changes: wrong principal axes in
    PyBullet would break that (Bullet integrates the gyroscopic term implicitly, so the check is loose)."""
    import pybullet as pb

    scene = _scene("builtin:l_block")
    try:
        scene.new_object(np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, 0.0, 1.0]))
        w0 = np.array([3.0, 5.0, -2.0])
        pb.resetBaseVelocity(scene.obj_body, [0, 0, 0], w0.tolist(), physicsClientId=scene.client)
        Qi = quat_to_matrix(scene.obj.inertia_quat)
        I_obj = Qi @ np.diag(scene.obj.inertia) @ Qi.T

        def momentum():
            s = scene.read()
            R = quat_to_matrix(s.obj_quat)
            return R @ I_obj @ R.T @ s.obj_angvel, s.obj_angvel

        L0, _ = momentum()
        for _ in range(10):
            scene.step()
        L1, w1 = momentum()
        assert np.linalg.norm(w1 - w0) > 0.1 * np.linalg.norm(w0)  # it tumbles: w is not conserved
        # Bullet's integrator lets it drift ~2 % in these 10 steps; the mesh axes as principal axes: ~100 %
        assert np.linalg.norm(L1 - L0) < 0.05 * np.linalg.norm(L0)
    finally:
        scene.close()


def test_object_size_scales_a_mesh_file_to_its_largest_extent_and_is_refused_for_builtins(tmp_path):
    import trimesh

    path = tmp_path / "brick.obj"
    trimesh.creation.box(extents=(0.2, 0.1, 0.05)).export(path)
    own = make_object(str(path), None, 500.0)
    assert max(own.mesh.extents) == pytest.approx(0.2)
    small = make_object(str(path), 0.05, 500.0)
    assert max(small.mesh.extents) == pytest.approx(0.05)
    assert small.mass == pytest.approx(500.0 * 0.05 * 0.025 * 0.0125)
    with pytest.raises(ObjectError, match="keeps its own size"):
        make_object("builtin:box", 0.05, 500.0)
    with pytest.raises(ObjectError, match="cube.*builtin:NAME.*mesh"):
        make_object("teapot", 0.05, 500.0)


def test_a_mesh_file_object_runs_in_the_env_and_caches_under_its_stem(tmp_path, monkeypatch, objects_dir):
    gym = pytest.importorskip("gymnasium", reason="the rotation env needs the rl extra (gymnasium)")
    import ohra.sim.rotation  # noqa: F401  (registers the env)

    monkeypatch.setenv("OHRA_CACHE_DIR", str(tmp_path))
    obj = str(objects_dir / "ycb" / "TomatoSoupCan")
    env = gym.make("ohra/InHandRotate-v0", hand="leap_hand_right", object=obj, object_size=0.06, grasp_count=3)
    try:
        env.reset(seed=0)
        for _ in range(5):
            *_, info = env.step(np.zeros(env.action_space.shape, dtype=np.float32))
        task = env.unwrapped.task
        assert task.obj.pieces and max(task.obj.mesh.extents) == pytest.approx(0.06)
        path = cache_path(task)
        assert path.is_file() and path.parent == tmp_path / "rotation" and "TomatoSoupCan" in path.name
    finally:
        env.close()
