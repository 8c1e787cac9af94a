"""notebooks/05_grasp_synthesis.ipynb runs headless and shows grasps."""

from __future__ import annotations

from pathlib import Path

import pytest

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")

NB = Path(__file__).resolve().parents[1] / "notebooks" / "05_grasp_synthesis.ipynb"


def test_synthesis_notebook_executes(tmp_path):
    nb = nbformat.read(NB, as_version=4)
    nbclient.NotebookClient(nb, timeout=300, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}).execute()
    texts = ["\n".join(o.get("text", "") + str(o.get("data", {}).get("text/plain", "")) for o in c.get("outputs", [])) for c in nb.cells if c.cell_type == "code"]
    assert "4 solves" in texts[0]
    assert "grasps to show:" in texts[1] and "(0, 31)" not in texts[1] and "inf" not in texts[1]
    code = [c for c in nb.cells if c.cell_type == "code"]
    assert any("ohra: open framed" in o.get("data", {}).get("text/html", "") for o in code[2].outputs)
    assert "grasp0.png True" in texts[3]
    assert any("image/png" in o.get("data", {}) for o in nb.cells[-1].outputs)
