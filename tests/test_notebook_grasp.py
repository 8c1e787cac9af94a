"""notebooks/06_grasp_model.ipynb runs headless on the shipped model and shows the key outputs."""

from __future__ import annotations


import pytest

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")
pytest.importorskip("torch")

from notebook_utils import execute  # noqa: E402

from ohra.learn.grasp.model import default_model_dir  # noqa: E402


def test_grasp_model_notebook_executes(tmp_path):
    if not (default_model_dir() / "model.pt").is_file():
        pytest.skip("shipped grasp model not present")
    nb, texts = execute("06_grasp_model.ipynb", tmp_path, timeout=600)
    assert "hands: allegro_hand_left, barrett_hand, shadow_hand_right" in texts[0]
    assert "unified model of the grasp-model study" in texts[0]
    assert texts[1].count("(100, 31)") == 5 and texts[1].count("same seed same grasps: True") == 5
    assert texts[2].count("succeeded") == 3
    assert "<png>" in texts[3]
    assert (tmp_path / "grasp_sheet.png").is_file() and (tmp_path / "grasp_scene.html").is_file()
    # from a checkout the study's committed tables are shown: one line per hand, then the sheet
    assert texts[5].count("hand-specific") == 3 and "<png>" in texts[5]
    # ... and where the model loses success (stop 44): the three measurements' tables
    code = [c for c in nb.cells if c.cell_type == "code"]
    shown = "\n".join(o.get("data", {}).get("text/markdown", "") for o in code[6].outputs)
    assert "unified-24000" in shown and "seen (training objects)" in shown and "stored rotations" in shown and "best of 8" in shown
    assert "palm position error" in shown
