"""notebooks/04_grasp_evaluation.ipynb runs headless and shows its key claims."""

from __future__ import annotations

from pathlib import Path

import pytest

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")

NB = Path(__file__).resolve().parents[1] / "notebooks" / "04_grasp_evaluation.ipynb"


def _text(cell) -> str:
    return "\n".join(o.get("text", "") + str(o.get("data", {}).get("text/plain", "")) for o in cell.get("outputs", []))


def test_grasp_evaluation_notebook_executes(tmp_path):
    nb = nbformat.read(NB, as_version=4)
    nbclient.NotebookClient(nb, timeout=180, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}).execute()
    texts = [_text(c) for c in nb.cells if c.cell_type == "code"]
    assert "sphere: volume" in texts[0] and "l_block" in texts[0]
    assert "friction 3.0" in texts[1] and "strict: friction 1.0" in texts[1]
    assert "success rate" in texts[2] and "inf" not in texts[2]
    assert "early exit changes no outcome: True" in texts[3]
    assert "reversed order, same results: True" in texts[3]
    assert "sheet (" in texts[5]
    code = [c for c in nb.cells if c.cell_type == "code"]
    assert any("image/png" in o.get("data", {}) for o in code[5].outputs)  # the contact sheet is shown
