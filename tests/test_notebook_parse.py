"""notebooks/02_parse_and_compare.ipynb runs headless and shows the key numbers."""

from __future__ import annotations

from pathlib import Path

import pytest

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")

NB = Path(__file__).resolve().parents[1] / "notebooks" / "02_parse_and_compare.ipynb"


def _text(cell) -> str:
    return "\n".join(o.get("text", "") + str(o.get("data", {}).get("text/plain", "")) for o in cell.get("outputs", []))


def test_parse_notebook_executes(hands_dir, tmp_path):
    nb = nbformat.read(NB, as_version=4)
    nbclient.NotebookClient(nb, timeout=300, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}).execute()
    texts = [_text(c) for c in nb.cells if c.cell_type == "code"]
    assert "shadow_hand/shadow_hand_right.urdf" in texts[0]
    assert "reproduces committed params: True" in texts[1]
    assert "mean fingertip error below 2 mm: True" in texts[2]
    assert "missing-mesh warnings" in texts[3] and "palm radius" in texts[3]
    assert "static HTML" in texts[4]
    assert (tmp_path / "shadow_overlay.html").is_file()
