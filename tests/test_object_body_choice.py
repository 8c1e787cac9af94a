"""Which body a mesh object is grasped and simulated as can be chosen (``body=``, ``--body``, a recipe's ``body:``),
and travels with the object: into dataset manifests, grasp files and the evaluation of either."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest
import trimesh

from ohra.errors import ObjectError, ObjectWarning
from ohra.objects.model import BODY_CHOICES, ObjectModel
from ohra.objects.resolve import resolve_objects

# a cup: 4 cm outer radius, 4 mm wall and 5 mm base, 9 cm tall; its hull holds x4.3 its volume
CUP_PROFILE = np.array([[0, 0], [0.04, 0], [0.04, 0.09], [0.036, 0.09], [0.036, 0.005], [0, 0.005]])


def _cup(folder: Path, with_decomposition: bool = False) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "cup.obj"
    trimesh.creation.revolve(CUP_PROFILE, sections=24).export(path)
    if with_decomposition:  # a coarse one: the base and four wall slabs
        parts = [trimesh.creation.box((0.08, 0.08, 0.005), trimesh.transformations.translation_matrix((0, 0, 0.0025)))]
        for x, y, ex, ey in ((0.038, 0, 0.004, 0.08), (-0.038, 0, 0.004, 0.08), (0, 0.038, 0.08, 0.004), (0, -0.038, 0.08, 0.004)):
            parts.append(trimesh.creation.box((ex, ey, 0.09), trimesh.transformations.translation_matrix((x, y, 0.045))))
        trimesh.util.concatenate(parts).export(folder / "collision_vhacd.obj")
    return path


def _load(path, **kw) -> ObjectModel:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ObjectWarning)
        obj = ObjectModel.load(path, **kw)
        obj.body  # noqa: B018 - its warnings are not what these tests are about
    return obj


def test_auto_takes_the_provided_decomposition_or_the_hull_whichever_is_nearer_and_each_can_be_asked_for(tmp_path):
    path = _cup(tmp_path, with_decomposition=True)
    auto, hull, provided = (_load(path, body=b) for b in ("auto", "hull", "provided"))
    assert hull.body.kind == "hull" and len(hull.body.pieces) == 1
    assert provided.body.kind == "provided:collision_vhacd.obj" and len(provided.body.pieces) == 5
    assert auto.body.kind in (hull.body.kind, provided.body.kind)
    # the body is what is simulated: volume, mass and the body hash follow the choice; the mesh does not
    assert hull.volume == pytest.approx(hull.mesh.convex_hull.volume)
    assert provided.volume < 0.5 * hull.volume
    assert hull.mesh_hash == provided.mesh_hash and hull.body_hash != provided.body_hash
    assert hull.describe()["body_choice"] == "hull" and provided.describe()["body"]["kind"] == "provided:collision_vhacd.obj"


def test_a_body_the_object_cannot_have_is_an_object_error_naming_what_is_missing(tmp_path):
    path = _cup(tmp_path)
    with pytest.raises(ObjectError, match=r"body 'provided' asked for, but it has no convex decomposition beside .*cup.obj "
                                          r"\(collision_vhacd.obj"):
        ObjectModel.load(path, body="provided").body  # noqa: B018
    open_cup = trimesh.creation.revolve(CUP_PROFILE[1:-1], sections=24)  # no base: open at the bottom
    assert not open_cup.is_watertight
    open_cup.export(tmp_path / "open.obj")
    with pytest.raises(ObjectError, match="body 'vhacd' needs a closed mesh"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ObjectWarning)
            ObjectModel.load(tmp_path / "open.obj", body="vhacd").body  # noqa: B018
    with pytest.raises(ObjectError, match="body must be one of auto, hull, provided, vhacd, got 'convex'"):
        ObjectModel.load(path, body="convex")
    with pytest.raises(ObjectError, match="body must be one of"):
        resolve_objects([str(path)], body="convex")


def test_built_in_and_procedural_shapes_keep_their_exact_solids_and_say_so(tmp_path):
    path = _cup(tmp_path)
    with pytest.warns(ObjectWarning, match=r"body 'hull' applies to objects read from files; builtin:box, procedural:box:3 keep "
                                           "its exact solid"):
        box, proc, cup = resolve_objects(["builtin:box", "procedural:box:3", str(path)], body="hull")
    assert box.body.kind == "primitives" and proc.body.kind == "primitives"
    assert cup.body_choice == "hull"


def test_a_dataset_object_is_read_again_at_its_scale_and_with_its_body(tmp_path):
    """A grasp dataset's manifest names each object by its source; training reads it from there. A millimetre mesh
    loaded with scale 0.001 was read back at scale 1 (another mesh hash: a DatasetError), and a chosen body as auto."""
    from ohra.learn.grasp.data import load_dataset_object

    mm = tmp_path / "cup_mm.obj"
    trimesh.creation.revolve(CUP_PROFILE * 1000, sections=24).export(mm)
    made = _load(mm, scale=0.001, body="hull")
    info = json.loads(json.dumps(made.describe()))  # as the manifest stores it
    again = load_dataset_object(tmp_path, made.name, info, {})
    assert again.mesh_hash == made.mesh_hash and again.body_hash == made.body_hash and again.body_choice == "hull"
    np.testing.assert_allclose(again.extents, made.extents)


def test_the_cli_offers_the_library_choices():
    from ohra.cli.main import BODY_CHOICES as CLI_CHOICES

    assert CLI_CHOICES == BODY_CHOICES


def test_ohra_eval_simulates_a_grasp_file_on_the_body_it_was_sampled_on(tmp_path, capsys):
    from ohra.cli.main import main

    path = _cup(tmp_path, with_decomposition=True)
    g = np.zeros((1, 31))
    g[0, 2], g[0, 3], g[0, 7] = 0.3, 1.0, 1.0  # a palm far above the cup: any body, same outcome
    out = tmp_path / "g.npz"
    np.savez(out, grasps=g, hand=np.array("barrett_hand"), object=np.array(str(path)), body=np.array("provided"),
             scale=np.array(1.0))
    assert main(["eval", str(out), "--hand", "barrett_hand", "--object", str(path), "-o", str(tmp_path / "r.json")]) == 0
    err = capsys.readouterr().err
    assert f"--body provided from {out}" in err
    report = json.loads((tmp_path / "r.json").read_text())
    assert "provided:collision_vhacd.obj" in json.dumps(report)
    assert main(["eval", str(out), "--hand", "barrett_hand", "--object", str(path), "--body", "hull",
                 "-o", str(tmp_path / "r2.json")]) == 0
    assert "--body provided from" not in capsys.readouterr().err
    assert '"kind": "hull"' in json.dumps(json.loads((tmp_path / "r2.json").read_text()))


@pytest.mark.e2e
def test_vhacd_can_be_asked_for_where_auto_would_keep_a_provided_decomposition(tmp_path, monkeypatch):
    monkeypatch.setenv("OHRA_CACHE_DIR", str(tmp_path / "cache"))
    path = _cup(tmp_path, with_decomposition=True)
    obj = _load(path, body="vhacd")
    assert obj.body.kind == "vhacd" and len(obj.body.pieces) > 1
    assert obj.volume < 0.6 * obj.mesh.convex_hull.volume  # it follows the cavity, where the hull fills it
