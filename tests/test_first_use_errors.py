"""Mistakes a first-time user makes with the library get an ohra error that names the fix, not a numpy or
Python error, nor an empty result (found by trying the README's examples as a new user)."""

from __future__ import annotations

import warnings

import numpy as np

import pytest

import ohra
from ohra import viz
from ohra.errors import DatasetError, GraspError, HandNotFoundError, ObjectError, OhraError, ParamsError


def test_a_hand_name_where_params_are_expected_says_to_resolve_it():
    for call in (ohra.render, ohra.HandModel.from_params):
        with pytest.raises(ParamsError, match=r"got str \(a hand name or file: pass ohra.get_hand\('leap_3303'\)\)"):
            call("leap_3303")


@pytest.mark.parametrize("n", [-1, 2.5, True])
def test_random_configurations_needs_a_whole_count(n):
    with pytest.raises(OhraError, match="n must be a whole number >= 0"):
        ohra.HandModel.from_params(ohra.get_hand("leap_3303")).random_configurations(n)


def test_an_unknown_form_is_an_error_not_an_empty_registry():
    assert ohra.hands.hands_in_form("base")
    with pytest.raises(HandNotFoundError, match="unknown form 'basic'"):
        ohra.hands.hands_in_form("basic")


def test_a_dataset_filtered_by_a_hand_it_does_not_hold_names_the_hands_it_holds(tmp_path):
    from ohra.data import GraspDataset
    from ohra.io import write_json

    write_json(tmp_path / "manifest.json", {"format": "ohra-grasps/1", "hands": {"leap_3303": {"shards": {}}}})
    assert GraspDataset(tmp_path, hands=["leap_3303"]).entries == []
    with pytest.raises(DatasetError, match=r"hand\(s\) \['leap_hnad'\] not in .*it holds leap_3303"):
        GraspDataset(tmp_path, hands=["leap_hnad"])


def _manifest(folder, hands: dict) -> None:
    from ohra.io import write_json

    write_json(folder / "manifest.json", {"format": "ohra-grasps/1", "hands": hands})


def test_a_dataset_filtered_by_an_object_it_does_not_hold_names_the_objects_it_holds(tmp_path):
    from ohra.data import GraspDataset

    shard = {"box-7fefc98d": {"object": {"name": "box"}}, "sphere-0a1b2c3d": {"object": {"name": "sphere"}}}
    _manifest(tmp_path, {"leap_3303": {"shards": shard}, "leap_2211": {"shards": {}}})
    assert len(GraspDataset(tmp_path, objects=["box"]).entries) == 1  # by name
    assert len(GraspDataset(tmp_path, objects=["sphere-0a1b2c3d"]).entries) == 1  # or by key
    assert GraspDataset(tmp_path, hands=["leap_2211"], objects=["box"]).entries == []  # held, not for that hand
    with pytest.raises(DatasetError, match=r"object\(s\) \['bxo'\] not in .*it holds 2 object\(s\): box, sphere"):
        GraspDataset(tmp_path, objects=["box", "bxo"])  # a typo was an empty selection


def test_one_hand_name_with_other_params_in_another_folder_is_refused(tmp_path):
    from ohra.data import GraspDataset

    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir(), b.mkdir()
    _manifest(a, {"my_hand": {"params_hash": "1111", "shards": {}}, "leap_3303": {"params_hash": "33", "shards": {}}})
    _manifest(b, {"my_hand": {"params_hash": "2222", "shards": {}}, "leap_3303": {"params_hash": "33", "shards": {}}})
    assert GraspDataset([a, b], hands=["leap_3303"]).entries == []  # same name, same params: one hand
    with pytest.raises(DatasetError, match=r"hand 'my_hand' has different params in these folders \(1111 in .*a; 2222 in .*b\)"):
        GraspDataset([a, b])  # e.g. a spec's base form in one folder, its extended form in the other


def test_the_evaluator_takes_an_object_spec_as_the_cli_does():
    from ohra.sim import GraspEvaluator

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ev = GraspEvaluator(ohra.get_hand("leap_3303"), "builtin:box")
    assert ev.obj.name == "box"
    with pytest.raises(ObjectError, match=r"not found: box \(the built-in object: builtin:box\)"):
        GraspEvaluator(ohra.get_hand("leap_3303"), "box")
    with pytest.raises(OhraError, match="hand must be params, a hand name or a SimHand, got int"):
        GraspEvaluator(3, "builtin:box")


def test_evaluate_model_takes_one_hand_by_itself():
    """A lone name is one hand, not a sequence of one-letter hands (the check fails on the path, not on '/')."""
    from ohra.learn.grasp.evaluate import evaluate_model

    with pytest.raises(HandNotFoundError, match=r"params file not found: /nowhere/hand.json"):
        evaluate_model(object(), "/nowhere/hand.json", "builtin:box", n=1, inertials="original", allow_seen=True)
    with pytest.raises(GraspError, match=r"--original\): leap_2211 is a LEAP variant, a canonical hand with no original URDF"):
        evaluate_model(object(), "leap_2211", "builtin:box", n=1, original=True, allow_seen=True)


def test_evaluate_model_refuses_a_bad_seed_protocol_or_a_repeated_hand_or_object_before_simulating(tmp_path):
    from ohra.learn.grasp.evaluate import evaluate_model
    from ohra.learn.grasp.model import load_grasp_model

    leap = load_grasp_model("leap")
    with pytest.raises(GraspError, match="seed must be a whole number >= 0, got -1"):
        evaluate_model(leap, "leap_2211", "procedural:box:1234", n=1, seed=-1)
    with pytest.raises(GraspError, match=r"seed must be below 2\*\*63, got 9223372036854775808"):  # not storable as int64
        evaluate_model(leap, "leap_2211", "procedural:box:1234", n=1, seed=2**63)
    with pytest.raises(GraspError, match=r"seed must be below 2\*\*63"):  # was a traceback when the .npz was written
        leap.sample("leap_2211", "procedural:box:1234", 1, seed=2**63)
    with pytest.raises(GraspError, match="unknown protocol preset 'nosuch'"):
        evaluate_model(leap, "leap_2211", "procedural:box:1234", n=1, protocol="nosuch")
    with pytest.raises(GraspError, match="protocol must be an ohra.sim.Protocol, a preset name or None, got int"):
        evaluate_model(leap, "leap_2211", "procedural:box:1234", n=1, protocol=3)
    with pytest.raises(GraspError, match=r"hand\(s\) \['leap_2211'\] given more than once"):
        evaluate_model(leap, ["leap_2211", "leap_2211"], "procedural:box:1234", n=1)
    spelled = tmp_path / "mine.json"  # the same hand by another spelling was counted twice, with the same grasps
    spelled.write_text(ohra.get_hand("leap_2211").to_json())
    with pytest.raises(GraspError, match=r"hands \['leap_2211', '.*mine.json'\] are the same hand"):
        evaluate_model(leap, ["leap_2211", str(spelled)], "procedural:box:1234", n=1)
    with pytest.raises(GraspError, match=r"object\(s\) \['box-1234'\] given more than once"):
        evaluate_model(leap, "leap_2211", ["procedural:box:1234", "procedural:box:1234"], n=1)


def test_evaluate_model_takes_a_protocol_preset_by_name(monkeypatch):
    from ohra.learn.grasp.evaluate import evaluate_model
    from ohra.learn.grasp.model import load_grasp_model
    from ohra.sim import Protocol

    rep = evaluate_model(load_grasp_model("leap"), "leap_2211", "procedural:box:1234", n=1, protocol="strict")
    assert rep.meta["protocol"] == Protocol.strict().__dict__


def test_evaluate_model_simulates_a_coupled_hand_with_its_couplings_as_ohra_eval_does(monkeypatch):
    """Inspire's coupled joints follow their drivers in simulation (``ohra eval`` and synthesis do so)."""
    from ohra.hands import get_couplings
    from ohra.learn.grasp.evaluate import evaluate_model
    from ohra.learn.grasp.model import load_grasp_model
    from ohra.sim import SimHand

    seen = []
    real = SimHand.from_params.__func__

    def spy(cls, params, name="canonical_hand", couplings=()):
        seen.append(tuple(couplings))
        return real(cls, params, name=name, couplings=couplings)

    monkeypatch.setattr(SimHand, "from_params", classmethod(spy))
    evaluate_model(load_grasp_model(), "inspire_hand_left", "procedural:box:1234", n=1)
    assert get_couplings("inspire_hand_left") and seen == [get_couplings("inspire_hand_left")]


def test_load_grasp_model_names_what_it_takes():
    from ohra.learn.grasp.model import load_grasp_model

    with pytest.raises(OhraError, match="a grasp model is a shipped name .*, a folder or a .pt file, got int"):
        load_grasp_model(3)


def test_a_scale_given_for_a_built_in_or_procedural_shape_is_said_to_change_nothing():
    from ohra.errors import ObjectWarning
    from ohra.objects.resolve import resolve_objects

    with pytest.warns(ObjectWarning, match=r"scale 0.001 applies to objects read from files; procedural:box:7 keeps its own size"):
        (box,) = resolve_objects("procedural:box:7", scale=0.001)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert resolve_objects("procedural:box:7")[0].mesh_hash == box.mesh_hash  # same shape, no warning without a scale
        resolve_objects("procedural:box:7", scale=1.0)


def test_the_object_point_the_evaluator_warns_about_can_be_set_on_the_command_line(tmp_path, monkeypatch):
    """The off-origin warning advises Protocol(object_point='com'); both evaluation commands can set it."""
    import numpy as np

    import ohra.learn.grasp.evaluate as grasp_eval
    import ohra.sim
    from ohra.cli.main import main

    class Seen(Exception):
        pass

    def spy_evaluator(hand, obj, protocol=None):
        raise Seen(protocol.object_point)

    monkeypatch.setattr(ohra.sim, "GraspEvaluator", spy_evaluator)
    np.save(tmp_path / "g.npy", np.zeros((1, 31)))
    for point in ("com", "frame"):
        with pytest.raises(Seen, match=f"^{point}$"):
            main(["eval", str(tmp_path / "g.npy"), "--hand", "leap_3303", "--object", "builtin:box", "--object-point", point])

    def spy_model_eval(model, hands, objs, **kw):
        raise Seen(kw["protocol"].object_point)

    monkeypatch.setattr(grasp_eval, "evaluate_model", spy_model_eval)
    with pytest.raises(Seen, match="^com$"):
        main(["grasp", "eval", "--hands", "leap_2211", "--objects", "builtin:box", "-n", "1", "--object-point", "com"])


def test_an_upper_case_object_prefix_names_the_lower_case_one():
    from ohra.objects.resolve import resolve_objects

    with pytest.raises(ObjectError, match=r"not found: BUILTIN:box \(the builtin object: builtin:box\)"):
        resolve_objects("BUILTIN:box")
    with pytest.raises(ObjectError, match=r"\(the procedural object: procedural:box:7\)"):
        resolve_objects("Procedural:box:7")


def test_ohra_eval_checks_every_output_and_option_before_writing_anything(tmp_path, capsys):
    import numpy as np

    from ohra.cli.main import main

    np.save(tmp_path / "g.npy", np.zeros((2, 31)))
    (tmp_path / "adir").mkdir()
    base = ["eval", str(tmp_path / "g.npy"), "--hand", "leap_3303", "--object", "builtin:box"]
    for extra, named in ((["-o", str(tmp_path / "r.json"), "--render", str(tmp_path / "adir")], "adir is a folder"),
                         (["-o", str(tmp_path / "r.json"), "--meshcat", str(tmp_path / "adir")], "adir is a folder"),
                         (["-o", str(tmp_path / "r.txt")], "-o must end in .json, got"),
                         (["--render", str(tmp_path / "x.txt")], "--render must end in .png, got"),
                         (["--meshcat", str(tmp_path / "x.png")], "--meshcat must end in .html, got"),
                         (["--limit", "0"], "--limit must be >= 1, got 0"),
                         (["--original", "--inertials", "original"], "give one of them")):
        assert main(base + extra) == 2, extra
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and named in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["adir", "g.npy"]  # no report, no temporary file


def test_a_hand_without_a_movable_joint_is_refused_by_every_simulation_by_name(tmp_path, capsys):
    """leap_0000 (no finger) and a hand whose every joint has upper == lower cannot be simulated: an ohra error
    naming the hand, and exit 2 from the CLI, not a numpy error from PyBullet's empty joint lists."""
    import dataclasses

    from ohra.cli import main
    from ohra.sim.hands import SimHand

    with pytest.raises(GraspError, match="'leap_0000' has no movable joint"):
        SimHand.from_params(ohra.get_hand("leap_0000"), name="leap_0000")
    p = ohra.get_hand("allegro_hand_left", "base")
    rigid = dataclasses.replace(p, joint_uppers=tuple(p.joint_lowers))
    with pytest.raises(GraspError, match="no movable joint"):
        SimHand.from_params(rigid, name="rigid")
    SimHand.from_params(p, name="allegro")  # one movable joint is enough: the check is not on the finger count
    for argv in (["rotate", "grasps", "--hand", "leap_0000", "--grasps", "2"],
                 ["grasp", "eval", "--hands", "leap_0000", "--objects", "builtin:box", "-n", "2"]):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert "no movable joint" in err and "Traceback" not in err


def test_a_spec_file_where_a_registered_hand_is_needed_says_how_to_register_it(tmp_path):
    from ohra.hands import registry

    spec = tmp_path / "trident.yaml"
    spec.write_text("name: trident\n")
    with pytest.raises(HandNotFoundError, match=rf"pass ohra --hands-path {tmp_path} .*and the spec's name"):
        registry.spec_path(str(spec))
    with pytest.raises(HandNotFoundError, match="unknown hand 'tridnet'; registered: ") as exc:
        registry.spec_path("tridnet")
    assert "--hands" not in str(exc.value)


def test_data_info_keeps_one_name_with_other_params_in_two_rows_and_counts_objects_without_a_split(tmp_path):
    from ohra.data.build import combined_summary, format_summary

    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir(), b.mkdir()
    shards = {"box-1": {"n_grasps": 3}, "sphere-2": {"n_grasps": 1}}
    _manifest(a, {"my_hand": {"params_hash": "1111aaaa", "shards": shards}, "leap_3303": {"params_hash": "33", "shards": shards}})
    _manifest(b, {"my_hand": {"params_hash": "2222bbbb", "shards": shards}, "leap_3303": {"params_hash": "33", "shards": shards}})
    rows = {r["hand"]: r["grasps"] for r in combined_summary([a, b])["rows"]}
    assert rows == {"my_hand [1111aaaa]": 4, "my_hand [2222bbbb]": 4, "leap_3303": 8}
    assert "2 objects (no train/test split: not built from a recipe)" in format_summary(combined_summary([a]))


def test_a_vae_given_to_a_params_conditioned_training_is_refused_not_ignored(tmp_path, capsys):
    pytest.importorskip("torch", reason="grasp training needs the learn extra")
    from ohra.cli.main import main

    assert main(["train", "grasp", "--data", str(tmp_path), "--condition", "params", "--vae", "my_vae", "-o",
                 str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--vae my_vae gives the VAE of --condition vae" in err
    assert not (tmp_path / "run").exists()


def test_an_interrupted_resumable_command_says_how_to_continue(tmp_path, capsys, monkeypatch):
    import ohra.synth.pipeline as pipeline
    from ohra.cli.main import main

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(pipeline, "synthesize", interrupted)
    assert main(["synth", "--hand", "leap_3303", "--objects", "builtin:box", "--out", str(tmp_path / "o")]) == 130
    assert capsys.readouterr().err == "ohra: interrupted; the same command with --resume continues it\n"


# -- odd arguments to the action map, the LEAP variants, the original loader and the viewer (they gave a numpy
#    or regex TypeError / ValueError, or a matmul message about gufunc signatures) -------------------------------
def _action_map():
    return ohra.resolve_hand("leap_hand_right").action_map()


@pytest.mark.parametrize("call, said", [
    (lambda am: am.to_canonical("abc"), "original joint vector must be numbers, got the string 'abc'"),
    (lambda am: am.to_original("x"), "canonical joint vector must be numbers"),
    (lambda am: am.wrist_to_canonical(np.eye(3)), r"wrist_to_canonical: the original root pose must be a 4x4 .* got shape \(3, 3\)"),
    (lambda am: am.wrist_to_original(np.full((4, 4), np.nan)), "wrist_to_original: the canonical palm pose holds non-finite"),
    (lambda am: ohra.ActionMap("abc", ["j1"]), "slots must be a mapping of canonical slot -> original joint"),
    (lambda am: ohra.ActionMap({}, "j1"), "original_joints must be a sequence of joint names"),
    (lambda am: ohra.SlotMap(3), "the original joint's name must be a non-empty string, got 3"),
])
def test_odd_action_map_arguments_are_mapping_errors(call, said):
    from ohra.errors import MappingError

    with pytest.raises(MappingError, match=said):
        call(_action_map())


def test_a_stack_of_wrist_poses_still_maps():
    am = _action_map()
    T = np.tile(np.eye(4), (3, 1, 1))
    np.testing.assert_allclose(am.wrist_to_original(am.wrist_to_canonical(T)), T, atol=1e-12)


def test_a_number_for_a_hand_name_is_a_hand_error():
    with pytest.raises(HandNotFoundError, match="3 is not a LEAP variant name"):
        ohra.hands.leap_variant(3)
    with pytest.raises(HandNotFoundError, match="unknown hand 3"):
        ohra.load_original(3)


@pytest.mark.parametrize("call, said", [
    (lambda vis: viz.add_points(vis, np.zeros((5, 2))), r"add_points: points must be an array of shape \(Nx3\), got \(5, 2\)"),
    (lambda vis: viz.add_points(vis, "pts"), "add_points: points must be"),
    (lambda vis: viz.add_frame(vis, np.eye(3)), r"add_frame: T must be an array of shape \(4x4\), got \(3, 3\)"),
    (lambda vis: viz.add_frame(vis, np.full((4, 4), np.inf)), "add_frame: T holds non-finite values"),
])
def test_odd_shapes_given_to_the_viewer_name_the_call(call, said):
    import meshcat

    vis = meshcat.Visualizer.__new__(meshcat.Visualizer)  # no server: the check comes before anything is drawn
    with pytest.raises(OhraError, match=said):
        call(vis)


def test_object_specs_may_be_paths_and_anything_else_is_named(tmp_path):
    import trimesh

    from ohra.objects.resolve import resolve_objects

    trimesh.creation.box(extents=(0.05, 0.05, 0.05)).export(tmp_path / "box.obj")
    assert [o.name for o in resolve_objects(tmp_path / "box.obj")] == [o.name for o in resolve_objects([tmp_path / "box.obj"])]
    for bad in ([None], [1], [""]):
        with pytest.raises(ObjectError, match="object spec"):
            resolve_objects(bad)


def test_original_joints_may_come_from_a_generator():
    am = ohra.ActionMap({"index_joint1": "j1"}, (n for n in ["j1", "j2"]))
    assert am.original_joints == ("j1", "j2")
