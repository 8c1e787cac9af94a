"""``ohra eval``: success line and JSON report; bad input is one line, exit 2, and no output file."""

from __future__ import annotations

import json

import numpy as np
import pytest

from ohra.cli.main import main

from sim_fixtures import pinch_box, pinch_grasp, pinch_hand


@pytest.fixture
def setup(tmp_path):
    hand = tmp_path / "pinch.json"
    pinch_hand().to_json(hand)
    mesh = tmp_path / "box.stl"
    pinch_box().mesh.export(str(mesh))
    grasps = tmp_path / "g.npz"
    np.savez(grasps, grasps=np.array([pinch_grasp(), pinch_grasp(dx=0.03)]))
    return tmp_path, hand, mesh, grasps


def _run(capsys, *argv):
    rc = main(["eval", *map(str, argv), "--quiet"])
    out = capsys.readouterr()
    return rc, out.out, out.err


def test_eval_reports_success_rate_and_writes_json(setup, capsys):
    tmp, hand, mesh, grasps = setup
    rc, out, err = _run(capsys, grasps, "--hand", hand, "--object", mesh, "-o", tmp / "r.json", "--render", tmp / "s.png")
    assert rc == 0 and "1/2 succeeded (50.0 %)" in out
    rep = json.loads((tmp / "r.json").read_text())
    assert rep["n"] == 2 and [g["success"] for g in rep["grasps"]] == [True, False]
    assert rep["form"] in ("base", "extended") and "grasps_made_for" not in rep  # a plain array: made for nothing known
    assert rep["protocol"]["friction"] == 3.0 and rep["object_info"]["mass_kg"] > 0
    assert (tmp / "s.png").read_bytes()[:4] == b"\x89PNG"
    assert rep["protocol"]["dt"] == pytest.approx(1 / 240)
    # every file it wrote is named on stderr (the report was not), the result on stdout
    assert f"wrote {tmp / 'r.json'}" in err and f"to {tmp / 's.png'}" in err and "wrote" not in out


def test_isaac_step_option_runs_the_literal_reference_step(setup, capsys):
    tmp, hand, mesh, grasps = setup
    rc, out, err = _run(capsys, grasps, "--hand", hand, "--object", mesh, "--isaac-step", "-o", tmp / "r.json")
    rep = json.loads((tmp / "r.json").read_text())
    assert rc == 0 and (rep["protocol"]["dt"], rep["protocol"]["substeps"]) == (0.01, 2)


@pytest.mark.parametrize("bad, match", [
    (lambda g: g[:, :30], "shape"),
    (lambda g: np.where(np.arange(31) == 4, np.nan, g), "NaN"),
    (lambda g: np.where((np.arange(31) >= 3) & (np.arange(31) < 9), 0.0, g), "not a rotation"),
])
def test_bad_grasps_are_one_line_exit_2_and_leave_no_report(setup, capsys, bad, match):
    tmp, hand, mesh, _ = setup
    f = tmp / "bad.npz"
    np.savez(f, grasps=bad(np.array([pinch_grasp(), pinch_grasp()])))
    rc, _, err = _run(capsys, f, "--hand", hand, "--object", mesh, "-o", tmp / "r.json")
    assert rc == 2 and match in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert not (tmp / "r.json").exists()
    assert not list(tmp.glob(".r.json*"))


def test_missing_or_empty_mesh_is_exit_2(setup, capsys):
    tmp, hand, _, grasps = setup
    rc, _, err = _run(capsys, grasps, "--hand", hand, "--object", tmp / "nope.obj", "-o", tmp / "r.json")
    assert rc == 2 and "not found" in err
    (tmp / "empty.obj").write_text("# no faces\n")
    rc, _, err = _run(capsys, grasps, "--hand", hand, "--object", tmp / "empty.obj", "-o", tmp / "r.json")
    assert rc == 2 and "no faces" in err
    assert not (tmp / "r.json").exists()


def test_joints_outside_limits_are_clamped_and_counted(setup, capsys):
    tmp, hand, mesh, _ = setup
    g = pinch_grasp()
    g[9 + 6] = 3.0  # index flexion beyond its 1.5 rad limit
    f = tmp / "oob.npz"
    np.savez(f, grasps=g[None])
    rc, out, err = _run(capsys, f, "--hand", hand, "--object", mesh, "-o", tmp / "r.json")
    assert rc == 0 and "clamped" in err and "1 clamped" in out
    assert json.loads((tmp / "r.json").read_text())["clamped_joints_grasps"] == 1


@pytest.mark.parametrize("original", [False, True])
def test_form_picks_the_canonical_hand_and_the_action_map(original, hands_dir):
    """Grasps made for Allegro's extended form (finger twist free) replay through the extended map."""
    from ohra.cli.eval import eval_hand
    from ohra.hands import get_hand

    for form in ("base", "extended"):
        h = eval_hand("allegro_hand_left", original, form)
        assert np.array_equal(h.canon_lower, np.asarray(get_hand("allegro_hand_left", form).joint_lowers))
    assert not np.array_equal(eval_hand("allegro_hand_left", original, "base").canon_lower,
                              eval_hand("allegro_hand_left", original, "extended").canon_lower)


def test_a_millimetre_mesh_is_named_and_scale_makes_it_the_same_object(setup, capsys):
    tmp, hand, mesh, grasps = setup
    mm = tmp / "box_mm.stl"
    pinch_box().mesh.apply_scale(1000.0).export(str(mm))
    rc, out, err = _run(capsys, grasps, "--hand", hand, "--object", mm, "--limit", "1")
    assert rc == 0 and "ohra: warning: object 'box_mm'" in err and "--scale 0.001" in err
    rc, out, err = _run(capsys, grasps, "--hand", hand, "--object", mm, "--scale", "0.001")
    assert rc == 0 and "1/2 succeeded (50.0 %)" in out and "warning" not in err


def test_a_dataset_folder_for_grasps_names_a_shard_to_pass_and_an_empty_file_says_nothing_ran(setup, capsys):
    tmp, hand, mesh, grasps = setup
    shard = tmp / "data" / "pinch" / "box-0123abcd.npz"
    shard.parent.mkdir(parents=True)
    np.savez(shard, grasps=np.array([pinch_grasp()]))
    rc, _, err = _run(capsys, tmp / "data", "--hand", hand, "--object", mesh)
    assert rc == 2 and "is a folder" in err and "pinch/box-0123abcd.npz" in err and len(err.strip().splitlines()) == 1
    empty = tmp / "empty.npz"
    np.savez(empty, grasps=np.zeros((0, 31)))
    report = tmp / "empty.json"
    rc, out, _ = _run(capsys, empty, "--hand", hand, "--object", mesh, "-o", report)
    assert rc == 0 and "holds no grasps; nothing was simulated" in out and "0/0" not in out
    written = json.loads(report.read_text())
    assert written["n"] == 0 and written["success_rate"] is None  # no grasps is not a 0 % success rate


def test_a_file_that_is_not_numpy_and_a_variant_replayed_on_its_original_say_what_is_wrong(tmp_path, capsys):
    report = tmp_path / "report.json"
    report.write_text("{}")
    rc, _, err = _run(capsys, report, "--hand", "leap_3303", "--object", "builtin:box")
    assert rc == 2 and "not a NumPy .npz/.npy file" in err and "pickled" not in err
    grasps = tmp_path / "g.npz"
    np.savez(grasps, grasps=np.zeros((1, 31)))
    rc, _, err = _run(capsys, grasps, "--hand", "leap_3303", "--object", "builtin:box", "--original")
    assert rc == 2 and "leap_3303 is a LEAP variant, a canonical hand with no original URDF" in err


def test_the_meshcat_scene_draws_the_form_that_was_simulated(setup, capsys, monkeypatch):
    """``--form extended --meshcat`` drew the name's default (base) hand beside the extended hand simulated."""
    from ohra.canonical.params import ExtendedParams
    from ohra import viz

    tmp, _, mesh, _ = setup
    drawn = []
    monkeypatch.setattr(viz, "add_grasp", lambda vis, hand, *a, **k: drawn.append(hand.params))
    monkeypatch.setattr(viz, "save_html", lambda vis, path: None)
    monkeypatch.setattr(viz, "new_visualizer", lambda: None)  # no meshcat server
    grasps = tmp / "a.npz"
    g = np.zeros((1, 31))
    g[0, 0], g[0, 3], g[0, 7] = 0.2, 1.0, 1.0  # palm 20 cm away, identity rotation: nothing to hold
    np.savez(grasps, grasps=g)
    for form, kind in (("extended", ExtendedParams), ("base", type(None))):
        rc, _, err = _run(capsys, grasps, "--hand", "allegro_hand_left", "--form", form, "--object", mesh, "--meshcat",
                          tmp / "m.html")
        assert rc == 0, err
        assert isinstance(drawn[-1], ExtendedParams) == (kind is ExtendedParams)


def test_a_sampled_grasp_file_says_which_hand_and_form_it_was_made_for(tmp_path, capsys, monkeypatch):
    """``ohra grasp sample`` records hand, form and model beside the grasps; ``ohra eval`` of that hand takes the
    form from the file (evaluating base-form grasps on the extended hand changed the outcome silently) and says
    so when --form asks for another one."""
    pytest.importorskip("torch", reason="sampling needs the learn extra")
    import ohra.cli.eval as cli_eval

    out = tmp_path / "g.npz"
    assert main(["grasp", "sample", "--hand", "allegro_hand_left", "--object", "builtin:box", "-n", "2", "-o", str(out)]) == 0
    with np.load(out) as d:
        assert (str(d["hand"]), str(d["form"]), str(d["model"])) == ("allegro_hand_left", "base", "default")
        assert d["grasps"].shape == (2, 31)
        # ... and what makes them again: the object, its mesh, the seed and the sampling options
        from ohra.objects.model import ObjectModel

        assert (str(d["object"]), str(d["object_name"]), str(d["object_hash"])) == (
            "builtin:box", "box", ObjectModel.builtin("box").mesh_hash)
        assert (int(d["seed"]), str(d["refine"]), int(d["candidates"]), bool(d["centre"]), str(d["condition_hand"])) == (
            0, "none", 1, False, "")
    forms = []
    real = cli_eval.eval_hand
    monkeypatch.setattr(cli_eval, "eval_hand", lambda name, original, form, inertials: forms.append(form) or
                        real(name, original, form, inertials))
    capsys.readouterr()
    rc, said, err = _run(capsys, out, "--hand", "allegro_hand_left", "--object", "builtin:box")
    assert rc == 0 and forms[-1] == "base" and "note" not in err
    assert said.startswith("allegro_hand_left on box: ")  # the canonical hand; a replay names the original URDF
    from ohra.paths import hands_root

    if hands_root().is_dir():  # the replay needs the original URDF
        rc, said, _ = _run(capsys, out, "--hand", "allegro_hand_left", "--object", "builtin:box", "--original")
        assert rc == 0 and said.startswith("allegro_hand_left (original URDF) on box: ")
    rc, _, err = _run(capsys, out, "--hand", "allegro_hand_left", "--object", "builtin:box", "--form", "extended",
                      "-o", tmp_path / "ext.json")
    assert rc == 0 and forms[-1] == "extended" and "sampled for the base form of allegro_hand_left" in err
    # the report says which form it simulated and what the grasps were made for (two reports differed in outcomes only)
    rep = json.loads((tmp_path / "ext.json").read_text())
    assert (rep["hand"], rep["form"]) == ("allegro_hand_left", "extended")
    assert rep["grasps_made_for"] == {"hand": "allegro_hand_left", "form": "base", "object_name": "box",
                                      "object_hash": ObjectModel.builtin("box").mesh_hash}


def test_a_dataset_shard_evaluated_on_another_hand_or_object_says_so(tmp_path, capsys):
    """A shard's manifest records its hand and object: box grasps scored on a sphere read as a plausible 50 %
    with no word that they were made for another object."""
    from ohra.cli.synth import main as synth

    assert synth(["--hand", "leap_3303", "--objects", "builtin:box", "--grasps-per-object", "1", "--robust-trials", "0",
                  "--no-filter", "-o", str(tmp_path / "d"), "--quiet"]) == 0
    shard = str(next((tmp_path / "d" / "leap_3303").glob("box-*.npz")))
    capsys.readouterr()
    assert main(["eval", shard, "--hand", "leap_3303", "--object", "builtin:box", "--quiet"]) == 0
    assert "note" not in capsys.readouterr().err
    assert main(["eval", shard, "--hand", "leap_3303", "--object", "builtin:sphere", "--quiet"]) == 0
    err = capsys.readouterr().err
    assert f"{shard} holds grasps of box (mesh " in err and "evaluating them on --object builtin:sphere" in err
    assert main(["eval", shard, "--hand", "leap_2220", "--object", "builtin:box", "--quiet"]) == 0
    assert f"{shard} was synthesised for leap_3303; evaluating it on --hand leap_2220" in capsys.readouterr().err
    # another hand in another form: both are said (only the hand was)
    from ohra.hands import get_hand

    form = "extended" if "finger_radii" in get_hand("leap_3303").to_dict() else "base"
    other = "base" if form == "extended" else "extended"
    assert main(["eval", shard, "--hand", "allegro_hand_left", "--form", other, "--object", "builtin:box", "--quiet"]) == 0
    assert (f"{shard} was synthesised for the {form} form of leap_3303; evaluating it on --hand allegro_hand_left ({other} "
            "form)") in capsys.readouterr().err


def test_grasps_sampled_on_a_millimetre_mesh_are_evaluated_at_the_scale_they_were_sampled_at(setup, capsys):
    """`ohra grasp sample --scale 0.001` wrote no scale: `ohra eval` of the file on the same mesh without --scale read
    it in metres (an 80 m box: a size warning and 0 of 8) although the file said which object it was made for."""
    pytest.importorskip("torch", reason="sampling needs the learn extra")
    tmp, _, _, _ = setup
    mm = tmp / "box_mm.stl"
    pinch_box().mesh.apply_scale(1000.0).export(str(mm))
    out = tmp / "g_mm.npz"
    assert main(["grasp", "sample", "--hand", "allegro_hand_left", "--object", str(mm), "--scale", "0.001", "-n", "2",
                 "-o", str(out)]) == 0
    with np.load(out) as d:
        assert float(d["scale"]) == 0.001
    capsys.readouterr()
    rc, _, err = _run(capsys, out, "--hand", "allegro_hand_left", "--object", mm)
    assert rc == 0 and "--scale 0.001 from" in err and "warning" not in err and "holds grasps of" not in err
    rc, _, err = _run(capsys, out, "--hand", "allegro_hand_left", "--object", mm, "--scale", "1")  # as asked: the 80 m box
    assert rc == 0 and "ohra: warning: object 'box_mm'" in err and "--scale 0.001 from" not in err


def test_a_bare_object_word_lists_the_built_in_shapes_and_a_speck_names_its_units(tmp_path):
    """`--object cube` said only "not found"; a 3 cm torus given --scale 0.001 (meant for another, millimetre mesh)
    was called flat."""
    import trimesh

    from ohra.errors import ObjectError
    from ohra.objects.resolve import resolve_object

    with pytest.raises(ObjectError, match=r"not found: cube \(built-in objects: builtin:sphere, builtin:box.*procedural:FAMILY:SEED"):
        resolve_object("cube")
    with pytest.raises(ObjectError, match=r"not found: .*cube.obj$"):  # a file name gets no list
        resolve_object(str(tmp_path / "cube.obj"))
    torus = tmp_path / "torus.obj"
    trimesh.creation.torus(0.04, 0.015).export(str(torus))
    with pytest.raises(ObjectError, match=r"is flat: .*only 0.11 mm across, so its units are likely wrong"):
        resolve_object(str(torus), scale=0.001)
    sheet = tmp_path / "sheet.obj"  # a 10 cm sheet: flat, and not a units problem
    trimesh.Trimesh([[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0], [0.1, 0.1, 0]], [[0, 1, 2], [1, 3, 2]]).export(str(sheet))
    with pytest.raises(ObjectError, match=r"is flat: .*needs volume$"):
        resolve_object(str(sheet))


def test_the_form_note_suggests_the_hand_as_the_user_gave_it(tmp_path, capsys, hands_dir):
    """Grasps made for a spec hand's extended form, evaluated with --hand SPEC.yaml (its base form): the note
    suggested --hand NAME --form extended, a name that fails unless the spec's folder is registered."""
    from ohra.hands.registry import spec_path

    import re

    spec = tmp_path / "my_allegro.yaml"  # a user's spec, its folder not registered
    spec.write_text(re.sub(r"(?m)^name: .*$", "name: my_allegro", spec_path("allegro_hand_left").read_text()))
    spec = str(spec)
    g = tmp_path / "g.npz"
    np.savez(g, grasps=pinch_grasp()[None], hand=np.array("my_allegro"), form=np.array("extended"))
    rc, _, err = _run(capsys, g, "--hand", spec, "--object", "builtin:box", "--limit", "1")
    assert rc == 0 and f"(--hand {spec} --form extended evaluates the hand the grasps were made for)" in err


@pytest.mark.parametrize("preset", ["reference", "strict", "isaac-step", "isaac-drive"])
def test_eval_takes_the_protocol_preset_as_grasp_eval_does_and_its_flag_means_the_same(preset):
    """``ohra grasp eval --protocol X`` had no ``ohra eval`` spelling (only the flags ``--strict``, ``--isaac-*``)."""
    from ohra.cli.eval import protocol_of
    from ohra.cli.main import build_parser
    from ohra.sim import Protocol

    def parsed(*extra):
        return build_parser().parse_args(["eval", "g.npz", "--hand", "leap_3303", "--object", "builtin:box", *extra])

    assert protocol_of(parsed("--protocol", preset)) == Protocol.preset(preset)
    if preset != "reference":
        assert protocol_of(parsed(f"--{preset}")) == Protocol.preset(preset)


def test_a_shard_of_a_scaled_or_chosen_body_is_evaluated_as_it_was_made_by_any_path_to_its_file(tmp_path, capsys, monkeypatch):
    """A shard of a centimetre mesh made with --scale 0.01 was evaluated on the 9 m box unless --scale was given again
    (the manifest records it), and a grasp file's recorded scale was applied only when --object was the same string
    (an absolute path to the same file got the 9 m box)."""
    import trimesh

    from ohra.cli.synth import main as synth

    monkeypatch.chdir(tmp_path)
    (tmp_path / "objs").mkdir()
    trimesh.creation.box(extents=(5.0, 6.0, 9.0)).export(tmp_path / "objs" / "box_cm.stl")  # centimetres
    assert synth(["--hand", "leap_3303", "--objects", "objs/box_cm.stl", "--scale", "0.01", "--grasps-per-object", "1",
                  "--robust-trials", "0", "--no-filter", "-o", "d", "--quiet"]) == 0
    shard = str(next((tmp_path / "d" / "leap_3303").glob("box_cm-*.npz")))
    capsys.readouterr()
    for given in ("objs/box_cm.stl", str(tmp_path / "objs" / "box_cm.stl")):
        assert main(["eval", shard, "--hand", "leap_3303", "--object", given]) == 0
        err = capsys.readouterr().err
        assert f"--scale 0.01 from {shard} (the scale its grasps were synthesised at)" in err, err
        assert "holds grasps of" not in err and "m across" not in err
