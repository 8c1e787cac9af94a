"""A hand of your own, from its spec YAML, through every step the README lists (toy URDFs written here).

What a new user meets that the registered hands never exercise: a spec passed to synthesis by path,
a palm piece that follows another joint and carries fingers, closely spaced fingers in the base
form, and a recipe naming a coupled spec.
"""

from __future__ import annotations

import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from ohra.canonical.couplings import Coupling
from ohra.canonical.kinematics import HandModel
from ohra.errors import OhraError
from ohra.original.parse import FINGER_GAP, ParseWarning, parse

# Two fingers (index, middle) 15 mm apart, each a proximal joint and a distal <mimic> joint, with
# cylinders of radius 8 mm (so the original's fingers are 16 mm wide). The middle finger hangs off a
# palm piece 'cup' that follows the index proximal joint through a <mimic> tag.
FINGER = """
  <link name="{f}1"><collision><origin xyz="0 0 0.02"/><geometry><cylinder radius="0.008" length="0.04"/></geometry></collision></link>
  <link name="{f}2"><collision><origin xyz="0 0 0.015"/><geometry><cylinder radius="0.008" length="0.03"/></geometry></collision></link>
  <link name="{f}_tip"/>
  <joint name="{f}_a" type="revolute"><parent link="{parent}"/><child link="{f}1"/><origin xyz="0 {y} 0.09"/><axis xyz="0 1 0"/><limit lower="0" upper="1.5"/></joint>
  <joint name="{f}_m" type="revolute"><parent link="{f}1"/><child link="{f}2"/><origin xyz="0 0 0.04"/><axis xyz="0 1 0"/><limit lower="0" upper="1.6"/>
    <mimic joint="{f}_a" multiplier="1.1" offset="0"/></joint>
  <joint name="{f}_t" type="fixed"><parent link="{f}2"/><child link="{f}_tip"/><origin xyz="0 0 0.03"/></joint>
"""
URDF = f"""<?xml version="1.0"?>
<robot name="toy_two_finger">
  <link name="palm"><collision><origin xyz="0 0 0.045"/><geometry><box size="0.02 0.06 0.09"/></geometry></collision></link>
  <link name="cup"/>
  <joint name="cup_j" type="revolute"><parent link="palm"/><child link="cup"/><origin xyz="0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="0" upper="0.2"/><mimic joint="index_a" multiplier="0.1" offset="0"/></joint>
{FINGER.format(f="index", parent="palm", y=0.0075)}
{FINGER.format(f="middle", parent="cup", y=-0.0075)}
</robot>
"""
SPEC = """name: toy_two_finger
urdf: toy_two_finger.urdf
palm_origin: {xyz: [0, 0, 0], rpy: [0, 0, 0]}
joints:
  index_joint2: index_a
  index_joint3: index_m
  middle_joint2: middle_a
  middle_joint3: middle_m
forms: {base: {}, extended: {}}
"""


@pytest.fixture
def spec(tmp_path, monkeypatch) -> Path:
    """The toy spec in its own folder (the hand-assets root points nowhere)."""
    monkeypatch.setenv("OHRA_HANDS_ROOT", str(tmp_path / "no_assets_here"))
    folder = tmp_path / "hands"
    folder.mkdir()
    (folder / "toy_two_finger.urdf").write_text(URDF)
    p = folder / "toy_two_finger.yaml"
    p.write_text(SPEC)
    return p


def test_synthesis_on_a_spec_path_writes_into_out_under_the_spec_name(spec, tmp_path):
    # an absolute spec path used to become the hand's folder name: out / "/abs/x.yaml/box.npz" is
    # "/abs/x.yaml/box.npz", a traceback (FileExistsError) and, for a relative path, a write outside out
    out = tmp_path / "grasps"
    r = subprocess.run([sys.executable, "-m", "ohra.synth", "--hand", str(spec.resolve()), "--objects", "builtin:sphere",
                        "--grasps-per-object", "1", "--no-filter", "--quiet", "-o", str(out)],
                       capture_output=True, text=True, timeout=240)
    assert r.returncode == 0, r.stderr
    assert "Traceback" not in r.stderr
    assert [p.name for p in (out / "toy_two_finger").glob("*.npz")] == [p.name for p in (out / "toy_two_finger").iterdir()]
    assert len(list((out / "toy_two_finger").glob("sphere-*.npz"))) == 1
    assert r.stdout.startswith("toy_two_finger: 1 solves")
    assert sorted(p.name for p in spec.parent.iterdir()) == ["toy_two_finger.urdf", "toy_two_finger.yaml"]


@pytest.mark.parametrize("name", ["my/hand.yaml", "ABSOLUTE", "..", ""])
def test_a_hand_name_that_is_a_path_is_refused_before_anything_is_written(tmp_path, name):
    name = str(tmp_path / "elsewhere") if name == "ABSOLUTE" else name
    from ohra.hands import get_hand
    from ohra.objects.model import ObjectModel
    from ohra.synth.pipeline import SynthSettings, synthesize

    with pytest.raises(OhraError, match="cannot name a dataset folder"):
        synthesize([(name, get_hand("leap_3303"))], [ObjectModel.builtin("sphere")], tmp_path / "out", SynthSettings())
    assert not (tmp_path / "out").exists() and not (tmp_path / "elsewhere").exists()


def test_an_unmapped_mimic_joint_that_carries_a_finger_is_named(spec):
    # 'cup' follows index_a and carries the middle finger: the canonical middle finger cannot follow it
    with pytest.warns(ParseWarning, match=r"'cup_j' \(mimic of 'index_a'\) moves the middle finger\(s\) but drives no slot"):
        res = parse(spec, "extended", fit_params=False)
    assert any("'cup_j'" in n and n.startswith("approximation: ") for n in res.notes)
    from ohra.original.fidelity import compare

    assert any("'cup_j'" in a for a in compare(res, "extended", samples=10, surface=False).approximations)


def test_base_fingers_that_would_intersect_at_rest_get_a_radius_that_separates_them(spec):
    # 8 mm fingers 15 mm apart: with the measured radius the parallel base-form fingers overlap by
    # 1 mm in every pose, so synthesis could never converge; the radius is capped instead, and noted
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ParseWarning)  # the 'cup' joint (the test above)
        res = parse(spec, "base", fit_params=False)
    assert res.params.finger_radius == pytest.approx(0.5 * (0.015 - FINGER_GAP), abs=2e-6)
    hm = HandModel.from_params(res.params)
    rest = np.clip(res.action_map.project(np.zeros(22)), hm.lower, hm.upper)
    assert hm.self_collision_pairs(rest, margin=FINGER_GAP - 1e-5) == []
    assert any(n.startswith("approximation: finger radius 8.00 -> 7.00 mm") for n in res.notes)
    # the extended form keeps its measured radii (its fingers sit where the original's do)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ParseWarning)
        ext = parse(spec, "extended", fit_params=False)
    assert ext.params.finger_radii[1] == pytest.approx(0.008, abs=1e-4)


def test_a_recipe_gives_synthesis_the_couplings_of_its_spec_hands(spec, tmp_path, monkeypatch):
    import ohra.synth.pipeline as pipeline
    from ohra.data.build import build

    recipe = tmp_path / "r.yaml"
    recipe.write_text(f"hands: [{{spec: {spec}, form: base}}, leap_3303]\nobjects: [builtin:sphere]\n")
    seen = {}
    monkeypatch.setattr(pipeline, "synthesize", lambda hands, *a, **k: seen.update({h[0]: h[2] for h in hands}) or {})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ParseWarning)
        build(recipe, out=tmp_path / "out", progress=False)
    assert seen["toy_two_finger"] == (Coupling("index_joint3", "index_joint2", 1.1, 0.0),
                                      Coupling("middle_joint3", "middle_joint2", 1.1, 0.0))
    assert seen["leap_3303"] == ()


# -- what `ohra hand` prints for such a hand --------------------------------------------------------
def _hand_cli(args: list[str], capsys) -> tuple[int, str, str]:
    from ohra.cli.main import main

    capsys.readouterr()
    rc = main(["hand", *args])
    out, err = capsys.readouterr()
    return rc, out, err


@pytest.mark.parametrize("extra", [[], ["--no-fidelity"]])
def test_parse_prints_each_coupling_and_approximation_once(spec, tmp_path, capsys, extra):
    # the notes used to be printed, then the fidelity table repeated their coupling and approximation
    # lines (and the unmapped 'cup_j' warning came a third time)
    rc, _, err = _hand_cli(["parse", str(spec), "--extended", "-o", str(tmp_path / "toy.json"), *extra], capsys)
    assert rc == 0, err
    lines = err.splitlines()
    assert [l for l in lines if l.startswith("coupling: index_joint3 = 1.1 * index_joint2")] != []
    for line in lines:
        if line.startswith(("coupling: ", "approximation: ")):
            assert lines.count(line) == 1, line
    assert len([l for l in lines if "'cup_j'" in l]) == 1


def test_parse_table_has_no_empty_surface_column(spec, tmp_path, capsys):
    # parse skips the (slow) surface distance: the table says so and how to get it, instead of a
    # column of "-"; --surface computes it as `ohra hand compare` does
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ParseWarning)
        rc, _, err = _hand_cli(["parse", str(spec), "--extended", "-o", str(tmp_path / "a.json")], capsys)
    assert rc == 0, err
    table = err[err.index("toy_two_finger (extended)"):].splitlines()
    assert "surface" not in table[1] and not any(l.rstrip().endswith("-") for l in table[2:5])
    assert "surface: not computed; --surface adds it" in err
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ParseWarning)
        rc, _, err = _hand_cli(["parse", str(spec), "--extended", "--surface", "-o", str(tmp_path / "b.json")], capsys)
    assert rc == 0, err
    table = err[err.index("toy_two_finger (extended)"):].splitlines()
    assert table[1].split() == ["fingertip", "joint", "(axis", "line)", "surface"]
    hand_row = next(l for l in table if l.startswith("hand "))
    assert len(hand_row.split()) == 1 + 9 and "not computed" not in err  # mean / p95 / max of three columns


def test_info_on_a_spec_names_the_hand_and_lists_its_couplings(spec, capsys):
    rc, out, err = _hand_cli(["info", str(spec), "--extended"], capsys)
    assert rc == 0, err
    assert out.splitlines()[0].startswith("toy_two_finger  form=")  # the spec's name: key, not its path
    assert "couplings (slot = a * driver + b):" in out
    assert "  index_joint3 = 1.1 * index_joint2 + 0" in out and "  middle_joint3 = 1.1 * middle_joint2 + 0" in out
    rc, out, _ = _hand_cli(["info", str(spec), "--extended", "--json"], capsys)
    import json

    info = json.loads(out)
    assert info["hand"] == "toy_two_finger"
    assert [c.split("  (")[0] for c in info["couplings"]] == ["index_joint3 = 1.1 * index_joint2 + 0",
                                                             "middle_joint3 = 1.1 * middle_joint2 + 0"]
    rc, out, _ = _hand_cli(["info", "leap_3303"], capsys)  # an uncoupled hand has no couplings block
    assert rc == 0 and "couplings" not in out


def test_check_on_a_spec_lists_the_hand_by_its_name_not_its_path(spec, capsys):
    rc, out, err = _hand_cli(["check", str(spec)], capsys)
    assert rc == 0, err
    row = next(l for l in out.splitlines() if l.split() and l.split()[-1] == "ok")
    assert row.split()[0] == "toy_two_finger" and str(spec) not in out


@pytest.mark.parametrize("action", ["render", "info", "check", "compare", "show"])
def test_every_hand_argument_says_it_takes_a_spec_yaml_or_params_json(action):
    import argparse

    from ohra.cli.main import build_parser

    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    hand = next(a for a in sub.choices["hand"]._actions if isinstance(a, argparse._SubParsersAction))
    arg = next(a for a in hand.choices[action]._actions if a.dest in ("hand", "hands"))
    assert "registered hand" in arg.help and "spec YAML" in arg.help and "params JSON" in arg.help, arg.help
    assert ("leap_XXXX" in arg.help) == (action != "compare")  # compare needs the original hand


def test_compare_takes_a_params_json_in_its_own_form(spec, capsys):
    # compare (and show) take a hand in its natural form, as info and render do: extended params with no base
    # form compare in the extended form (they failed asking for --extended), a base params JSON in the base form
    from ohra.canonical.couplings import params_json
    from ohra.canonical.params import ExtendedParams

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ParseWarning)
        res = parse(spec, "extended", fit_params=False)
        base = parse(spec, "base", fit_params=False)
    d = res.params.to_dict()
    d["finger_radii"][1] = 0.006  # unequal radii: no base form
    path = spec.with_suffix(".json")  # beside its spec, so compare finds the original
    for extra in ([], ["--extended"]):
        path.write_text(params_json(ExtendedParams.from_dict(d), res.couplings))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ParseWarning)
            rc, out, err = _hand_cli(["compare", str(path), *extra, "--samples", "5", "--no-surface"], capsys)
        assert rc == 0, err
        assert out.startswith("toy_two_finger (extended)")
    path.write_text(params_json(base.params, base.couplings))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ParseWarning)
        rc, out, err = _hand_cli(["compare", str(path), "--samples", "5", "--no-surface"], capsys)
    assert rc == 0 and out.startswith("toy_two_finger (base)"), err


def test_form_defaults_of_a_spec_are_stated_where_the_user_picks_the_hand(spec, tmp_path):
    # `synth --hand SPEC.yaml` synthesises on the base form, a recipe's {spec: ...} entry on the extended
    # form: the behaviour, and the two places that say so (the --hand help, the recipe format)
    from ohra.canonical.params import BaseParams
    from ohra.cli.synth import _hands, build_parser
    from ohra.data import recipe as recipe_mod

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ParseWarning)
        assert isinstance(_hands(str(spec))[0][1], BaseParams)
        for entry in ({"spec": str(spec)}, str(spec)):
            rec = recipe_mod.Recipe.from_dict({"hands": [entry], "objects": ["builtin:sphere"]}, tmp_path / "r.yaml")
            assert [type(h[1]).__name__ for h in rec.resolve_hands()] == ["ExtendedParams"]
    help_text = " ".join(next(a for a in build_parser()._actions if a.dest == "hand").help.split())
    assert "spec YAML is parsed (with the fit) in its BASE form" in help_text
    assert "{spec: ...} entry defaults to extended" in help_text
    assert "form defaults to\n" in recipe_mod.__doc__ and "extended (a bare my_hand.yaml too)" in recipe_mod.__doc__


# Three fingers 20 mm apart with 8 mm radii; the ring finger hangs off a palm piece 'carrier' that
# tilts it toward the middle finger (about the palm normal) whenever the index finger flexes, as the
# Schunk SVH's ring/little carrier follows thumb opposition. The canonical base hand cannot follow it.
CARRIER_URDF = f"""<?xml version="1.0"?>
<robot name="toy_carrier">
  <link name="palm"><collision><origin xyz="0 0 0.045"/><geometry><box size="0.02 0.07 0.09"/></geometry></collision></link>
  <link name="carrier"/>
  <joint name="carrier_j" type="revolute"><parent link="palm"/><child link="carrier"/><origin xyz="0 -0.01 0.06"/><axis xyz="1 0 0"/>
    <limit lower="-1" upper="0"/><mimic joint="index_a" multiplier="-0.5" offset="0"/></joint>
{FINGER.format(f="index", parent="palm", y=0.02)}
{FINGER.format(f="middle", parent="palm", y=0.0)}
{FINGER.format(f="ring", parent="carrier", y=-0.01).replace('xyz="0 -0.01 0.09"', 'xyz="0 -0.01 0.03"')}
</robot>
"""
CARRIER_SPEC = """name: toy_carrier
urdf: toy_carrier.urdf
palm_origin: {xyz: [0, 0, 0], rpy: [0, 0, 0]}
joints: {index_joint2: index_a, index_joint3: index_m, middle_joint2: middle_a, middle_joint3: middle_m,
         ring_joint2: ring_a, ring_joint3: ring_m}
forms: {base: {}}
"""


def test_the_base_fit_keeps_finger_bases_apart_when_a_palm_piece_pulls_one_onto_its_neighbour(tmp_path, monkeypatch):
    # unbounded, the least-squares fit averaged the carrier's sweep into the ring finger's base and moved
    # it from y = -20 mm onto the middle finger's (+1.9 mm): parallel base fingers intersecting at rest,
    # on which synthesis rejects every grasp; the unfitted layout was fine
    monkeypatch.setenv("OHRA_HANDS_ROOT", str(tmp_path / "no_assets_here"))
    (tmp_path / "toy_carrier.urdf").write_text(CARRIER_URDF)
    (tmp_path / "toy_carrier.yaml").write_text(CARRIER_SPEC)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ParseWarning)  # the unmapped 'carrier_j'
        measured = parse(tmp_path / "toy_carrier.yaml", "base", fit_params=False)
        res = parse(tmp_path / "toy_carrier.yaml", "base", fit_params=True)
    assert measured.params.finger_xyz[1:4, 1] == pytest.approx([0.02, 0.0, -0.02], abs=1e-6)
    y = res.params.finger_xyz[1:4, 1]
    least = 2 * res.params.finger_radius + FINGER_GAP
    assert res.params.finger_radius == measured.params.finger_radius == pytest.approx(0.008)  # not shrunk instead
    assert y[0] - y[1] >= least - 1e-6 and y[1] - y[2] >= least - 1e-6
    assert res.fit.final_rms_mm < res.fit.initial_rms_mm  # still a fit
    hm = HandModel.from_params(res.params)
    rest = np.clip(res.action_map.project(np.zeros(22)), hm.lower, hm.upper)
    assert hm.self_collision_pairs(rest, margin=FINGER_GAP - 1e-5) == []
    said = [n for n in res.notes if "base fit would move the middle and ring finger bases" in n]
    assert len(said) == 1 and said[0].startswith("approximation: ") and "kept near its measured place" in said[0]


def test_fingers_that_no_radius_can_separate_are_named(tmp_path, monkeypatch):
    # index and middle 3 mm apart: a radius under 2 mm would be needed; the note says which fingers
    monkeypatch.setenv("OHRA_HANDS_ROOT", str(tmp_path / "no_assets_here"))
    urdf = CARRIER_URDF.replace('<origin xyz="0 0.02 0.09"/>', '<origin xyz="0 0.0015 0.09"/>').replace(
        '<origin xyz="0 0.0 0.09"/>', '<origin xyz="0 -0.0015 0.09"/>')
    (tmp_path / "toy_carrier.urdf").write_text(urdf)
    (tmp_path / "toy_carrier.yaml").write_text(CARRIER_SPEC)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ParseWarning)
        res = parse(tmp_path / "toy_carrier.yaml", "base", fit_params=False)
    said = [n for n in res.notes if "intersect at rest" in n]
    assert len(said) == 1 and said[0].startswith("approximation: canonical fingers intersect at rest (index and middle;")
    assert "no grasp can be synthesised" in said[0]


# The carrier hand on a wrist: 'forearm' -> wrist_j -> 'palm'.
WRIST_URDF = CARRIER_URDF.replace(
    '<link name="palm">',
    '<link name="forearm"/>\n  <joint name="wrist_j" type="revolute"><parent link="forearm"/><child link="palm"/>'
    '<axis xyz="0 1 0"/><limit lower="-0.5" upper="0.5"/></joint>\n  <link name="palm">',
)


@pytest.mark.parametrize("joint, said", [
    ("wrist_j", "error"),  # above the palm: moves the middle and ring fingers too
    ("carrier_j", "note"),  # a palm piece: moves the ring finger, not the middle
])
def test_a_finger_slot_on_a_joint_that_moves_every_other_finger_is_refused(tmp_path, monkeypatch, capsys, joint, said):
    """Mapping a wrist (or arm) joint to a finger slot parsed a wrong hand without a word (the palm
    frame rode on the forearm, Shadow's WRJ2 as index_joint1: 49 mm mean fingertip error, exit 0)."""
    monkeypatch.setenv("OHRA_HANDS_ROOT", str(tmp_path / "no_assets_here"))
    (tmp_path / "toy_wrist.urdf").write_text(WRIST_URDF)
    (tmp_path / "toy_wrist.yaml").write_text(
        CARRIER_SPEC.replace("toy_carrier", "toy_wrist").replace("index_joint2: index_a,", f"index_joint1: {joint}, index_joint2: index_a,"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ParseWarning)
        if said == "error":
            with pytest.raises(OhraError, match=r"toy_wrist\.yaml: slot 'index_joint1' maps joint 'wrist_j', which moves every "
                                                r"other finger too: middle \('middle_a' \.\.\.\), ring \('ring_a' \.\.\.\)"):
                parse(tmp_path / "toy_wrist.yaml", "base", fit_params=False)
            from ohra.cli import main

            assert main(["hand", "parse", str(tmp_path / "toy_wrist.yaml"), "-o", str(tmp_path / "p.json")]) == 2
            err = capsys.readouterr().err
            assert "above the palm" in err and "Traceback" not in err and not (tmp_path / "p.json").exists()
            return
        res = parse(tmp_path / "toy_wrist.yaml", "base", fit_params=False)
    said_notes = [n for n in res.notes if "'carrier_j', which also moves the ring" in n]
    assert len(said_notes) == 1 and said_notes[0].startswith("approximation: ")


@pytest.mark.parametrize("suffix", [".glb", ".ply"])
def test_an_original_urdf_with_meshes_pybullet_cannot_read_is_simulated_on_the_same_shape(spec, tmp_path, monkeypatch, suffix):
    """PyBullet rejects a URDF naming a .glb (or .ply, .off) mesh ("Cannot load URDF file": dex-urdf's
    *_glb hands gave a traceback in `ohra eval --original`); the mesh reaches it as a cached OBJ of
    the shape the parser measured."""
    import pybullet as pb
    import trimesh

    from ohra.sim.bullet import load_urdf_text
    from ohra.sim.hands import SimHand

    monkeypatch.setenv("OHRA_CACHE_DIR", str(tmp_path / "cache"))
    box = trimesh.creation.box((0.02, 0.06, 0.09))
    box.apply_translation((0.0, 0.0, 0.045))
    urdf_path = spec.parent / "toy_two_finger.urdf"
    aabbs = []
    for ext in (".obj", suffix):
        box.export(spec.parent / f"palm{ext}")
        text = URDF.replace('<origin xyz="0 0 0.045"/><geometry><box size="0.02 0.06 0.09"/></geometry>',
                            f'<geometry><mesh filename="palm{ext}"/></geometry>')
        assert text != URDF
        urdf_path.write_text(text)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ParseWarning)
            hand = SimHand.original_of(str(spec), "base")
        client = pb.connect(pb.DIRECT)
        try:
            body = load_urdf_text(hand.urdf, client, useFixedBase=True)
            aabbs.append(np.array(pb.getAABB(body, -1, physicsClientId=client)))
        finally:
            pb.disconnect(client)
    assert np.allclose(aabbs[0], aabbs[1], atol=1e-6), aabbs
    assert list((tmp_path / "cache" / "bullet_meshes").glob("palm-*.obj"))


# The carrier hand at the end of a two-joint arm: 'arm_base' -> shoulder_j -> 'upper' -> elbow_j -> 'lower' -> (fixed, 0.3 m) 'palm'.
ARM_URDF = CARRIER_URDF.replace(
    '<link name="palm">',
    '<link name="arm_base"/><link name="upper"><collision><geometry><box size="0.05 0.05 0.5"/></geometry></collision></link>'
    '<link name="lower"/>\n'
    '  <joint name="shoulder_j" type="revolute"><parent link="arm_base"/><child link="upper"/><origin xyz="0 0 0.1"/>'
    '<axis xyz="0 1 0"/><limit lower="-2" upper="2"/></joint>\n'
    '  <joint name="elbow_j" type="revolute"><parent link="upper"/><child link="lower"/><origin xyz="0 0 0.5"/>'
    '<axis xyz="0 1 0"/><limit lower="-2" upper="2"/></joint>\n'
    '  <joint name="flange" type="fixed"><parent link="lower"/><child link="palm"/><origin xyz="0 0 0.3"/></joint>\n'
    '  <transmission name="elbow_tr"><joint name="elbow_j"/></transmission>\n'
    '  <link name="palm">',
)


def test_a_hand_on_an_arm_is_parsed_below_its_root_link(tmp_path, monkeypatch):
    """dex-urdf's arm + hand assemblies: a spec names the hand's own root with root_link: and gets the
    hand alone (arm links, joints and transmissions dropped); without it the palm 0.9 m up the arm
    was refused as a units slip, and a palm frame at the arm's base blamed palm_origin alone."""
    monkeypatch.setenv("OHRA_HANDS_ROOT", str(tmp_path / "no_assets_here"))
    (tmp_path / "toy_carrier.urdf").write_text(CARRIER_URDF)
    (tmp_path / "toy_carrier.yaml").write_text(CARRIER_SPEC)
    (tmp_path / "toy_arm.urdf").write_text(ARM_URDF)
    arm_spec = CARRIER_SPEC.replace("toy_carrier", "toy_arm")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ParseWarning)  # the unmapped 'carrier_j'
        alone = parse(tmp_path / "toy_carrier.yaml", "base", fit_params=False)
        (tmp_path / "toy_arm.yaml").write_text(arm_spec.replace("palm_origin:", "root_link: palm\npalm_origin:"))
        on_arm = parse(tmp_path / "toy_arm.yaml", "base", fit_params=False)
        assert on_arm.params == alone.params
        assert "shoulder_j" not in on_arm.measurement.hand.joints and "upper" not in on_arm.measurement.hand.links
        (tmp_path / "toy_arm.yaml").write_text(arm_spec.replace("palm_origin:", "root_link: plam\npalm_origin:"))
        with pytest.raises(OhraError, match=r"root_link 'plam' is not a link of the URDF \(did you mean 'palm'"):
            parse(tmp_path / "toy_arm.yaml", "base", fit_params=False)
        (tmp_path / "toy_arm.yaml").write_text(arm_spec.replace("xyz: [0, 0, 0]", "xyz: [0, 0, 0.9]"))
        with pytest.raises(OhraError, match=r"0\.9 m from the root link .* a hand on an arm\? name the hand's own root link "
                                            r"with root_link:"):
            parse(tmp_path / "toy_arm.yaml", "base", fit_params=False)
        (tmp_path / "toy_arm.yaml").write_text(arm_spec)  # palm frame at the arm's base: fingers 0.9 m up +z
        with pytest.raises(OhraError, match=r"finger joints lie up to 1\.0 m from the palm frame: 2 movable joint\(s\) lie "
                                            r"between the URDF's root 'arm_base' and the palm link 'palm'"):
            parse(tmp_path / "toy_arm.yaml", "base", fit_params=False)
        (tmp_path / "toy_arm.yaml").write_text(arm_spec.replace("rpy: [0, 0, 0]", "rpy: [3.14159265, 0, 0]"))
        with pytest.raises(OhraError, match=r"point toward -z of the palm frame.*2 movable joint\(s\) lie between the URDF's "
                                            r"root 'arm_base' and the palm link 'palm': shoulder_j, elbow_j; if that is an arm"):
            parse(tmp_path / "toy_arm.yaml", "base", fit_params=False)
