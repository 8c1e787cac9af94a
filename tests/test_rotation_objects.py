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
    cfg = RotationConfig(object=obj, **{"gravity": 0.0, **kw})
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


def _object_pixels(img: np.ndarray) -> int:
    return int(np.sum(np.all(np.abs(img.astype(int) - [217, 161, 102]) < 40, axis=-1)))  # the object's colour, shaded


def test_a_scene_without_visuals_draws_a_mesh_object_and_drawing_it_changes_no_state():
    """An env made without render_mode builds no visual shapes; PyBullet's renderer then shows primitives but not a
    mesh object's convex pieces (the object vanished from notebook 08's frames). A collision-free stand-in draws it."""
    from ohra.sim.rotation.render import render

    scenes = [_scene("builtin:ellipsoid", gravity=-9.81) for _ in range(2)]
    try:
        for sc in scenes:
            assert not sc.visual and not sc.obj.prims
            sc.new_object(sc.palm_centre_world() + np.array([0.0, 0.0, 0.08]), np.array([0.0, 0.0, 0.0, 1.0]))
        assert _object_pixels(render(scenes[0], 120)) > 100
        for k in range(60):
            for sc in scenes:
                sc.step()
            if k % 10 == 0:
                render(scenes[0], 48)
        a, b = (sc.read() for sc in scenes)
        np.testing.assert_array_equal(a.obj_pos, b.obj_pos)
        np.testing.assert_array_equal(a.q, b.q)
    finally:
        for sc in scenes:
            sc.close()


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


def _off_centre_box(tmp_path, offset=(0.05, 0.03, 0.0)):
    """A 6 x 5 x 5 cm box whose mesh frame origin lies ``offset`` [m] from its centre (a mesh exported in scene
    coordinates, as the YCB meshes are, 1-10 cm off-centre)."""
    import trimesh

    m = trimesh.creation.box(extents=(0.06, 0.05, 0.05))
    m.apply_translation(offset)
    path = tmp_path / "off_box.obj"
    m.export(path)
    return str(path)


def test_starting_states_of_an_off_centre_mesh_turn_it_about_its_centre_of_mass(tmp_path):
    """Every starting state has the object's centre of mass over the palm centre, whatever its random yaw: the
    yaw turns the object about its centre of mass, not about the mesh frame origin 6 cm away (which swung the
    object up to 12 cm off the palm)."""
    from ohra.sim.rotation.grasps import generate

    cfg = RotationConfig(object=_off_centre_box(tmp_path), grasp_count=4)
    t = resolve(cfg)
    scene = RotationScene(t.hand, t.obj, cfg, t.palm_radius)
    try:
        centre = scene.palm_centre_world()
    finally:
        scene.close()
    gs = generate(t)
    yaws = [2 * np.arctan2(q[2], q[3]) for q in gs.obj_quat]
    assert np.ptp(np.unwrap(yaws)) > 0.5  # the states do differ in yaw
    for pos, quat in zip(gs.obj_pos, gs.obj_quat):
        com = pos + quat_to_matrix(quat) @ t.obj.com
        assert np.linalg.norm((com - centre)[:2]) < 0.015


def test_turning_an_off_centre_object_in_place_neither_ends_the_episode_nor_counts_as_drift(tmp_path, monkeypatch):
    """Termination, the drift term and the observed position follow the centre of mass: a mesh turned 3 rad
    about its centre of mass has not left the hand (its frame origin, 5.8 cm off, moved ~11 cm)."""
    gym = pytest.importorskip("gymnasium", reason="the rotation env needs the rl extra (gymnasium)")
    import pybullet as pb

    import ohra.sim.rotation  # noqa: F401  (registers the env)

    monkeypatch.setenv("OHRA_CACHE_DIR", str(tmp_path))
    env = gym.make("ohra/InHandRotate-v0", object=_off_centre_box(tmp_path), grasp_count=2)
    try:
        env.reset(seed=0)
        u = env.unwrapped
        body, c = u.scene.obj_body, u.scene.client
        p, q = pb.getBasePositionAndOrientation(body, physicsClientId=c)  # the base frame is the centre of mass
        turned = pb.multiplyTransforms([0, 0, 0], [0.0, 0.0, np.sin(1.5), np.cos(1.5)], [0, 0, 0], q)[1]
        pb.resetBasePositionAndOrientation(body, p, turned, physicsClientId=c)
        obs, _, terminated, _, info = env.step(np.zeros(env.action_space.shape, dtype=np.float32))
        assert info["termination"] is None and not terminated
        assert info["reward/drift"] < 0.01
        from ohra.sim.rotation.observations import slices

        assert np.linalg.norm(obs[slices(u.space.dim)["object_pos"]]) < 0.01
    finally:
        env.close()


@pytest.mark.parametrize("extent, size, ok", [(60.0, None, False), (0.008, None, False), (0.06, None, True),
                                              (60.0, 0.06, True), (0.06, 0.6, False), (0.06, 0.45, True)])
def test_an_object_no_hand_can_hold_is_refused_with_the_fix(tmp_path, extent, size, ok):
    """A mesh in millimetres (a 60 m brick) or an 8 mm one ran as if held; the graspable range is the data
    engine's (1-50 cm, either side of its edges here) and ``object_size`` is the way out."""
    import trimesh

    path = tmp_path / "brick.stl"
    trimesh.creation.box(extents=(extent, 0.5 * extent, 0.4 * extent)).export(path)
    if ok:
        assert make_object(str(path), size, 500.0).mesh.extents.max() == pytest.approx(size or extent)
    else:
        with pytest.raises(ObjectError, match=r"largest extent .* outside the graspable range 0\.01-0\.5 m.*object_size"):
            make_object(str(path), size, 500.0)
    with pytest.raises(ObjectError, match="outside the graspable range"):
        make_object("cube", 0.6, 500.0)


@pytest.mark.parametrize("damage", [b"", b"PK\x03\x04 not really a zip", None])
def test_a_damaged_starting_state_cache_is_regenerated_with_the_umask_mode(tmp_path, monkeypatch, damage):
    """An empty or truncated cache file (an interrupted copy) made gym.make and ohra rotate fail with a zipfile
    or EOF error; it is regenerated, and the new file's mode follows the umask (it was always 0644)."""
    import os

    from ohra.sim.rotation.grasps import load_or_generate

    monkeypatch.setenv("OHRA_CACHE_DIR", str(tmp_path))
    task = resolve(RotationConfig(grasp_count=2))
    good = load_or_generate(task)
    path = cache_path(task)
    if damage is None:
        damage = path.read_bytes()[: path.stat().st_size // 2]
    path.write_bytes(damage)
    old = os.umask(0o027)
    try:
        again = load_or_generate(task)
    finally:
        os.umask(old)
    np.testing.assert_array_equal(again.q, good.q)
    assert path.stat().st_mode & 0o777 == 0o640


def test_an_interrupted_starting_state_generation_continues_to_the_same_states(tmp_path, monkeypatch):
    """The first use of a hand generates 1,000 states (minutes); interrupted, it kept nothing. The unfinished set is
    saved every few kept states with the random generator's state, and the next use continues from it to the
    states an uninterrupted generation gives."""
    from ohra.sim.rotation import grasps as G

    monkeypatch.setenv("OHRA_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(G, "PARTIAL_EVERY", 2)
    task = resolve(RotationConfig(grasp_count=5))
    whole = G.generate(task)
    calls, real_keep = [], G._keep

    def keep_then_stop(*a, **k):
        calls.append(1)
        if len(calls) >= max(3, 2 * whole.attempts // 3):  # past the first saves
            raise KeyboardInterrupt
        return real_keep(*a, **k)

    monkeypatch.setattr(G, "_keep", keep_then_stop)
    with pytest.raises(KeyboardInterrupt):
        G.load_or_generate(task)
    partial = cache_path(task).with_name(f".{cache_path(task).stem}.partial.npz")
    assert partial.is_file() and not cache_path(task).exists()
    counted = []
    monkeypatch.setattr(G, "_keep", lambda *a, **k: counted.append(1) or real_keep(*a, **k))
    again = G.load_or_generate(task)
    assert 0 < len(counted) < whole.attempts  # continued, not started again
    for a, b in ((whole.q, again.q), (whole.target, again.target), (whole.obj_pos, again.obj_pos)):
        np.testing.assert_array_equal(a, b)
    assert again.attempts == whole.attempts and not partial.exists()


def test_a_continued_generation_counts_the_rejections_of_the_interrupted_one_too(tmp_path, monkeypatch):
    """The "only N of M starting states" warning gives the reasons of every rejected attempt, those made before an
    interruption included (they were saved with the unfinished set)."""
    from ohra.sim.rotation import grasps as G

    monkeypatch.setenv("OHRA_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(G, "PARTIAL_EVERY", 1)
    monkeypatch.setattr(G, "MAX_ATTEMPTS_PER_GRASP", 3)
    # planted: attempt 1 falls, 2 is kept (and saved), 3 is interrupted; after the restart every attempt has too few contacts
    first = iter([G.REJECTIONS[1], None])
    monkeypatch.setattr(G, "_rejection", lambda *a, **k: next(first))
    task = resolve(RotationConfig(grasp_count=2))
    with pytest.raises(StopIteration):
        G.load_or_generate(task)
    monkeypatch.setattr(G, "_rejection", lambda *a, **k: G.REJECTIONS[5])
    with pytest.warns(UserWarning, match=r"only 1 of 2 starting states after 6 attempts; the others: too few hand contacts "
                                         r"\(4\), object fell \(1\)"):
        G.load_or_generate(task)


def test_a_hand_that_keeps_no_starting_state_is_told_why(tmp_path, monkeypatch):
    """D'Claw (a claw, not a palm-up hand) ended with "none of N perturbed grasps survived 1.5 s" and nothing on why:
    the error now counts each rejection reason, and says what most falls mean."""
    from ohra.sim.rotation import grasps as G

    monkeypatch.setenv("OHRA_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(G, "MAX_ATTEMPTS_PER_GRASP", 3)
    reasons = iter([G.REJECTIONS[1], G.REJECTIONS[1], G.REJECTIONS[5]])
    monkeypatch.setattr(G, "_rejection", lambda *a, **k: next(reasons))  # planted: two falls, one with too few contacts
    with pytest.raises(G.GraspGenerationError, match=r"none of 3 perturbed grasps survived .*: object fell \(2\), too few hand "
                                                   r"contacts \(1\) \(a hand that cannot hold the object palm up"):
        G.generate(resolve(RotationConfig(grasp_count=1)))


def test_a_hand_that_keeps_few_starting_states_is_told_why_too(tmp_path, monkeypatch):
    """The original Schunk SVH kept 1 of 20 states after 400 attempts: the warning said only the counts (every
    other settle had dropped the object)."""
    from ohra.sim.rotation import grasps as G

    monkeypatch.setenv("OHRA_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(G, "MAX_ATTEMPTS_PER_GRASP", 2)
    reasons = iter([None, G.REJECTIONS[1], G.REJECTIONS[1], G.REJECTIONS[5]])
    monkeypatch.setattr(G, "_rejection", lambda *a, **k: next(reasons))  # planted: one kept, then three rejected
    with pytest.warns(UserWarning, match=r"only 1 of 2 starting states after 4 attempts; the others: object fell \(2\), "
                                         r"too few hand contacts \(1\)"):
        G.generate(resolve(RotationConfig(grasp_count=2)))
