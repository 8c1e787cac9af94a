"""notebooks/03_morphology_vae.ipynb runs headless (small settings) and shows the key numbers."""

from __future__ import annotations

from pathlib import Path

import pytest

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")
pytest.importorskip("torch")


NB = Path(__file__).resolve().parents[1] / "notebooks" / "03_morphology_vae.ipynb"


def _text(cell) -> str:
    out = []
    for o in cell.get("outputs", []):
        out.append(o.get("text", ""))
        out.append(str(o.get("data", {}).get("text/plain", "")))
        if "image/png" in o.get("data", {}):
            out.append("<png>")
    return "\n".join(out)


def test_morphology_notebook_executes(tmp_path):
    nb = nbformat.read(NB, as_version=4)
    nbclient.NotebookClient(nb, timeout=300, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}).execute()
    texts = [_text(c) for c in nb.cells if c.cell_type == "code"]
    assert "4096 hands, 82 numbers each" in texts[0] and "<png>" in texts[0]
    assert "epoch 3: total" in texts[1]
    assert "shipped model: latent" in texts[2] and "encoding rot6d70" in texts[2]
    assert "fingers: [3," in texts[3] and "<png>" in texts[3]
    assert "reference model, steps with a thumb pointing into the palm" in texts[4] and "<png>" in texts[4]
    assert "valid: True | plausible: True" in texts[5]
    assert (tmp_path / "interpolation.png").is_file() and (tmp_path / "small_run" / "model.pt").is_file()
