"""Objects: repair of real meshes, SDF signs, analytic volumes of the built-ins, samples, errors."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from ohra import ObjectError
from ohra.errors import ObjectWarning
from ohra.objects.model import ObjectModel, builtin_object_names, farthest_point_sampling, load_convex_pieces
from ohra.objects.builtin import ANALYTIC_VOLUME


@pytest.mark.parametrize("name", list(ANALYTIC_VOLUME))
def test_builtin_volume_is_analytic_within_one_percent(name):
    o = ObjectModel.builtin(name)
    assert o.volume == pytest.approx(ANALYTIC_VOLUME[name], rel=0.01)
    assert o.mass == pytest.approx(o.volume * 500.0)


def test_builtins_include_a_non_convex_shape_with_convex_pieces():
    assert {"sphere", "box", "cylinder", "capsule", "ellipsoid"} <= set(builtin_object_names())
    o = ObjectModel.builtin("l_block")
    assert o.mesh.convex_hull.volume > 1.2 * o.volume
    assert len(o.convex_pieces()) == 2


def test_repaired_ycb_can_has_volume_and_consistent_sdf_signs(objects_dir):
    o = ObjectModel.load(objects_dir / "ycb" / "MasterChefCan")
    assert not o.repair_report.watertight_before
    assert o.volume > 0
    g = o.sdf()
    inside = g.query(o.center_mass[None])[0]
    outside = g.query((o.bounds[1] + 0.04)[None])[0]
    assert inside < -0.02 and outside > 0.03
    assert o.signed_distance(o.center_mass[None])[0] < 0


def test_an_open_box_closed_by_repair_is_said_and_recorded_but_a_merely_unwelded_mesh_is_not(objects_dir):
    """A box without its lid came out of repair watertight, so nothing downstream said that the open box is grasped as
    a solid one; YCB meshes are unwelded, not open (merging vertices closes them): no note for them."""
    box = trimesh.creation.box(extents=(0.06, 0.06, 0.08))
    top = np.flatnonzero(box.triangles_center[:, 2] > 0.039)
    lidless = trimesh.Trimesh(box.vertices, np.delete(box.faces, top, axis=0), process=False)
    with pytest.warns(ObjectWarning, match=r"'cup': the mesh was open; repair closed its holes with 2 face\(s\), 13.6 % of the "
                                           r"surface, so it is grasped and simulated as that closed solid \(volume 288 cm\^3\)"):
        o = ObjectModel(lidless, name="cup")
    rep = o.describe()["repair"]
    assert rep["filled_faces"] == 2 and rep["removed_faces"] == 0 and rep["filled_area_fraction"] == pytest.approx(36 / 264)
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error", ObjectWarning)
        can = ObjectModel(trimesh.load(objects_dir / "ycb" / "MasterChefCan" / "textured_simple_reoriented.obj", force="mesh"),
                          name="can")
    assert not can.repair_report.watertight_before and can.repair_report.filled_faces == 0
    # a hole filled while a bigger one stays open: the mesh is still open, and only that is said
    cyl = trimesh.creation.cylinder(radius=0.03, height=0.08, sections=24)
    keep = cyl.triangles_center[:, 2] < 0.039  # no lid
    side = np.flatnonzero(keep & (np.abs(cyl.triangles_center[:, 2]) < 0.03))[:1]  # and one side triangle missing
    keep[side] = False
    cup = trimesh.Trimesh(cyl.vertices, cyl.faces[keep], process=False)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        o = ObjectModel(cup, name="cup2")
        o.body
    texts = [str(w.message) for w in caught]
    assert o.repair_report.filled_faces >= 1 and not o.repair_report.watertight
    assert any("mesh is open" in t for t in texts) and not any("repair closed its holes" in t for t in texts), texts


def test_a_part_saved_inside_out_is_turned_outward_with_the_others():
    """Three separate parts, one with every face wound inward: repair oriented the mesh as one body, the inverted part's
    volume counted negative (104 of 132 cm^3) and the manifest said winding_consistent with no note."""
    box = trimesh.creation.box(extents=(0.04, 0.04, 0.04))
    ball = trimesh.creation.icosphere(subdivisions=2, radius=0.02).apply_translation((0.07, 0.0, 0.0))
    can = trimesh.creation.cylinder(radius=0.015, height=0.05).apply_translation((0.0, 0.07, 0.0))
    inverted = trimesh.Trimesh(ball.vertices, ball.faces[:, ::-1], process=False)
    truth = box.volume + ball.volume + can.volume
    o = ObjectModel(trimesh.util.concatenate([box, inverted, can]), "parts")
    assert o.repair_report.watertight and abs(float(o.mesh.volume)) == pytest.approx(truth, rel=1e-6)
    # an inward-facing part inside another is a cavity's wall, not a part saved inside out: it keeps its faces
    outer = trimesh.creation.icosphere(subdivisions=3, radius=0.05)
    wall = trimesh.creation.icosphere(subdivisions=3, radius=0.04)
    hollow = ObjectModel(trimesh.util.concatenate([outer, trimesh.Trimesh(wall.vertices, wall.faces[:, ::-1], process=False)]),
                         "hollow")
    assert float(hollow.mesh.volume) == pytest.approx(outer.volume - wall.volume, rel=1e-6)


def test_sdf_of_a_sphere_is_accurate():
    o = ObjectModel.builtin("sphere")
    pts = np.array([[0, 0, 0], [0.05, 0, 0], [0, 0.02, 0], [0, 0, -0.08]])
    exact = np.linalg.norm(pts, axis=1) - 0.035
    assert np.allclose(o.signed_distance(pts), exact, atol=1.5e-3)
    assert np.allclose(o.sdf().query(pts), exact, atol=3e-3)


def test_surface_samples_are_seeded_and_on_the_surface():
    o = ObjectModel.builtin("box")
    a, na = o.sample_surface(256, seed=3, oversample=4)
    b, _ = o.sample_surface(256, seed=3, oversample=4)
    assert np.array_equal(a, b) and a.shape == (256, 3)
    assert np.allclose(np.abs(o.signed_distance(a)), 0.0, atol=2e-3)
    assert np.allclose(np.linalg.norm(na, axis=1), 1.0)


@pytest.mark.parametrize("n", [0, -3])
def test_sampling_fewer_than_one_surface_point_is_an_error_naming_the_object(n):
    o = ObjectModel.builtin("sphere")
    with pytest.raises(ObjectError, match=rf"'sphere': sample_surface needs n >= 1 points, got {n}"):
        o.sample_surface(n)
    with pytest.raises(ObjectError, match=rf"got {n}"):
        o.sample_surface(n, oversample=4)


def test_farthest_point_sampling_spreads_points():
    pts = np.random.default_rng(0).random((500, 3))
    idx = farthest_point_sampling(pts, 20, seed=0)
    assert len(set(idx.tolist())) == 20


def _write_obj(path, meshes) -> None:
    """One OBJ file, one ``o`` object per mesh (the layout of V-HACD output)."""
    lines, base = [], 0
    for k, m in enumerate(meshes):
        lines.append(f"o piece{k}")
        lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in m.vertices]
        lines += [f"f {i + base + 1} {j + base + 1} {l + base + 1}" for i, j, l in m.faces]
        base += len(m.vertices)
    path.write_text("\n".join(lines) + "\n")


def test_urdf_object_applies_its_mesh_scale_to_the_mesh_and_the_convex_pieces(tmp_path):
    """A PyBullet-style object URDF with a non-uniform scale: the object (the built-in L block's mesh,
    non-convex, so its two provided convex pieces are used) is the scaled mesh, and so are its pieces."""
    ref = ObjectModel.builtin("l_block")
    _write_obj(tmp_path / "visual.obj", [ref.mesh])
    _write_obj(tmp_path / "collision.obj", ref.convex_pieces())
    scale = np.array([2.0, 0.5, 3.0])
    s = " ".join(f"{v:g}" for v in scale)
    (tmp_path / "model.urdf").write_text(
        f'<robot name="thing"><link name="base"><visual><geometry><mesh filename="visual.obj" scale="{s}"/></geometry></visual>'
        f'<collision><geometry><mesh filename="collision.obj" scale="{s}"/></geometry></collision></link></robot>')
    o = ObjectModel.load(tmp_path / "model.urdf")
    assert o.mesh.extents == pytest.approx(scale * ref.mesh.extents, rel=1e-6)
    pieces = o.convex_pieces()
    assert len(pieces) == 2
    assert sum(p.volume for p in pieces) == pytest.approx(np.prod(scale) * sum(p.volume for p in ref.convex_pieces()), rel=1e-9)
    for got, want in zip(sorted(p.bounds.tolist() for p in pieces), sorted((p.bounds * scale).tolist() for p in ref.convex_pieces())):
        assert np.allclose(got, want, atol=1e-6), (got, want)
    assert ObjectModel.load(tmp_path / "visual.obj").mesh.extents == pytest.approx(ref.mesh.extents, rel=1e-6)


def test_urdf_collision_mesh_takes_its_own_scale_not_the_visual_ones(tmp_path):
    """The ``<collision>`` mesh stored in millimetres (scale 0.001) beside a visual mesh in metres gives
    pieces in metres; a URDF with only a ``<collision>`` mesh scales the object by that mesh's scale."""
    ref = ObjectModel.builtin("l_block")
    _write_obj(tmp_path / "visual.obj", [ref.mesh])
    _write_obj(tmp_path / "collision_mm.obj", [p.copy().apply_scale(1000.0) for p in ref.convex_pieces()])
    (tmp_path / "model.urdf").write_text(
        '<robot name="thing"><link name="base"><visual><geometry><mesh filename="visual.obj"/></geometry></visual>'
        '<collision><geometry><mesh filename="collision_mm.obj" scale="0.001 0.001 0.001"/></geometry></collision></link></robot>')
    o = ObjectModel.load(tmp_path / "model.urdf")
    assert o.mesh.extents == pytest.approx(ref.mesh.extents, rel=1e-6)
    pieces = o.convex_pieces()
    assert len(pieces) == 2
    assert sum(p.volume for p in pieces) == pytest.approx(sum(p.volume for p in ref.convex_pieces()), rel=1e-6)
    (tmp_path / "collision_only.urdf").write_text(
        '<robot name="thing"><link name="base"><collision><geometry><mesh filename="visual.obj" scale="2 2 2"/>'
        '</geometry></collision></link></robot>')
    assert ObjectModel.load(tmp_path / "collision_only.urdf").mesh.extents == pytest.approx(2.0 * ref.mesh.extents, rel=1e-6)


def test_ycb_urdf_scale_is_applied(objects_dir):
    """MasterChefCan's URDF scales its mesh by 0.7."""
    a = ObjectModel.load(objects_dir / "ycb" / "MasterChefCan" / "model.urdf")
    b = ObjectModel.load(objects_dir / "ycb" / "MasterChefCan" / "textured_simple_reoriented.obj")
    assert a.mesh.extents == pytest.approx(0.7 * b.mesh.extents, rel=1e-6)


def test_missing_or_empty_mesh_is_a_clear_error(tmp_path):
    with pytest.raises(ObjectError, match="not found"):
        ObjectModel.load(tmp_path / "nope.obj")
    empty = tmp_path / "empty.obj"
    empty.write_text("# nothing\n")
    with pytest.raises(ObjectError, match="no faces"):
        ObjectModel.load(empty)
    with pytest.raises(ObjectError, match="unknown built-in object"):
        ObjectModel.builtin("teapot")


@pytest.mark.parametrize("suffix", [".ply", ".off", ".glb"])
def test_a_folder_holding_any_supported_mesh_type_loads_it_after_the_preferred_files(tmp_path, suffix):
    box = trimesh.creation.box((0.04, 0.05, 0.06))
    folder = tmp_path / "thing"
    folder.mkdir()
    box.export(folder / f"a{suffix}")
    o = ObjectModel.load(folder)
    assert o.name == "thing" and o.source == folder / f"a{suffix}"
    assert o.mesh.extents == pytest.approx([0.04, 0.05, 0.06], rel=1e-6)
    box.export(folder / "z.stl")  # .obj and .stl keep their precedence over the other types
    assert ObjectModel.load(folder).source == folder / "z.stl"


def test_loading_an_unsupported_path_names_every_supported_mesh_type(tmp_path):
    listed = r"\.obj, \.stl, \.ply, \.off, \.glb"
    (tmp_path / "notes.txt").write_text("no mesh here\n")
    with pytest.raises(ObjectError, match=rf"folder holds no mesh \({listed}\) or object URDF"):
        ObjectModel.load(tmp_path)
    with pytest.raises(ObjectError, match=rf"unsupported object file type '\.txt' \(use {listed} or \.urdf\)"):
        ObjectModel.load(tmp_path / "notes.txt")


@pytest.mark.parametrize("density", [0.0, -500.0, float("nan"), float("inf")])
def test_a_density_that_is_not_a_positive_number_is_an_error_naming_the_object(density):
    with pytest.raises(ObjectError, match=rf"object 'cube': density must be a finite number > 0 kg/m\^3, got {density}"):
        ObjectModel(trimesh.creation.box((0.05, 0.05, 0.05)), "cube", density=density)
    with pytest.raises(ObjectError, match=rf"object 'sphere': density .* got {density}"):
        ObjectModel.builtin("sphere", density=density)


def test_object_urdf_places_the_mesh_by_its_visual_origin(objects_dir):
    """MustardBottle's URDF turns the mesh 1.57 rad about z: the object frame is the URDF link frame."""
    a = ObjectModel.load(objects_dir / "ycb" / "MustardBottle" / "model.urdf")
    b = ObjectModel.load(objects_dir / "ycb" / "MustardBottle" / "textured_simple_reoriented.obj")
    Rz = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # 90 deg (1.57 ~ pi/2 to 1e-3 rad)
    assert np.allclose(np.sort(a.mesh.vertices @ np.eye(3), axis=0)[[0, -1]],
                       np.sort(b.mesh.vertices @ Rz.T, axis=0)[[0, -1]], atol=2e-4)


def test_sdf_grid_gradient_points_away_from_a_sphere():
    o = ObjectModel.builtin("sphere")
    g = o.sdf()
    pts = np.array([[0.05, 0.0, 0.0], [0.0, -0.06, 0.0], [0.0, 0.0, 0.045]])
    grad = g.gradient(pts)
    unit = pts / np.linalg.norm(pts, axis=1, keepdims=True)
    assert np.all((grad * unit).sum(axis=1) > 0.95)
    assert np.allclose(g.interpolant()(pts), g.query(pts), atol=1e-12)


def test_a_decomposition_file_gives_one_convex_piece_per_object(tmp_path):
    """V-HACD writes every piece as an OBJ object indexing one shared vertex list."""
    a = trimesh.creation.box(extents=(0.02, 0.02, 0.02))
    b = trimesh.creation.box(extents=(0.01, 0.04, 0.01))
    b.apply_translation((0.05, 0.0, 0.0))
    lines = [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in np.vstack([a.vertices, b.vertices])]
    lines.append("o piece0")
    lines += [f"f {i + 1} {j + 1} {k + 1}" for i, j, k in a.faces]
    lines.append("o piece1")
    lines += [f"f {i + 9} {j + 9} {k + 9}" for i, j, k in b.faces]
    path = tmp_path / "collision_vhacd.obj"
    path.write_text("\n".join(lines) + "\n")
    pieces = load_convex_pieces(path)
    assert sorted(round(p.volume * 1e6, 3) for p in pieces) == [4.0, 8.0]
    with pytest.raises(ObjectError, match="not found"):
        load_convex_pieces(tmp_path / "missing.obj")


def test_ycb_decompositions_cover_the_mesh_where_the_simulator_needs_them(objects_dir):
    """Concave YCB objects simulate as their provided pieces: together about the mesh's volume and bounds."""
    for name in ("Scissors", "PowerDrill", "MustardBottle"):
        o = ObjectModel.load(objects_dir / "ycb" / name)
        pieces = o.convex_pieces()
        assert len(pieces) > 1, name
        lo = np.min([p.bounds[0] for p in pieces], axis=0)
        hi = np.max([p.bounds[1] for p in pieces], axis=0)
        assert np.abs(lo - o.mesh.bounds[0]).max() < 0.005 and np.abs(hi - o.mesh.bounds[1]).max() < 0.005, name
        assert 0.9 < sum(p.volume for p in pieces) / o.volume < 1.6, name


def test_the_size_check_reads_the_mesh_and_never_builds_the_simulated_body():
    """Sampling and evaluation check an object's size first; a plausible object must not pay for (or warn
    about) a convex decomposition there."""
    from ohra.objects.model import ObjectModel
    from ohra.objects.resolve import size_problem, warn_if_ungraspable

    ball = ObjectModel(trimesh.creation.icosphere(radius=0.04), "ball")
    assert size_problem(ball) is None and not warn_if_ungraspable(ball)
    assert "body" not in vars(ball)  # the cached simulated body was never built
    big = ObjectModel(trimesh.creation.icosphere(radius=40.0), "ball_mm")
    assert "--scale 0.001" in size_problem(big)


def test_refusing_an_implausibly_sized_object_builds_no_body_and_warns_only_about_its_size():
    """A concave mesh in millimetres is refused for its size alone: no V-HACD run on the 80 m object
    first, no warning about how a convex body fits it, and the quoted mass is the mesh's."""
    import warnings

    from ohra.objects.model import ObjectModel
    from ohra.objects.resolve import size_problem

    ring = ObjectModel(trimesh.creation.torus(major_radius=30.0, minor_radius=10.0), "ring_mm")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # any warning fails
        problem = size_problem(ring)
    assert "--scale 0.001" in problem and "body" not in vars(ring)
    assert f"({abs(ring.mesh.volume) * 500.0:.4g} kg at 500 kg/m^3)" in problem


def test_a_folder_with_an_object_urdf_is_that_urdf_with_its_scale(tmp_path):
    """A PyBullet-style folder (a URDF scaling a mesh in other units, beside that mesh and its collision
    decomposition) is the object the URDF describes, whether named as the folder or found in a folder of
    objects; a folder of several loose meshes says which one it took."""
    import warnings

    from ohra.objects.model import ObjectModel
    from ohra.objects.resolve import resolve_objects

    duck = tmp_path / "objects" / "duck"
    duck.mkdir(parents=True)
    trimesh.creation.box((1.2, 1.0, 0.8)).export(duck / "duck.obj")  # in decimetres
    trimesh.creation.box((1.2, 1.0, 0.8)).export(duck / "duck_vhacd.obj")
    (duck / "duck_vhacd.urdf").write_text(
        '<robot name="duck"><link name="base"><visual><geometry><mesh filename="duck.obj" scale=".05 .05 .05"/>'
        '</geometry></visual><collision><geometry><mesh filename="duck_vhacd.obj" scale=".05 .05 .05"/></geometry>'
        '</collision></link></robot>')
    for o in (ObjectModel.load(duck), *resolve_objects([str(tmp_path / "objects")])):
        assert o.name == "duck" and o.source == duck / "duck_vhacd.urdf"
        assert o.mesh.extents == pytest.approx([0.06, 0.05, 0.04])
    cup = tmp_path / "cup"  # the URDF's meshes in a sub-folder: still one object, not a folder of objects
    (cup / "meshes").mkdir(parents=True)
    trimesh.creation.cylinder(radius=0.6, height=1.4).export(cup / "meshes" / "cup.obj")
    (cup / "cup_small.urdf").write_text('<robot name="cup"><link name="base"><visual><geometry>'
                                        '<mesh filename="meshes/cup.obj" scale=".05 .05 .05"/></geometry></visual></link></robot>')
    (o,) = resolve_objects([str(cup)])
    assert o.name == "cup" and o.mesh.extents == pytest.approx([0.06, 0.06, 0.07], rel=1e-3)
    loose = tmp_path / "loose"
    loose.mkdir()
    for n in ("bowl", "mug"):
        trimesh.creation.box((0.05, 0.06, 0.07)).export(loose / f"{n}.obj")
    with pytest.warns(ObjectWarning, match=r"holds 2 meshes \(bowl.obj, mug.obj\); loading bowl.obj"):
        assert ObjectModel.load(loose).source == loose / "bowl.obj"


def test_an_object_urdf_is_simulated_as_all_its_collision_elements(tmp_path):
    """A dumbbell URDF (like PyBullet's plate: several <collision> meshes plus a primitive) is grasped and
    simulated as the union of every collision element, not the first one or the convex hull of the whole:
    two 4 cm cubes 10 cm apart on a 1 cm bar weigh two cubes and a bar, not a 4 x 4 x 14 cm brick."""
    from ohra.objects.model import ObjectModel

    left, right = trimesh.creation.box((0.04,) * 3), trimesh.creation.box((0.04,) * 3)
    left.apply_translation([-0.05, 0, 0]); right.apply_translation([0.05, 0, 0])
    bar = trimesh.creation.box((0.06, 0.01, 0.01))
    trimesh.util.concatenate([left, right, bar]).export(tmp_path / "visual.obj")
    left.export(tmp_path / "left.obj"); right.export(tmp_path / "right.obj")
    col = '<collision><geometry><mesh filename="{}"/></geometry></collision>'
    (tmp_path / "dumbbell.urdf").write_text(
        '<robot name="dumbbell"><link name="base"><visual><geometry><mesh filename="visual.obj"/></geometry></visual>'
        + col.format("left.obj") + col.format("right.obj")
        + '<collision><geometry><box size="0.06 0.01 0.01"/></geometry></collision></link></robot>')
    o = ObjectModel.load(tmp_path / "dumbbell.urdf")
    assert o.body.kind.startswith("provided") and len(o.body.pieces) == 3
    assert o.volume == pytest.approx(2 * 0.04**3 + 0.06 * 0.01 * 0.01, rel=0.03)
    assert o.fidelity.within_tolerance


def test_object_urdfs_side_by_side_are_named_by_their_files(tmp_path):
    """pybullet_data keeps duck_vhacd.urdf and teddy_vhacd.urdf in one folder: both were named "data"
    (their folder), so reports read "on data" and GraspDataset(objects=["data"]) merged their grasps.
    The YCB layout's generic file names (model.urdf, textured*.obj, collision_vhacd.obj) still name
    the object by its folder."""
    flat = tmp_path / "data"
    flat.mkdir()
    for n, size in (("duck_vhacd", 0.05), ("teddy_vhacd", 0.08)):
        trimesh.creation.box((size, size, size)).export(flat / f"{n}.obj")
        (flat / f"{n}.urdf").write_text(f'<robot name="{n}"><link name="base"><visual><geometry><mesh filename="{n}.obj"/>'
                                        '</geometry></visual></link></robot>')
    assert [ObjectModel.load(flat / f"{n}.urdf").name for n in ("duck_vhacd", "teddy_vhacd")] == ["duck_vhacd", "teddy_vhacd"]
    ycb = tmp_path / "Banana"
    ycb.mkdir()
    trimesh.creation.box((0.05, 0.06, 0.07)).export(ycb / "textured_simple_reoriented.obj")
    trimesh.creation.box((0.05, 0.06, 0.07)).export(ycb / "collision_vhacd.obj")
    (ycb / "model.urdf").write_text('<robot name="b"><link name="base"><visual><geometry><mesh filename="textured_simple_reoriented.obj"/>'
                                    '</geometry></visual></link></robot>')
    for p in (ycb, ycb / "model.urdf", ycb / "textured_simple_reoriented.obj", ycb / "collision_vhacd.obj"):
        assert ObjectModel.load(p).name == "Banana", p


def test_every_visual_element_of_an_object_urdf_is_part_of_its_surface(tmp_path):
    """pybullet_data's pan_tefal.urdf: a pan mesh and a <cylinder> handle as two <visual> elements; only the
    first was read, so the grasp model's surface points and the body's distances knew no handle."""
    trimesh.creation.cylinder(radius=0.12, height=0.05).export(tmp_path / "pan.obj")
    (tmp_path / "pan.urdf").write_text(
        '<robot name="pan"><link name="base">'
        '<visual><geometry><mesh filename="pan.obj"/></geometry></visual>'
        '<visual><origin xyz="0.2 0 0" rpy="0 1.5707963 0"/><geometry><cylinder radius="0.01" length="0.18"/></geometry></visual>'
        '<collision><geometry><mesh filename="pan.obj"/></geometry></collision>'
        '<collision><origin xyz="0.2 0 0" rpy="0 1.5707963 0"/><geometry><cylinder radius="0.01" length="0.18"/></geometry></collision>'
        '</link></robot>')
    o = ObjectModel.load(tmp_path / "pan.urdf")
    assert o.mesh.bounds[:, 0] == pytest.approx([-0.12, 0.29], abs=1e-3)  # pan rim to handle end
    assert o.fidelity.p95 < 0.002  # the body (both collisions) follows the whole surface


def test_a_missing_further_visual_is_left_out_with_a_warning(tmp_path):
    """Reading every <visual> made a missing second visual mesh fatal ("object mesh not found") where it had been
    ignored; a bad visual primitive's size was reported as a <collision> one's."""
    trimesh.creation.cylinder(radius=0.05, height=0.05).export(tmp_path / "body.obj")
    urdf = ('<robot name="o"><link name="base"><visual><geometry><mesh filename="body.obj"/></geometry></visual>'
            '<visual><geometry>{}</geometry></visual></link></robot>')
    (tmp_path / "o.urdf").write_text(urdf.format('<mesh filename="gone.obj"/>'))
    with pytest.warns(ObjectWarning, match=r"a further <visual> is left out of the object's surface: .*gone\.obj"):
        o = ObjectModel.load(tmp_path / "o.urdf")
    assert o.mesh.extents == pytest.approx([0.1, 0.1, 0.05], abs=1e-3)
    (tmp_path / "o.urdf").write_text(urdf.format('<box size="0.1 x 0.1"/>'))
    with pytest.raises(ObjectError, match=r"a <visual> primitive with a missing or non-numeric size"):
        ObjectModel.load(tmp_path / "o.urdf")


@pytest.mark.parametrize("kw, message", [({"max_cells": 0}, "max_cells must be a whole number >= 1"),
                                         ({"spacing": -0.01}, "spacing must be a distance > 0"),
                                         ({"padding": float("nan")}, "padding must be a distance >= 0")])
def test_an_sdf_grid_that_cannot_be_made_is_an_object_error(kw, message):
    """max_cells=0 gave a (1, 1, 1) grid of spacing inf whose queries were NaN; a negative spacing a bare ValueError."""
    from ohra.errors import ObjectError

    with pytest.raises(ObjectError, match=message):
        ObjectModel.builtin("box").sdf(**kw)


def test_non_finite_vertices_used_by_faces_are_named_and_unused_ones_are_dropped():
    """A NaN vertex that faces use ended in numpy's 'SVD did not converge' traceback (exit 1) from every command."""
    box = trimesh.creation.box(extents=(0.04, 0.05, 0.06))
    v = box.vertices.copy()
    v[3] = np.nan
    with pytest.raises(ObjectError, match=r"object 'nan_box': 1 vertices used by its faces are not finite numbers \(NaN or "
                                          r"infinity\), e.g. vertex 3"):
        ObjectModel(trimesh.Trimesh(v, box.faces, process=False), "nan_box")
    spare = np.vstack([box.vertices, [[np.inf, 0.0, 0.0]]])  # no face uses it: repair drops it
    o = ObjectModel(trimesh.Trimesh(spare, box.faces, process=False), "spare")
    assert np.isfinite(o.mesh.vertices).all() and o.volume == pytest.approx(0.04 * 0.05 * 0.06, rel=1e-6)


def test_an_object_urdf_of_two_links_places_each_link_where_its_joint_puts_it(tmp_path):
    """A box with a handle on a second link (a fixed joint 5 cm up) was merged at the links' own origins, the handle
    buried in the box; a movable joint was merged without a word."""
    from ohra.errors import ObjectWarning

    trimesh.creation.box(extents=(0.06, 0.06, 0.04)).export(tmp_path / "base.obj")
    trimesh.creation.cylinder(radius=0.015, height=0.06).export(tmp_path / "handle.obj")
    link = '<link name="{0}"><visual><geometry><mesh filename="{0}.obj"/></geometry></visual>' \
           '<collision><geometry><mesh filename="{0}.obj"/></geometry></collision></link>'
    urdf = ('<?xml version="1.0"?><robot name="mug">' + link.format("base") + link.format("handle")
            + '<joint name="j" type="{}"><parent link="base"/><child link="handle"/><origin xyz="0 0 0.05"/></joint></robot>')
    (tmp_path / "two.urdf").write_text(urdf.format("fixed"))
    o = ObjectModel.load(tmp_path / "two.urdf")
    np.testing.assert_allclose(o.bounds, [[-0.03, -0.03, -0.02], [0.03, 0.03, 0.08]], atol=1e-6)
    (tmp_path / "hinged.urdf").write_text(urdf.format("revolute"))
    with pytest.warns(ObjectWarning, match=r"movable joint\(s\) j \(revolute\); ohra grasps one rigid object"):
        h = ObjectModel.load(tmp_path / "hinged.urdf")
    np.testing.assert_allclose(h.bounds, o.bounds, atol=1e-6)
