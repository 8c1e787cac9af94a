"""notebooks/01_canonical_hand.ipynb runs headless and shows the key numbers."""

from __future__ import annotations

from pathlib import Path

import pytest

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")

NB = Path(__file__).resolve().parents[1] / "notebooks" / "01_canonical_hand.ipynb"


def _text(cell) -> str:
    out = []
    for o in cell.get("outputs", []):
        out.append(o.get("text", ""))
        out.append(str(o.get("data", {}).get("text/plain", "")))
        out.append(str(o.get("data", {}).get("text/html", ""))[:200])
    return "\n".join(out)


def test_canonical_hand_notebook_executes(hands_dir, tmp_path):
    nb = nbformat.read(NB, as_version=4)
    nbclient.NotebookClient(nb, timeout=180, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}).execute()
    texts = [_text(c) for c in nb.cells if c.cell_type == "code"]
    assert "3 fingers, 12 DoF, right hand, 82 numbers" in texts[0]
    assert "index   tip at q=0: [0.    0.025 0.185]" in texts[1]
    assert "batch tips (1024, 5, 3) | index tip Jacobian (6, 22)" in texts[2]
    assert "<iframe" in texts[3] or "iframe" in texts[3].lower()
    assert "round trip exact: True" in texts[4]
