"""The hand registry never hides a broken spec: a YAML that does not parse is an error naming the file."""

from __future__ import annotations

import shutil

import pytest

import ohra
from ohra.cli.main import main
from ohra.errors import SpecError
from ohra.hands import hands_in_form, list_hands, registry
from ohra.resources import specs_dir


@pytest.fixture
def spec_folder(tmp_path, monkeypatch):
    """The registry reading its specs from ``tmp_path`` (one good spec copied in); cache cleared around."""
    shutil.copy(specs_dir() / "shadow_hand_right.yaml", tmp_path)
    monkeypatch.setattr(registry, "specs_dir", lambda: tmp_path)
    registry._spec_files_in.cache_clear()
    yield tmp_path
    registry._spec_files_in.cache_clear()  # runs before monkeypatch restores specs_dir: nothing stale is cached


def test_good_spec_alone_is_registered(spec_folder):
    assert list_hands() == ["shadow_hand_right"]


def test_unparsable_spec_is_an_error_naming_the_file(spec_folder):
    broken = spec_folder / "broken_hand.yaml"
    broken.write_text("name: broken_hand\njoints: {index_joint1: [unclosed\n")
    with pytest.raises(SpecError, match=r"broken_hand\.yaml:.*invalid YAML"):
        list_hands()
    with pytest.raises(SpecError, match=r"broken_hand\.yaml"):
        ohra.get_hand("shadow_hand_right")  # every registry lookup fails, not just the broken hand's


def test_yaml_that_is_not_a_spec_is_an_error_naming_the_file(spec_folder):
    (spec_folder / "notes.yaml").write_text("- just\n- a list\n")
    with pytest.raises(SpecError, match=r"notes\.yaml: not a hand spec"):
        list_hands()


def test_cli_reports_a_broken_spec_in_one_line(spec_folder, capsys):
    (spec_folder / "broken_hand.yaml").write_text("joints: [\n")
    assert main(["hand", "list"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "broken_hand.yaml" in err[0] and err[0].startswith("ohra: error:"), err


def test_hands_in_form_has_exactly_the_hands_registered_in_that_form():
    base, ext = hands_in_form("base"), hands_in_form("extended")
    assert list(base) == [n for n in list_hands() if "base" in registry.registered_forms(n)]
    assert set(base) < set(list_hands()) and set(ext) <= set(list_hands())
    assert set(list_hands()) - set(base), "expected an extended-only hand (none left out: the filter is untested)"
    assert all(p.form == "base" for p in base.values()) and all(p.form == "extended" for p in ext.values())
    assert base["shadow_hand_right"].isclose(ohra.get_hand("shadow_hand_right", "base"))
