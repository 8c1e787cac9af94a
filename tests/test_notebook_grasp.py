"""notebooks/06_grasp_model.ipynb runs headless on the shipped model and shows the key outputs."""

from __future__ import annotations

from pathlib import Path

import pytest

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")
pytest.importorskip("torch")

from ohra.learn.grasp.model import default_model_dir  # noqa: E402

NB = Path(__file__).resolve().parents[1] / "notebooks" / "06_grasp_model.ipynb"


def _text(cell) -> str:
    out = []
    for o in cell.get("outputs", []):
        out.append(o.get("text", ""))
        out.append(str(o.get("data", {}).get("text/plain", "")))
        if "image/png" in o.get("data", {}):
            out.append("<png>")
    return "\n".join(out)


def test_grasp_model_notebook_executes(tmp_path):
    if not (default_model_dir() / "model.pt").is_file():
        pytest.skip("shipped grasp model not present")
    nb = nbformat.read(NB, as_version=4)
    nbclient.NotebookClient(nb, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}).execute()
    texts = [_text(c) for c in nb.cells if c.cell_type == "code"]
    assert "hands: allegro_hand_left, barrett_hand, shadow_hand_right" in texts[0] and "pipeline check" in texts[0]
    assert texts[1].count("(100, 31)") == 5 and texts[1].count("same seed same grasps: True") == 5
    assert texts[2].count("succeeded") == 3
    assert "<png>" in texts[3]
    assert (tmp_path / "grasp_sheet.png").is_file() and (tmp_path / "grasp_scene.html").is_file()
