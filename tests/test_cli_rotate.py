"""``ohra rotate ...``: arguments reach the library; bad input is one line on stderr and exit 2."""

from __future__ import annotations

import pytest

pytest.importorskip("gymnasium", reason="ohra rotate needs the rl extra (gymnasium)")

from ohra.cli.rotate import main  # noqa: E402


def test_unknown_config_field_is_one_line_and_exit_2(tmp_path, capsys):
    assert main(["grasps", "--set", "frobnicate=1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "frobnicate" in err


def test_eval_of_a_folder_without_a_run_is_one_line_and_exit_2(tmp_path, capsys):
    pytest.importorskip("stable_baselines3", reason="ohra rotate eval needs stable-baselines3")
    assert main(["eval", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "config.json" in err


def test_plot_needs_label_equals_runs(tmp_path, capsys):
    assert main(["plot", "nolabel", "-o", str(tmp_path / "x.png")]) == 2
    assert "LABEL=RUN" in capsys.readouterr().err


def test_grasps_command_generates_and_reports_the_cache(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("OHRA_CACHE_DIR", str(tmp_path))
    assert main(["grasps", "--grasps", "3", "--set", "settle_time=1.0"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("3 starting states") and str(tmp_path) in out
    assert len(list((tmp_path / "rotation").glob("leap_hand_right_canonical_cube_*.npz"))) == 1
