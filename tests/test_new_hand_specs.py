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
