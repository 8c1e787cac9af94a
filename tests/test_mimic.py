"""Coupled (mimic) joints end to end: parse, true fingertip, fidelity, guard rails, any hand in the CLI."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np

from ohra.hands import get_hand
import pytest

from ohra import cli
from ohra.canonical.couplings import Coupling, read_couplings
from ohra.canonical.kinematics import HandModel
from ohra.canonical.params import JOINT_INDEX, load_params
from ohra.errors import ParseError, SpecError
from ohra.hands import get_couplings, get_hand, registry
from ohra.original.fidelity import compare
from ohra.original.parse import ParseWarning, parse
from ohra.original.spec import load_spec

# A one-finger hand: proximal joint a (actuated), intermediate joint m follows a through <mimic>.
MIMIC_URDF = """<?xml version="1.0"?>
<robot name="toy_mimic">
  <link name="palm"><collision><geometry><box size="0.02 0.08 0.09"/></geometry><origin xyz="0 0 0.045"/></collision></link>
  <link name="l1"><collision><geometry><cylinder radius="0.008" length="0.04"/></geometry><origin xyz="0 0 0.02"/></collision></link>
  <link name="l2"><collision><geometry><cylinder radius="0.008" length="0.03"/></geometry><origin xyz="0 0 0.015"/></collision></link>
  <link name="tip"/>
  <joint name="a" type="revolute"><parent link="palm"/><child link="l1"/><origin xyz="0 0.02 0.09"/><axis xyz="0 1 0"/><limit lower="0" upper="1.5"/></joint>
  <joint name="m" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0 0 0.04"/><axis xyz="0 1 0"/><limit lower="-0.05" upper="1.6"/>
    <mimic joint="a" multiplier="1.2" offset="-0.05"/></joint>
  <joint name="t" type="fixed"><parent link="l2"/><child link="tip"/><origin xyz="0 0 0.03"/></joint>
</robot>
"""
MIMIC_SPEC = """name: toy_mimic
urdf: toy_mimic.urdf
palm_origin: [0, 0, 0, 0, 0, 0]
joints: {index_joint2: a, index_joint3: m}
forms: {extended: {}}
"""


def _toy(folder: Path, spec: str = MIMIC_SPEC, name: str = "toy_mimic.yaml") -> Path:
    (folder / "toy_mimic.urdf").write_text(MIMIC_URDF)
    p = folder / name
    p.write_text(spec)
    return p


@pytest.fixture
def no_hands_root(monkeypatch, tmp_path):
    """The hand-assets root points nowhere: a relative urdf path must resolve against the spec file."""
    monkeypatch.setenv("OHRA_HANDS_ROOT", str(tmp_path / "no_assets_here"))


def test_a_mapped_mimic_joint_becomes_a_coupling_and_the_finger_keeps_its_length(tmp_path, no_hands_root):
    res = parse(_toy(tmp_path), "extended", fit_params=True)
    assert res.couplings == (Coupling("index_joint3", "index_joint2", 1.2, -0.05),)
    assert any(n.startswith("coupling: index_joint3 = 1.2 * index_joint2") for n in res.notes)
    # canonical zero poses the mimic joint from its own slot (0): a straight finger, 0.09 + 0.04 + 0.03 long
    hm = HandModel.from_params(res.params)
    np.testing.assert_allclose(hm.fingertips(np.zeros(22))[1], [0.0, 0.02, 0.16], atol=2e-4)
    # coupled limits: what the driver's range [0, 1.5] gives
    k = JOINT_INDEX["index_joint3"]
    assert (res.params.joint_lowers[k], res.params.joint_uppers[k]) == pytest.approx((-0.05, 1.75))
    rep = compare(res, "extended", samples=40, surface=False)
    assert rep.tips["hand"].mean < 0.5 and rep.tips["hand"].n == 41


def test_a_prismatic_joint_in_a_revolute_slot_is_refused(tmp_path, no_hands_root):
    """Its metre limits were read as radians: a parse that passed with 1-2 m fingertip errors."""
    urdf = MIMIC_URDF.replace('<mimic joint="a" multiplier="1.2" offset="-0.05"/>', "")
    (tmp_path / "toy_mimic.urdf").write_text(urdf.replace('<joint name="m" type="revolute">', '<joint name="m" type="prismatic">'))
    spec = tmp_path / "toy.yaml"
    spec.write_text(MIMIC_SPEC)
    with pytest.raises(SpecError, match="slot 'index_joint3' names joint 'm', a prismatic joint"):
        parse(spec, "extended", fit_params=False)
    (tmp_path / "toy_mimic.urdf").write_text(urdf)  # the same hand with a revolute m parses
    assert parse(spec, "extended", fit_params=False).params is not None


def test_an_unmapped_mimic_joint_is_named_and_its_error_is_honest(tmp_path, no_hands_root):
    spec = _toy(tmp_path, MIMIC_SPEC.replace(", index_joint3: m", ""))
    with pytest.warns(ParseWarning, match=r"'m' \(mimic of 'a'\).*drive no slot"):
        res = parse(spec, "extended", fit_params=True)
    # the true fingertip is the end of l2 (moved by the mimic joint), never the end of the last mapped link
    assert res.measurement.fingers["index"].tip_link == "l2"
    rep = compare(res, "extended", samples=40, surface=False)
    assert rep.tips["hand"].mean > 5.0
    assert any("'m' (mimic of 'a')" in a for a in rep.approximations)
    assert "approximation:" in rep.table()


def test_a_mimic_joint_whose_driver_has_no_slot_drives_it_as_a_proxy(tmp_path, no_hands_root):
    """E.g. a spread joint moving a palm piece, mimicked by two fingers' abduction joints: map the mimics only."""
    spec = _toy(tmp_path, MIMIC_SPEC.replace("index_joint2: a, ", ""))
    res = parse(spec, "extended", fit_params=False)
    am = res.action_map
    assert am.mapped_original.tolist() == [True] and not res.couplings
    q = np.zeros(22)
    q[JOINT_INDEX["index_joint3"]] = 0.55
    assert am.to_original(q)[0] == pytest.approx((0.55 + 0.05) / 1.2)  # a = (m + 0.05) / 1.2
    np.testing.assert_allclose(am.to_canonical(am.to_original(q)), q, atol=1e-12)


def test_a_declared_coupling_travels_like_a_urdf_one(tmp_path, no_hands_root):
    urdf = MIMIC_URDF.replace('<mimic joint="a" multiplier="1.2" offset="-0.05"/>', "")
    (tmp_path / "free.urdf").write_text(urdf)
    spec = tmp_path / "free.yaml"
    spec.write_text(MIMIC_SPEC.replace("toy_mimic.urdf", "free.urdf")
                    + "couplings: [{slot: index_joint3, driver: index_joint2, multiplier: 0.5}]\n")
    res = parse(spec, "extended", fit_params=False)
    assert res.couplings == (Coupling("index_joint3", "index_joint2", 0.5, 0.0),)
    bad = tmp_path / "bad.yaml"
    bad.write_text(MIMIC_SPEC + "couplings: [{slot: index_joint4, driver: index_joint2, multiplier: 0.5}]\n")
    with pytest.raises(SpecError, match=r"couplings\[0\].*not both mapped"):
        load_spec(bad)


def test_yaml_syntax_errors_are_one_line_with_the_line_number(tmp_path):
    p = tmp_path / "broken.yaml"
    p.write_text("name: x\njoints: {index_joint2: a\nurdf: y\n")
    with pytest.raises(SpecError) as exc:
        load_spec(p)
    msg = str(exc.value)
    assert "\n" not in msg and "broken.yaml" in msg and "line 3" in msg and "invalid YAML" in msg


def test_cli_takes_a_spec_file_and_its_params_json(tmp_path, no_hands_root, capsys):
    spec = _toy(tmp_path)
    out = tmp_path / "toy.json"
    assert cli.main(["hand", "parse", str(spec), "--extended", "--fit", "-o", str(out), "--no-fidelity"]) == 0
    assert read_couplings(out) == (Coupling("index_joint3", "index_joint2", 1.2, -0.05),)
    assert get_couplings(out) == read_couplings(out) and get_hand(out).isclose(load_params(out), atol=0.0)
    capsys.readouterr()
    assert cli.main(["hand", "info", str(spec), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["fingertips_q0_m"]["index"][2] == pytest.approx(0.16, abs=2e-4)
    assert cli.main(["hand", "render", str(out), "-o", str(tmp_path / "toy.urdf")]) == 0
    # compare: a spec file directly, and a params JSON whose spec lies beside it under the same stem
    assert cli.main(["hand", "compare", str(spec), "--extended", "--samples", "20", "--no-surface"]) == 0
    assert "toy_mimic (extended)" in capsys.readouterr().out
    (tmp_path / "toy.yaml").write_text(spec.read_text())
    assert cli.main(["hand", "compare", str(out), "--extended", "--samples", "20", "--no-surface"]) == 0
    (tmp_path / "toy.yaml").unlink()
    assert cli.main(["hand", "compare", str(out), "--extended", "--samples", "20", "--no-surface"]) == 2
    assert "needs the original hand" in capsys.readouterr().err


def test_user_hand_folders_join_the_registry(tmp_path, no_hands_root, monkeypatch, capsys):
    folder = tmp_path / "my_hands"
    folder.mkdir()
    _toy(folder)
    assert "toy_mimic" not in registry.registered_hands()
    monkeypatch.setenv("OHRA_HANDS_PATH", "")  # the command appends to it; restored after the test
    assert cli.main(["--hands", str(folder), "hand", "list"]) == 0
    assert "toy_mimic" in capsys.readouterr().out
    # processes the command starts (worker pools, SubprocVecEnv under forkserver/spawn) see the folder too
    child = subprocess.run([sys.executable, "-c", "from ohra.hands.registry import registered_hands as r; print('toy_mimic' in r())"],
                           capture_output=True, text=True, timeout=120)
    assert child.stdout.strip() == "True", child.stderr
    registry._added.clear()
    monkeypatch.setenv("OHRA_HANDS_PATH", str(folder))
    assert registry.registered_forms("toy_mimic") == ["extended"]
    assert get_couplings("toy_mimic") == (Coupling("index_joint3", "index_joint2", 1.2, -0.05),)
    (folder / "dup.yaml").write_text(MIMIC_SPEC)
    with pytest.raises(SpecError, match="'toy_mimic' is defined twice"):
        registry.registered_hands()
    monkeypatch.setenv("OHRA_HANDS_PATH", str(tmp_path / "missing"))
    with pytest.raises(Exception, match="not a folder"):
        registry.registered_hands()


def test_a_user_hands_written_params_are_used_until_its_spec_is_edited(tmp_path, no_hands_root, monkeypatch):
    folder = tmp_path / "my_hands"
    folder.mkdir()
    spec = _toy(folder)
    monkeypatch.setenv("OHRA_HANDS_PATH", str(folder))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert registry.main(["toy_mimic"]) == 0  # the documented writer of DIR/params/<form>/<name>.json
    written = folder / "params" / "extended" / "toy_mimic.json"
    assert written.is_file() and (folder / "urdf" / "extended" / "toy_mimic.urdf").is_file()
    os.utime(written, ns=(spec.stat().st_mtime_ns + 10**9,) * 2)  # written after the spec: no fit on use
    marked = load_params(written).to_dict()
    marked["palm_radius"] = 0.031  # a value the parser would not give: shows which source was read
    written.write_text(json.dumps(marked))
    os.utime(written, ns=(spec.stat().st_mtime_ns + 10**9,) * 2)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert registry.registered_params("toy_mimic").palm_radius == pytest.approx(0.031)
    # the spec edited after the file was written: the file no longer describes the hand
    spec.write_text(MIMIC_SPEC + "overrides:\n  - {key: palm_radius, value: 0.04, reason: a thicker palm}\n")
    os.utime(spec, ns=(written.stat().st_mtime_ns + 1,) * 2)  # one nanosecond newer is enough
    with pytest.warns(UserWarning, match=r"toy_mimic\.json is older than .*toy_mimic\.yaml.*python -m ohra.hands.registry toy_mimic"):
        fresh = registry.registered_params("toy_mimic")
    assert fresh.palm_radius == pytest.approx(0.04)
    assert registry.couplings("toy_mimic") == (Coupling("index_joint3", "index_joint2", 1.2, -0.05),)


def test_show_fails_on_a_bad_name_before_starting_meshcat(monkeypatch, capsys):
    from ohra import viz

    def boom():  # pragma: no cover - the point is that it is never called
        raise AssertionError("meshcat started")

    monkeypatch.setattr(viz, "new_visualizer", boom)
    assert cli.main(["hand", "show", "no_such_hand", "--no-wait"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "unknown hand 'no_such_hand'" in err[0]



@pytest.fixture
def piped_viewer(monkeypatch):
    """`ohra hand show` with a stand-in viewer (no meshcat server) and stdin that is not a terminal."""
    import io

    from ohra import viz

    class Vis:
        def url(self):
            return "http://127.0.0.1:7000/static/"

    monkeypatch.setattr(viz, "new_visualizer", Vis)
    monkeypatch.setattr(viz, "show_hand", lambda *a, **k: None)
    monkeypatch.setattr("sys.stdin", io.StringIO(""))


def test_show_without_a_terminal_stops_the_viewer_instead_of_a_traceback(piped_viewer, capsys):
    """Piped or under CI, input() met end of file: an EOFError traceback after the URL."""
    assert cli.main(["hand", "show", "leap_3303"]) == 0
    assert "stdin is not a terminal: the viewer stops now" in capsys.readouterr().err

def test_show_no_wait_saves_a_page_that_outlives_the_command_and_says_when_there_is_none(tmp_path, capsys):
    """`--no-wait` printed the meshcat URL and exited, taking the server (and the page at that URL) with it."""
    page = tmp_path / "hand.html"
    assert cli.main(["hand", "show", "leap_3303", "--no-wait", "-o", str(page)]) == 0
    out = capsys.readouterr()
    assert f"wrote {page}" in out.err and "127.0.0.1" not in out.out + out.err
    html = page.read_text()
    assert "ohra: open framed on the content" in html  # a static export, framed on the hand
    assert cli.main(["hand", "show", "leap_3303", "--no-wait"]) == 0
    out = capsys.readouterr()
    assert "127.0.0.1" not in out.out and "-o PAGE.html saves a page that stays" in out.err


def test_show_says_which_joints_of_q_the_hand_cannot_take(piped_viewer, capsys):
    """`--q` of 3 rad everywhere was drawn past every limit, absent joints included, with no word."""
    from ohra.cli.hand import limits_note

    p = get_hand("leap_3303")
    lo, up = np.asarray(p.joint_lowers), np.asarray(p.joint_uppers)
    inside = np.where(p.present_joints, 0.5 * (lo + up), 0.0)
    assert limits_note(p, inside) == "" and limits_note(p, np.clip(inside, lo, up)) == ""
    q = inside.copy()
    q[JOINT_INDEX["index_joint2"]] = up[JOINT_INDEX["index_joint2"]] + 0.01
    assert limits_note(p, q) == (f"1 joint(s) outside the hand's limits, drawn as given: index_joint2 "
                                 f"{q[JOINT_INDEX['index_joint2']]:g} (limits {lo[JOINT_INDEX['index_joint2']]:.3g} to "
                                 f"{up[JOINT_INDEX['index_joint2']]:.3g})")
    q = inside.copy()
    q[JOINT_INDEX["middle_joint1"]] = 0.2  # leap_3303 has no middle finger
    assert limits_note(p, q) == "the hand has no middle_joint1 (its joints with both limits 0), drawn as given"
    assert cli.main(["hand", "show", "leap_3303", "--q", ",".join(["3.0"] * 22)]) == 0
    err = capsys.readouterr().err
    assert "ohra: note: --q: 12 joint(s) outside the hand's limits" in err and "the hand has no thumb_joint3" in err
    assert cli.main(["hand", "show", "leap_3303", "--q", ",".join(["nan"] + ["0"] * 21)]) == 2
    err = capsys.readouterr().err
    assert err == "ohra: error: --q: expected finite numbers, got nan at index 0\n"


# -- the Inspire hand (../shared) ------------------------------------------------------------------
@pytest.mark.assets
@pytest.mark.parametrize("form, target", [("extended", 2.0), ("base", 8.0)])
def test_inspire_meets_the_targets_against_the_true_fingertip(hands_dir, form, target):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rep = compare("inspire_hand_right", form, samples=60, surface=False)
    assert rep.tips["hand"].mean <= target
    assert len(rep.couplings) == 6 and not rep.approximations


@pytest.mark.assets
def test_inspire_fingers_are_full_length(hands_dir):
    """The canonical fingertips at canonical zero sit at the URDF's own *_tip frames (within the pad's
    few mm), not at the end of the last actuated link (the issue saw the index tip at z = 0.145 m)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        orig = registry.load_original("inspire_hand_right")
    am = registry.spec("inspire_hand_right").action_map("extended", orig)
    names = ["thumb_tip", "index_tip", "middle_tip", "ring_tip", "pinky_tip"]
    urdf_tips = orig.link_poses(am.to_original(np.zeros(22)), names, passive=am.passive_values(np.zeros(22)))[:, :3, 3]
    for form, tol in (("base", 0.010), ("extended", 0.006)):  # base: the four fingers share their lengths
        tips = HandModel.from_params(registry.registered_params("inspire_hand_right", form)).fingertips(np.zeros(22))
        assert np.all(np.linalg.norm(tips - urdf_tips, axis=1) < tol), form
        assert tips[1, 2] > 0.205


@pytest.mark.assets
def test_the_old_style_inspire_spec_is_not_called_near_perfect(hands_dir, tmp_path):
    text = registry.spec_path("inspire_hand_right").read_text()
    text = "\n".join(l for l in text.splitlines() if "_intermediate_joint" not in l and "thumb_distal_joint" not in l)
    spec = tmp_path / "old_style.yaml"
    spec.write_text(text.replace(f"urdf: inspire_hand/", f"urdf: {hands_dir}/inspire_hand/"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = parse(spec, "extended", fit_params=False)
    rep = compare(res, "extended", samples=30, surface=False)
    assert rep.tips["hand"].mean > 10.0  # measured at the true fingertip: 30-45 mm in the issue
    assert len([a for a in rep.approximations if "mimic of" in a]) == 5


@pytest.mark.assets
@pytest.mark.parametrize("signs", [False, True])
def test_a_mirrored_palm_frame_is_named_not_hidden_by_sign_advice(hands_dir, tmp_path, signs):
    import yaml

    d = yaml.safe_load(registry.spec_path("inspire_hand_right").read_text())
    d["palm_origin"]["rpy"] = [0.0, 0.0, float(np.pi)]
    d["urdf"] = str(hands_dir / d["urdf"])
    if signs:  # what following the axis check's 'use sign -1' advice gives: every flexion joint negated
        d["joints"] = {s: (j if s == "thumb_joint1" else {"joint": j, "sign": -1}) for s, j in d["joints"].items()}
    spec = tmp_path / "mirrored.yaml"
    spec.write_text(yaml.safe_dump(d))
    for form in ("base", "extended"):
        with pytest.raises(SpecError, match="curl toward -x.*named right.*Rotate palm_origin by pi about z") as exc:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                parse(spec, form, fit_params=False)
        assert ("sign flips" in str(exc.value)) == signs


@pytest.mark.assets
@pytest.mark.parametrize("yaw", [np.pi / 2, -np.pi / 2, 0.85, 0.6])
def test_a_palm_frame_turned_about_z_is_named_with_its_fix(hands_dir, tmp_path, yaw):
    """Turned by ~90 deg the fingers still point along +z and flex positively, but curl toward +-y: an error
    naming the turn that undoes it (also past 45 deg, 0.85 rad); 0.6 rad (34 deg) is left to the axis notes."""
    import yaml

    d = yaml.safe_load(registry.spec_path("inspire_hand_right").read_text())
    d["palm_origin"]["rpy"] = [0.0, 0.0, float(yaw)]
    d["urdf"] = str(hands_dir / d["urdf"])
    spec = tmp_path / "turned.yaml"
    spec.write_text(yaml.safe_dump(d))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if yaw == 0.6:
            parse(spec, "extended", fit_params=False)
            return
        with pytest.raises(SpecError, match=r"curl \d+ deg away from \+x.*palm_origin is rotated about z") as exc:
            parse(spec, "extended", fit_params=False)
    import re

    deg, fix = re.search(r"curl (\d+) deg away.*yaw ([+-][\d.]+)\)", str(exc.value)).groups()
    assert abs(int(deg) - np.degrees(abs(yaw))) <= 3 and abs(float(fix) + yaw) < 0.05  # the turn that undoes it


@pytest.mark.assets
@pytest.mark.parametrize("beyond", [True, False])
def test_a_palm_origin_beyond_the_knuckles_is_an_error_naming_them(hands_dir, tmp_path, beyond):
    """Placed 5 mm past the knuckles along +z the finger bases lie behind the origin (an error naming them);
    5 mm short of them it is a valid, if odd, palm frame."""
    import yaml

    d = yaml.safe_load(registry.spec_path("inspire_hand_right").read_text())
    assert d["palm_origin"]["xyz"] == [0.0, 0.0, 0.0] and d["palm_origin"]["rpy"] == [0.0, 0.0, 0.0]
    knuckle = min(float(get_hand("inspire_hand_right", "extended").joint_origins[r][2]) for r in (3, 5, 7))
    d["palm_origin"]["xyz"] = [0.0, 0.0, knuckle + (0.005 if beyond else -0.005)]
    d["urdf"] = str(hands_dir / d["urdf"])
    spec = tmp_path / "far.yaml"
    spec.write_text(yaml.safe_dump(d))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if not beyond:
            parse(spec, "extended", fit_params=False)
            return
        with pytest.raises(SpecError, match=r"finger bases \(index z = -5 mm.*lie behind the palm frame's origin"):
            parse(spec, "extended", fit_params=False)


@pytest.mark.assets
def test_a_finger_joint_forgotten_behind_its_mimic_is_named(hands_dir, tmp_path):
    import yaml

    d = yaml.safe_load(registry.spec_path("inspire_hand_right").read_text())
    del d["joints"]["index_joint2"]  # the actuated MCP; its mimic PIP (index_joint3) stays mapped
    d["urdf"] = str(hands_dir / d["urdf"])
    spec = tmp_path / "forgot.yaml"
    spec.write_text(yaml.safe_dump(d))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        notes = parse(spec, "extended", fit_params=False).notes
        full = parse(registry.spec_path("inspire_hand_right"), "extended", fit_params=False).notes
    named = [n for n in notes if "actuated joint 'index_proximal_joint' has no slot" in n]
    assert len(named) == 1 and "index_joint3 (mimic 'index_intermediate_joint')" in named[0]
    assert not any("has no slot; it moves with" in n for n in full)


@pytest.mark.assets
def test_a_relative_urdf_path_resolves_against_the_spec_file(hands_dir, tmp_path, monkeypatch):
    rel = os.path.relpath(hands_dir / "inspire_hand" / "inspire_hand_right.urdf", tmp_path)
    spec = tmp_path / "mine.yaml"
    spec.write_text(registry.spec_path("inspire_hand_right").read_text().replace("urdf: inspire_hand/inspire_hand_right.urdf", f"urdf: {rel}"))
    monkeypatch.setenv("OHRA_HANDS_ROOT", str(tmp_path / "nowhere"))
    assert load_spec(spec).urdf_path() == tmp_path / rel
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert parse(spec, "base", fit_params=False).hand.path.name == "inspire_hand_right.urdf"


@pytest.mark.assets
def test_flipped_mcp_flexion_signs_are_refused_in_the_extended_form_too(hands_dir, tmp_path):
    """The extended form measures j1/j2 axes freely (either may flex), but a flexion axis opposed to the finger's
    would make positive canonical angles extend the finger: it gets the base form's 'use sign' advice."""
    import yaml

    d = yaml.safe_load(registry.spec_path("inspire_hand_right").read_text())
    d["urdf"] = str(hands_dir / d["urdf"])
    for f in ("index", "middle", "ring", "little"):
        d["joints"][f"{f}_joint2"] = {"joint": d["joints"][f"{f}_joint2"], "sign": -1}
    spec = tmp_path / "flipped.yaml"
    spec.write_text(yaml.safe_dump(d))
    for form in ("base", "extended"):
        with pytest.raises(SpecError, match=r"_joint2.*with sign -1 its axis points opposite.*use sign \+1"):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                parse(spec, form, fit_params=False)


def test_hand_compare_checks_its_options_first_and_shows_missing_meshes(tmp_path, no_hands_root, capsys):
    """--samples below 1 was a traceback (negative) or a table of zero configurations (0); an --html folder was
    refused only after the comparison; a missing mesh, which changes the numbers, was silenced."""
    from ohra.cli.main import main

    spec = _toy(tmp_path, MIMIC_SPEC.replace("name: toy_mimic", "name: toy_nomesh"))
    urdf = (tmp_path / "toy_mimic.urdf").read_text()
    (tmp_path / "toy_mimic.urdf").write_text(urdf.replace(
        '<link name="l2">', '<link name="l2"><visual><geometry><mesh filename="meshes/l2.stl"/></geometry></visual>'))
    for argv, named in ((["--samples", "0"], "--samples must be >= 1"), (["--samples", "-5"], "--samples must be >= 1"),
                        (["--html", str(tmp_path)], "is a folder")):
        assert main(["hand", "compare", str(spec), "--no-surface", *argv]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and named in err, err
    assert main(["hand", "compare", str(spec), "--no-surface", "--samples", "3"]) == 0
    err = capsys.readouterr().err
    assert "1 mesh file(s) not found" in err and "l2.stl" in err


@pytest.mark.parametrize("rpy, off", [("0, 1.0, 0", 57), ("0, -1.0, 0", 57), ("1.2, 0, 0", 69)])
def test_a_palm_frame_tilted_past_45_degrees_is_refused(tmp_path, no_hands_root, rpy, off):
    """A roll or pitch in palm_origin passed (only a yaw or a reversed +z were caught) and parsed into centimetres
    of fingertip error; within 45 degrees it is the parse's business (the registered hands: within 32)."""
    spec = _toy(tmp_path, MIMIC_SPEC.replace("palm_origin: [0, 0, 0, 0, 0, 0]", f"palm_origin: [0, 0, 0, {rpy}]"))
    with pytest.raises(SpecError, match=rf"point {off} deg away from \+z of the palm frame .*palm_origin is tilted"):
        parse(spec, "extended", fit_params=False)
    ok = _toy(tmp_path, MIMIC_SPEC.replace("palm_origin: [0, 0, 0, 0, 0, 0]", "palm_origin: [0, 0, 0, 0, 0.7, 0]"), "ok.yaml")
    assert parse(ok, "extended", fit_params=False).params is not None  # 40 deg: parsed


def test_hand_parse_of_a_spec_with_only_an_extended_form_parses_that_form(tmp_path, no_hands_root, capsys):
    """It failed with "has no 'base' form" where info and render take the spec's own form."""
    from ohra.cli.main import main

    assert main(["hand", "parse", str(_toy(tmp_path)), "--no-fidelity"]) == 0
    assert "finger_radii" in json.loads(capsys.readouterr().out)


def test_eval_original_takes_a_spec_file_and_names_why_a_variant_cannot(tmp_path, no_hands_root, capsys):
    """--original took registered names only: a spec path, accepted without it, was an unknown hand."""
    from ohra.cli.main import main
    from ohra.rotations import pose_to_grasp

    T = np.eye(4)
    T[:3, 3] = (-0.05, 0.0, -0.1)
    g = tmp_path / "g.npy"
    np.save(g, pose_to_grasp(T, np.zeros(22))[None])
    spec = str(_toy(tmp_path))
    assert main(["eval", str(g), "--hand", spec, "--object", "builtin:box", "--original", "--quiet"]) == 0
    assert f"{spec} (original URDF) on box: " in capsys.readouterr().out
    assert main(["eval", str(g), "--hand", "leap_3303", "--object", "builtin:box", "--original", "--quiet"]) == 2
    assert "leap_3303 is a LEAP variant, a canonical hand with no original URDF" in capsys.readouterr().err


def test_a_urdf_in_millimetres_is_named_as_such(tmp_path, no_hands_root):
    """'palm_radius = 44.76 is outside radius bounds (m)' gave no hint that the URDF's lengths are millimetres."""
    import re

    def mm(match):
        return f'{match.group(1)}="' + " ".join(f"{1000 * float(v):g}" for v in match.group(2).split()) + '"'

    urdf = re.sub(r'\b(xyz|size|radius|length)="([^"]*)"', mm, MIMIC_URDF.replace(
        '<mimic joint="a" multiplier="1.2" offset="-0.05"/>', ""))
    (tmp_path / "toy_mm.urdf").write_text(urdf)
    spec = tmp_path / "toy_mm.yaml"
    spec.write_text(MIMIC_SPEC.replace("urdf: toy_mimic.urdf", "urdf: toy_mm.urdf"))
    with pytest.raises(ParseError, match=r"m from the palm frame: is toy_mm\.urdf written in millimetres\?"):
        parse(spec, "extended", fit_params=False)


CLAW_URDF = """<?xml version="1.0"?>
<robot name="toy_claw">
  <link name="palm"><collision><geometry><box size="0.02 0.08 0.05"/></geometry><origin xyz="0 0 0.025"/></collision></link>
{fingers}
</robot>
"""
CLAW_FINGER = """  <link name="{f}1"><collision><geometry><cylinder radius="0.008" length="0.04"/></geometry><origin xyz="0 0 0.02"/></collision></link>
  <link name="{f}2"><collision><geometry><cylinder radius="0.008" length="0.03"/></geometry><origin xyz="0 0 0.015"/></collision></link>
  <link name="{f}_tip"/>
  <joint name="{f}_a" type="revolute"><parent link="palm"/><child link="{f}1"/><origin xyz="0 {y} 0.05"/><axis xyz="0 {ay} 0"/><limit lower="{lo}" upper="{up}"/></joint>
  <joint name="{f}_b" type="revolute"><parent link="{f}1"/><child link="{f}2"/><origin xyz="0 0 0.04"/><axis xyz="0 {ay} 0"/><limit lower="{lo}" upper="{up}"/></joint>
  <joint name="{f}_t" type="fixed"><parent link="{f}2"/><child link="{f}_tip"/><origin xyz="0 0 0.03"/></joint>"""


def _claw(folder: Path, middle_axis: int, lo: float, up: float = 1.0, signs: int = 1) -> Path:
    """Two fingers side by side (index about +y, range [lo, 1] when ``up`` > 0, else [0, 1]: positive angles curl it
    toward +x); the middle finger's URDF axis is ``middle_axis`` * y, its range [lo, up], its slots carry ``signs``."""
    fingers = [CLAW_FINGER.format(f="i", y=0.02, ay=1, lo=lo if up > 0 else 0.0, up=1.0), CLAW_FINGER.format(f="m", y=-0.02, ay=middle_axis, lo=lo, up=up)]
    (folder / "claw.urdf").write_text(CLAW_URDF.format(fingers="\n".join(fingers)))
    spec = folder / "claw.yaml"
    spec.write_text("name: toy_claw\nurdf: claw.urdf\npalm_origin: [0, 0, 0, 0, 0, 0]\n"
                    "joints: {index_joint3: i_a, index_joint4: i_b, "
                    f"middle_joint3: {{joint: m_a, sign: {signs}}}, middle_joint4: {{joint: m_b, sign: {signs}}}}}\n"
                    "forms: {base: {}, extended: {}}\n")
    return spec


@pytest.mark.parametrize("lo, up, named", [
    (-1.0, 1.0, r"positive flexion curls finger middle toward -x .* while index curls toward \+x"),  # D'Claw-like
    (-1.0, 0.0, r"finger middle flexes toward negative canonical angles while index flexes toward positive ones"),
])
def test_one_finger_whose_flexion_signs_are_all_reversed_is_named(tmp_path, no_hands_root, lo, up, named):
    """A finger turning about -y in the URDF, mapped with sign +1 in both slots, curls toward the back of the hand for
    positive canonical angles, yet its slots agree with each other (no per-slot advice) and the extended fit
    reproduced it exactly: it parsed with a perfect fidelity table (one finger of two is no majority for the
    palm-frame rules). A symmetric range (D'Claw's) says so through the curl, a one-sided one through its sign."""
    spec = _claw(tmp_path, middle_axis=-1, lo=lo, up=up)
    for form in ("base", "extended"):
        with pytest.raises(SpecError, match=named + r".*: the signs of its flexion joints are reversed \(middle: middle_joint3 "
                                                    r"\(joint 'm_a', sign \+1\), middle_joint4 \(joint 'm_b', sign \+1\)\)"):
            parse(spec, form, fit_params=False)
    ok = _claw(tmp_path, middle_axis=-1, lo=lo, up=up, signs=-1)  # the fix the message names
    for form in ("base", "extended"):
        assert parse(ok, form, fit_params=False).params is not None


def test_both_fingers_opening_with_a_symmetric_range_is_refused(tmp_path, no_hands_root):
    """No range to tell a turned palm frame from reversed signs: the error offers both."""
    spec = _claw(tmp_path, middle_axis=-1, lo=-1.0)
    spec.write_text(spec.read_text().replace("index_joint3: i_a, index_joint4: i_b",
                                             "index_joint3: {joint: i_a, sign: -1}, index_joint4: {joint: i_b, sign: -1}"))
    with pytest.raises(SpecError, match=r"curls every finger \(index, middle\) toward -x .*rotate palm_origin by pi about z"):
        parse(spec, "extended", fit_params=False)


@pytest.mark.assets
def test_a_leap_finger_with_every_flexion_sign_flipped_is_refused_in_the_extended_form(hands_dir, tmp_path):
    """Flipping all of the index finger's flexion slots together (j1 at the palm, j3, j4) passed the extended
    form with the same fidelity as the right spec: its range turns negative while the other fingers' stay positive."""
    import yaml

    d = yaml.safe_load(registry.spec_path("leap_hand_right").read_text())
    d["urdf"] = str(hands_dir / d["urdf"])
    ext = d["forms"]["extended"]["joints"]
    ext["index_joint1"] = {"joint": ext["index_joint1"], "sign": -1}
    for s in ("index_joint3", "index_joint4"):
        d["joints"][s] = {"joint": d["joints"][s], "sign": -1}
    spec = tmp_path / "flipped.yaml"
    spec.write_text(yaml.safe_dump(d))
    with pytest.raises(SpecError, match=r"finger index flexes toward negative canonical angles while middle, little flex toward "
                                        r"positive ones.*index_joint1 \(joint '1', sign -1\), index_joint3"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            parse(spec, "extended", fit_params=False)


def test_a_spec_form_that_fits_its_original_poorly_is_named_once_where_it_is_used(tmp_path, no_hands_root, monkeypatch):
    """`python -m ohra.synth --hand SPEC` (and the grasp commands) silently used a D'Claw base form ~5 cm off its
    original (keypoint RMS 47 mm; the extended form: 0.14 mm): a warning names the fit and the extended form. The
    toy claw fits exactly, so the threshold is moved below its RMS to plant the poor fit."""
    from ohra.errors import HandWarning
    from ohra.hands import resolve as rs

    spec = _claw(tmp_path, middle_axis=1, lo=-1.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error", HandWarning)
        assert rs.resolve_hand(spec).form == "base"  # a good fit: silent
    monkeypatch.setattr(rs, "POOR_FIT_MM", -1.0)
    rs._warned_fits.clear()
    with pytest.warns(HandWarning, match=r"claw.yaml: its base form follows the original URDF poorly \(keypoint RMS 0 mm.*"
                                         r"ohra hand compare claw.yaml.*the extended form may follow it"):
        rs.resolve_hand(spec)
    with warnings.catch_warnings():
        warnings.simplefilter("error", HandWarning)
        rs.resolve_hand(spec)  # once per spec file and form


def test_ohra_hand_parse_names_a_poor_fit_too(tmp_path, no_hands_root, monkeypatch, capsys):
    """`ohra hand parse --fit` printed the RMS and no warning (a 33 mm base fit passed as any other)."""
    from ohra.cli import main
    from ohra.hands import resolve as rs

    spec = _claw(tmp_path, middle_axis=1, lo=-1.0)
    argv = ["hand", "parse", str(spec), "--fit", "--no-fidelity", "-o", str(tmp_path / "p.json")]
    for threshold, said in ((rs.POOR_FIT_MM, False), (-1.0, True)):
        monkeypatch.setattr(rs, "POOR_FIT_MM", threshold)
        assert main(argv) == 0
        err = capsys.readouterr().err
        assert ("warning: this base form follows the original URDF poorly" in err) == said, err
        assert ("try --form extended" in err) == said


def test_pictures_of_an_original_hand_pose_its_mimic_joints_as_the_simulation_does(tmp_path, no_hands_root):
    """`ohra eval --original --render` drew Ability's fingers straight (mimic joints at 0) while the simulation
    had closed them and counted the grasps held."""
    import pybullet as pb

    from ohra.sim.bullet import load_urdf_text
    from ohra.sim.hands import SimHand
    from ohra.sim.render import pose_joints

    hand = SimHand.original_of(str(_toy(tmp_path)))
    assert hand.mimic, "the test needs a hand with mimic joints"
    c = pb.connect(pb.DIRECT)
    try:
        body = load_urdf_text(hand.urdf, c, useFixedBase=True)
        by_name = {pb.getJointInfo(body, j, physicsClientId=c)[1].decode(): j for j in range(pb.getNumJoints(body, physicsClientId=c))}
        qs = 0.5 * (hand.lower + hand.upper) + 0.1
        pose_joints(hand, body, by_name, qs, c)
        for name, (driver, mul, off) in hand.mimic.items():
            got = pb.getJointState(body, by_name[name], physicsClientId=c)[0]
            assert got == pytest.approx(mul * qs[hand.joints.index(driver)] + off, abs=1e-9), name
    finally:
        pb.disconnect(c)
