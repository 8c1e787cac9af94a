"""Fidelity: canonical vs original joint, fingertip and surface errors."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from ohra import cli
from ohra.original.fidelity import Stats, compare
from ohra.hands import registry
from ohra.original.parse import parse

pytestmark = pytest.mark.assets


def test_stats_in_millimetres():
    s = Stats.of(np.array([0.001, 0.002, 0.003, np.nan]))
    assert (s.mean, s.max, s.n) == pytest.approx((2.0, 3.0, 3))


def test_extended_shadow_is_within_the_target(hands_dir):
    rep = compare("shadow_hand_right", "extended", samples=60, surface_configs=1, surface_points=400)
    assert set(rep.tips) == {"thumb", "index", "middle", "ring", "little", "hand"}
    assert rep.tips["hand"].mean <= 2.0
    assert rep.joints["hand"].mean <= 2.0
    assert np.isfinite(rep.surface["hand"].mean) and rep.surface["hand"].mean < 10.0
    text = rep.table()
    assert "fingertip" in text and "little" in text


def test_a_worse_hand_scores_worse(hands_dir):
    spec = registry.spec("dex3_right")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        good = parse(spec, "base", fit_params=False)
    bad_params = good.params.copy()
    bad_params.finger_lengths = bad_params.finger_lengths * 1.2
    bad = type(good)(**{**good.__dict__, "params": bad_params})
    e_good = compare(good, samples=40, surface=False).tips["hand"].mean
    e_bad = compare(bad, samples=40, surface=False).tips["hand"].mean
    assert e_bad > e_good + 3.0


def test_cli_compare_prints_the_table(hands_dir, capsys, tmp_path):
    html = tmp_path / "overlay.html"
    assert cli.main(["hand", "compare", "barrett_hand", "--samples", "30", "--no-surface", "--html", str(html)]) == 0
    out = capsys.readouterr().out
    assert "barrett_hand (base)" in out and "index" in out
    text = html.read_text()
    assert text.strip().startswith("<!DOCTYPE html>") and len(text) > 10_000


def test_joints_the_form_cannot_follow_count_and_are_named(hands_dir):
    """Allegro's finger twist joints have no slot in the base form: sampled, they make a large error
    (the honest number) and are named; held at 0 (as the action map drives the original) they do not."""
    rep = compare("allegro_hand_right", "base", samples=40, surface=False)
    assert {"joint_0.0", "joint_4.0", "joint_8.0"} == {a.split("'")[1] for a in rep.approximations}
    assert rep.tips["hand"].mean > 8.0 and rep.tips_held is not None and rep.tips_held.mean < 2.0
    ext = compare("allegro_hand_right", "extended", samples=20, surface=False)
    assert not ext.approximations and ext.tips_held is None
